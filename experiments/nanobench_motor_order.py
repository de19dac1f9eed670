"""Motors numbered otherwise in one flight log: does the motor-order check see it, and is it silent on honest flights?

For each of the 16 NanoBench flights, its signature (`dynax.internal.flight_signature`: the correlation of each
motor's differential input with the change of each body rate over the next 0.12 s) is tested against two
references, as `dynax fit quadrotor` and `dynax evaluate` would meet them: the other 15 flights (a model
fitted to many flights), and the one flight after it in the list (a fit given two flights). For the flight as
logged it reports the margin: the chi-square of the best other order less that of the given one (positive:
the given order fits best; the check refuses only where some order beats the given one by 20.1). Then the
flight's motor columns are permuted (file column j holds motor Q[j]) by each of the 23 other orders, and for
each it reports whether the check refuses and whether it names Q. The table of `docs/devdocs/quadrotor_notes.md`
shows five of the orders: a turn of the frame by one arm (m2,m3,m4,m1) and by two (m3,m4,m1,m2), two
neighbours swapped (m2,m1,m3,m4), the two across swapped (m3,m2,m1,m4) and the order reversed (m4,m3,m2,m1).

    python experiments/nanobench_motor_order.py [--out DIR]

Writes `DIR/motor_order.json` and `DIR/motor_order.md` (default DIR `experiments/results/nanobench_motor_order`),
with the check's cost per flight beside `dynax.load_flight`'s; about 45 s.
"""

import argparse
import pathlib
import sys
import time

import numpy as np

import dynax
from dynax.internal import (
    flight_signature,
    motor_order,
    motor_signature,
    MotorNumbering,
    order_text,
    PERMUTATIONS,
    write_json,
)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import DATA, NANOBENCH_MAP  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / "results"
SHOWN = ((1, 2, 3, 0), (2, 3, 0, 1), (1, 0, 2, 3), (2, 1, 0, 3), (3, 2, 1, 0))


def permuted(trajectory, order):
    """The record with file column j holding motor `order[j]`."""
    us = np.asarray(trajectory.us).copy()
    us[:, :4] = us[:, list(order)]
    return dynax.Trajectory(
        trajectory.ts, trajectory.xs, us, trajectory.state_names, trajectory.input_names, trajectory.system
    )


def outcomes(trajectory, usable, reference):
    """For each of the 23 other orders applied to the flight's columns: caught, the orders named, the evidence."""
    out = []
    for order in PERMUTATIONS[1:]:
        found = motor_order(flight_signature(permuted(trajectory, order), usable), reference)
        truth = order_text(np.argsort(order))  # the file's m1..m4 read like these motors
        named = [order_text(o) for o in found.named]
        out.append(
            {
                "order": truth,
                "caught": found.permuted,
                "named": named,
                "right": bool(named) and named[0] == truth,
                "wrong": bool(named) and truth not in named,
                "evidence": found.evidence,
            }
        )
    return out


def mark(outcome) -> str:
    if not outcome["caught"]:
        return "-"
    return "named" if outcome["right"] else ("WRONG" if outcome["wrong"] else "2nd")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(RESULTS / "nanobench_motor_order"))
    args = parser.parse_args(argv)
    start = time.perf_counter()
    paths = sorted(DATA.glob("*.csv.gz"))
    loading = time.perf_counter()
    flights = [dynax.load_flight(p, mapping=NANOBENCH_MAP) for p in paths]
    loading = (time.perf_counter() - loading) / len(paths)
    checking = time.perf_counter()  # the loader's check, as `dynax fit quadrotor` meets the flights
    numbering = MotorNumbering()
    for path, (trajectory, notes) in zip(paths, flights):
        numbering.check(trajectory, notes.usable, path)
    numbering.settle()  # each flight against the other 15
    checking = (time.perf_counter() - checking) / len(paths)
    signatures = [flight_signature(t, n.usable) for t, n in flights]
    rows = []
    for k, (path, (trajectory, notes)) in enumerate(zip(paths, flights)):
        row = {"flight": path.name.removesuffix(".csv.gz")}
        for name, refs in (("others", [j for j in range(16) if j != k]), ("pair", [(k + 1) % 16])):
            reference = motor_signature([signatures[j] for j in refs])
            honest = motor_order(signatures[k], reference)
            found = outcomes(trajectory, notes.usable, reference)
            row[name] = {
                "reference": [paths[j].name for j in refs],
                "margin": honest.margin,
                "refused": honest.permuted,
                "chi2_given": honest.chi2[0],
                "scale": honest.scale,
                "caught": sum(o["caught"] for o in found),
                "named_right": sum(o["right"] for o in found),
                "named_wrong": sum(o["wrong"] for o in found),
                "orders": found,
            }
        rows.append(row)
    shown = [order_text(np.argsort(o)) for o in SHOWN]
    lines = [
        "| flight | margin, 15 others | margin, 1 other | " + " | ".join(shown) + " | caught of 23 |",
        "|---|---|---|" + "---|" * len(shown) + "---|",
    ]
    for row in rows:
        cells = []
        for order in shown:
            o15, o1 = (next(o for o in row[n]["orders"] if o["order"] == order) for n in ("others", "pair"))
            cells.append(f"{mark(o15)} {o15['evidence']:.0f} / {mark(o1)} {o1['evidence']:.0f}")
        margins = [f"{row[n]['margin']:.1f}" + (" REFUSED" if row[n]["refused"] else "") for n in ("others", "pair")]
        caught = f"{row['others']['caught']} / {row['pair']['caught']}"
        lines.append(f"| {row['flight']} | {margins[0]} | {margins[1]} | " + " | ".join(cells) + f" | {caught} |")
    totals = {
        name: {
            "honest_refused": sum(r[name]["refused"] for r in rows),
            "min_margin": min(r[name]["margin"] for r in rows),
            "cases": 23 * len(rows),
            "caught": sum(r[name]["caught"] for r in rows),
            "named_right": sum(r[name]["named_right"] for r in rows),
            "named_wrong": sum(r[name]["named_wrong"] for r in rows),
        }
        for name in ("others", "pair")
    }
    lines.append("")
    for name, t in totals.items():
        lines.append(
            f"reference {name}: honest flights refused {t['honest_refused']} of {len(rows)} (smallest margin "
            f"{t['min_margin']:.1f}); permuted flights caught {t['caught']} of {t['cases']}, the right order named "
            f"first in {t['named_right']}, a wrong order named without the right one in {t['named_wrong']}"
        )
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines.append(
        f"cost per flight: the check {1e3 * checking:.0f} ms (its signature and the 24 orders), "
        f"dynax.load_flight {1e3 * loading:.0f} ms"
    )
    timing = {"check_s_per_flight": checking, "load_s_per_flight": loading}
    write_json(
        out / "motor_order.json",
        {"rows": rows, "totals": totals, **timing, "seconds": time.perf_counter() - start},
    )
    (out / "motor_order.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"{time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
