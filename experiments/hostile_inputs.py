"""Feed the command line the hostile corpus (`tests/cli/hostile_cases.py`) and tally what happens.

Each case (a fault of the kinds real logs carry: a glitch, a stuck sensor, a wrapped angle, a velocity
wrong in one stretch, a zero input, time in milliseconds, a record given twice, an impossible model, a
bad argument; and clean records that must keep their right answers) runs through the console script's
entry point in its own folder and is judged: refused correctly (exit 2, one line naming the column,
row or time and the fix, nothing written), warned correctly, accepted correctly (a right answer
against the truth the record was made from), silent failure (exit 0 with a wrong answer, or a bad
call that returns), misleading (advice that would make the data worse), traceback, refused badly
(exit 2 but the message misses the location), wrongly refused.

`--flights` runs the flight-log corpus instead (`tests/cli/hostile_flights.py`: glitches, motion-capture
dropouts, time units, quaternion signs and order, frames and units, motor and battery columns, files and
arguments of `dynax fit quadrotor` and `dynax evaluate`), judged by the same rules.

Run from the repository root: `python experiments/hostile_inputs.py [--flights] [--code PATH] [--out FILE]`.
`--code` puts another checkout's `dynax` first on the path (the code before the data checks) so that
the same cases judge it. Writes a JSON list of outcomes (default
`experiments/results/hostile_inputs/after.json`, `flights_after.json` with `--flights`) and prints a
Markdown table and the counts.
`--compare BEFORE.json AFTER.json` prints the two side by side instead of running anything.
"""

import argparse
import collections
import importlib.util
import json
import pathlib
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--code", default=str(REPO), help="checkout whose dynax is judged (default: this one)")
    parser.add_argument("--flights", action="store_true", help="the flight-log corpus (tests/cli/hostile_flights.py)")
    parser.add_argument(
        "--out", default=None, help="results file (default results/hostile_inputs/[flights_]after.json)"
    )
    parser.add_argument("--only", default=None, help="comma-separated case ids")
    parser.add_argument("--compare", nargs=2, default=None, metavar=("BEFORE", "AFTER"))
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    sys.path.insert(0, str(pathlib.Path(args.code).resolve()))
    import jax

    jax.config.update("jax_enable_x64", True)
    import dynax
    from dynax.internal import cli_main

    print(f"judging dynax from {pathlib.Path(dynax.__file__).parent}", file=sys.stderr)
    # this checkout's tests (the corpus, its judge, tests.reference for the fixtures) ahead of --code's: the same
    # cases and rules judge either; dynax itself stays the one imported above
    sys.path.insert(0, str(REPO))
    if args.flights:
        from tests.cli import hostile_cases
        from tests.cli import hostile_flights as cases

        run_case = hostile_cases.run_case
    else:
        spec = importlib.util.spec_from_file_location("hostile_cases", REPO / "tests" / "cli" / "hostile_cases.py")
        cases = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(cases)
        run_case = cases.run_case
    name = "flights_after.json" if args.flights else "after.json"
    args.out = args.out or str(REPO / "experiments" / "results" / "hostile_inputs" / name)

    only = set(args.only.split(",")) if args.only else None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        fixtures = cases.make_fixtures(tmp, cli_main) if args.flights else cases.make_fixtures(tmp)
        selected = [c for c in cases.CASES if not only or c.id in only]
        if args.flights and "star" not in fixtures:  # the NanoBench flights are not here
            selected = [c for c in selected if c.id not in cases.NEEDS_NANOBENCH]
        for k, case in enumerate(selected):
            start = time.perf_counter()
            o = run_case(case, tmp / case.id, fixtures, cli_main)
            rows.append(
                {
                    "id": case.id,
                    "kind": case.kind,
                    "expect": case.expect,
                    "verdict": o.verdict,
                    "status": o.status,
                    "message": o.message[:300],
                    "seconds": round(time.perf_counter() - start, 1),
                }
            )
            print(
                f"[{k + 1}/{len(selected)}] {case.id}: {o.verdict} ({o.status}) {o.message[:140]}",
                file=sys.stderr,
                flush=True,
            )
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1) + "\n")
    counts = collections.Counter(_short(r["verdict"]) for r in rows)
    print("| case | class | expected | outcome | exit |\n|---|---|---|---|---|")
    for r in rows:
        print(f"| `{r['id']}` | {r['kind']} | {r['expect']} | {r['verdict']} | {r['status']} |")
    print(f"\n{len(rows)} inputs tried: " + ", ".join(f"{n} {k}" for k, n in counts.most_common()))


def _short(verdict):
    return verdict.split(" (")[0]


def compare(before_path, after_path):
    """A Markdown table of two runs' outcomes, case by case, and both tallies."""
    before = {r["id"]: r for r in json.loads(pathlib.Path(before_path).read_text())}
    after = json.loads(pathlib.Path(after_path).read_text())
    print("| input | class | expected | before | after |\n|---|---|---|---|---|")
    for r in after:
        b = before.get(r["id"])
        was = (
            "-"
            if b is None
            else _short(b["verdict"]) + (f" (exit {b['status']})" if b["status"] not in (None, 0, 2) else "")
        )
        print(f"| `{r['id']}` | {r['kind']} | {r['expect']} | {was} | {_short(r['verdict'])} |")
    for name, rows in (("before", [before[r["id"]] for r in after if r["id"] in before]), ("after", after)):
        counts = collections.Counter(_short(r["verdict"]) for r in rows)
        print(f"\n{name}: {len(rows)} inputs: " + ", ".join(f"{n} {k}" for k, n in counts.most_common()))


if __name__ == "__main__":
    main()
