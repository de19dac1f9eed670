"""Where the least-squares force offsets come from on the stick-slip records, and the static level read when the
rows at low speed are left out of the least-squares stage (issue 48).

    python experiments/stick_slip_slow_rows.py --parts shoulder,coulomb,elbow --bands 0,0.02,0.03,0.05,0.1 \
        --no-offsets --out experiments/results/stick_slip_slow_rows
    python experiments/stick_slip_slow_rows.py --parts shoulder,coulomb,elbow --bands 0,0.03,0.1 --both-fits \
        --out experiments/results/stick_slip_slow_rows

`identify` runs as in `experiments/stick_slip_identification.py` (defaults, `Dynamic(static_friction=True)`,
`friction="coulomb"`, `holdout=0`), least squares only (`refine=False`: the level is read there), on the hidden-effect
battery's stick-slip records: stiction of 0.8 N m at the shoulder (`shoulder`), a sticking Coulomb friction of
0.5 N m at the elbow (`coulomb`), stiction of 0.5 N m at the elbow (`elbow`). The truth has no force offsets.

For each band of speeds (`--bands`, rad/s) the refit without the loaded rests (`identify`'s second least-squares
fit) also gives zero weight to each joint's dynamic rows whose speed (as `identify`'s slow-row rule reads it: the
record filtered by its chosen settings) is below the band, in place of the rule's own band
(`dynax.internal.slow_rows`), so band 0 is `identify` as it was before that rule and band 0.03 is the rule;
`--both-fits` applies the band to the first fit too. The stages' equations and row weights are read with
`dynax.internal.least_squares_seen`; the rows' speed bins below read the regressor's viscous column. Reported per band:
the level read, the fitted offsets, their standard errors (batch means of the fit's residuals over 20 contiguous
batches of each record's kept rows, robust to the serial correlation, and the parameters' share through the
group means), and, with the truth's parameters, the offset each record needs (the mean of its rows' residual)
taken apart by the rows' speed. `--no-offsets` adds a fit with `Dynamic(offsets=False, static_friction=True)`
(what a rule that drops insignificant offsets would do); the last fit is `identify` as it is, with the rule.
`--parts light,dfki`: `identify` as it is on the light arm's breakaway records of
`tests/identify/test_stiction_identification.py` and on the six DFKI runs (`light_and_dfki`). Writes `OUT/PART.json`
(`OUT/PART_both_fits.json`).
"""

import argparse
import json
import pathlib
import sys
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import least_squares_seen, parameter_names, slow_rows, with_friction  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.hidden_cases import CASES, records, truth_theta  # noqa: E402

CASE_NAMES = {
    "shoulder": "double_pendulum-stiction@q1-0.8-stick-slip",
    "coulomb": "double_pendulum-coulomb_friction@q2-0.5-sticking_coulomb",
    "elbow": "double_pendulum-stiction@q2-0.5-stick-slip",
}
SPEED_BINS = (0.0, 0.01, 0.03, 0.1, np.inf)  # rad/s: the tanh's width, three of them, and beyond
BATCHES = 20


def row_speeds(raw_a, names, n_joints):
    """Each dynamic row's own joint speed: the viscous column of its joint (`theta6` at q1, `theta7` at q2)."""
    per = raw_a.shape[0] // n_joints
    a = np.asarray(raw_a)
    speeds = []
    for j in range(n_joints):
        column = a[:, names.index(f"theta{6 + j}")]
        others = np.delete(np.arange(n_joints), j)
        assert all(np.all(column[k * per : (k + 1) * per] == 0.0) for k in others)  # the column is joint j's only
        speeds.append(column[j * per : (j + 1) * per])
    return np.concatenate(speeds)


def fit(data, band: float, offsets="auto", both=False, rule=False):
    """`identify` as the experiment runs it, and what its least-squares stages solved (`least_squares_seen`): the
    last stage's equations and row weights, and the stage itself. Without `rule`, the refit leaves out the rows
    under `band` (`slow_rows(band)`; 0: none, the refit as it was before `identify`'s slow-row rule); with it,
    `identify`'s own rule. `both`: the first fit leaves them out too."""
    start = time.perf_counter()
    with warnings.catch_warnings(), least_squares_seen() as seen, slow_rows(None if rule else band, first_fit=both):
        warnings.simplefilter("ignore")
        result = dynax.identify(
            dynax.DoublePendulum(),
            data,
            dynax.Dynamic(static_friction=True, offsets=offsets),
            friction="coulomb",
            refine=False,
            validation=dynax.Validate(holdout=0),
        )
    return result, seen[-1], time.perf_counter() - start


def offsets_taken_apart(caught, truth: np.ndarray) -> dict:
    """The fitted offsets with their standard errors, and the offset the truth's parameters need, by row speed."""
    ls, raw_a, raw_y, names, counts, keep = (
        caught.stage,
        caught.a,
        caught.y,
        list(caught.names),
        caught.counts,
        caught.keep,
    )
    n_joints = raw_a.shape[0] // sum(counts)
    keep = np.ones(len(raw_y)) if keep is None else np.asarray(keep)
    speeds = row_speeds(raw_a, names, n_joints)
    estimate = np.asarray(ls.estimate)
    covariance = np.asarray(ls.fit.covariance)
    theta = np.asarray([truth.get(n, 0.0) for n in names])
    out = []
    if ls.groups is None:
        return {"groups": out}
    for g, rows in enumerate(ls.groups):
        rows = np.asarray(rows)
        kept = rows[keep[rows] > 0]
        a_mean = raw_a[kept].mean(axis=0)
        fitted = float(raw_y[kept].mean() - a_mean @ estimate)
        assert np.isclose(fitted, np.asarray(ls.fitted_offsets).T.ravel()[g], atol=1e-9)  # the stage's own
        residual = raw_y[kept] - raw_a[kept] @ estimate - fitted
        batch_means = [b.mean() for b in np.array_split(residual, BATCHES)]
        se_noise = float(np.std(batch_means, ddof=1) / np.sqrt(BATCHES))
        se_params = float(np.sqrt(max(a_mean @ covariance @ a_mean, 0.0)))
        at_truth = raw_y[kept] - raw_a[kept] @ theta
        by_speed = {}
        for low, high in zip(SPEED_BINS[:-1], SPEED_BINS[1:]):
            inside = (np.abs(speeds[kept]) >= low) & (np.abs(speeds[kept]) < high)
            by_speed[f"{low:g} to {high:g} rad/s"] = {
                "rows": int(inside.sum()),
                "share of the offset": float(at_truth[inside].sum() / len(kept)),
                "mean residual": float(at_truth[inside].mean()) if inside.any() else None,
            }
        out.append(
            {
                "group": g,
                "rows": len(rows),
                "kept": len(kept),
                "fitted": fitted,
                "std_error": float(np.hypot(se_noise, se_params)),
                "std_error_noise": se_noise,
                "std_error_parameters": se_params,
                "at_truth": float(at_truth.mean()),
                "at_truth_by_speed": by_speed,
            }
        )
    return {"groups": out, "driven": list(ls.driven), "records": len(counts)}


def run(part: str, bands, no_offsets: bool, both: bool) -> dict:
    (case,) = [c for c in CASES if c.name == CASE_NAMES[part]]
    data = list(records(case))
    names = parameter_names(with_friction(dynax.DoublePendulum(), "coulomb"), "coulomb")
    truth = dict(zip(names, [float(v) for v in truth_theta(case)]))
    truth |= {"fc1": 0.0, "fc2": case.size if "coulomb" in case.name else 0.0}
    row = {"truth": {"fs": case.size, "joint": case.where, "parameters": truth}, "fits": {}}
    variants = [(f"band {b:g}", b, "auto", False) for b in bands]
    variants += [("no offsets", 0.0, False, False)] if no_offsets else []
    variants += [("identify (the slow-row rule)", 0.0, "auto", True)]
    for label, band, offsets, rule in variants:
        result, caught, seconds = fit(data, band, offsets, both, rule)
        sf = result.static_friction
        entry = {
            "band": band,
            "offsets": offsets,
            "fit_seconds": seconds,
            "levels": {j.name: {"level": j.level, "kind": j.kind, "lower_bound": j.lower_bound} for j in sf.joints},
            "level_error": {j.name: j.level / case.size - 1 for j in sf.joints},
            "rows_left_out": sf.rows_left_out,
            "rows": sf.rows,
            "estimate": dict(zip(caught.stage.names, np.asarray(caught.stage.estimate).tolist())),
            "offsets_taken_apart": offsets_taken_apart(caught, truth),
            "note": sf.note,
        }
        row["fits"][label] = entry
        print(part, label, f"{seconds:.0f} s", entry["levels"], entry["rows_left_out"], flush=True)
        for g in entry["offsets_taken_apart"]["groups"]:
            print(
                f"  group {g['group']}: fitted {g['fitted']:+.4f} ± {g['std_error']:.4f},",
                f"at truth {g['at_truth']:+.4f}",
                {k: round(v["share of the offset"], 4) for k, v in g["at_truth_by_speed"].items()},
                flush=True,
            )
    return row


def light_and_dfki(part: str) -> dict:
    """`identify` as it is, no band of the experiment's: the light arm's breakaway records of
    `tests/identify/test_stiction_identification.py` (its `fit`: refinement where it applies), or the six DFKI
    runs with `Dynamic(static_friction=True)`, `friction="coulomb"`, `refine=False`, `holdout=0` (run 12's levels)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if part == "light":
            from tests.identify.test_stiction_identification import breakaway_record
            from tests.identify.test_stiction_identification import fit as light_fit

            result = light_fit([breakaway_record(0)[0], breakaway_record(1)[0]])
        else:
            sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
            from dfki_default_identification import load, RUNS

            result = dynax.identify(
                dynax.DoublePendulum(),
                [load(r) for r in RUNS],
                dynax.Dynamic(static_friction=True),
                friction="coulomb",
                refine=False,
                validation=dynax.Validate(holdout=0),
            )
    sf = result.static_friction
    row = {
        "levels": {j.name: {"level": j.level, "kind": j.kind} for j in sf.joints},
        "rows_left_out": sf.rows_left_out,
        "rows": sf.rows,
    }
    print(part, row, flush=True)
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=pathlib.Path)
    parser.add_argument("--parts", default="shoulder,coulomb")
    parser.add_argument("--bands", default="0,0.03,0.1")
    parser.add_argument("--no-offsets", action="store_true")
    parser.add_argument("--both-fits", action="store_true", help="the band in the first fit too, not only the refit")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    bands = [float(b) for b in args.bands.split(",")]
    for part in args.parts.split(","):
        if part in ("light", "dfki"):
            (args.out / f"{part}.json").write_text(json.dumps(light_and_dfki(part), indent=2) + "\n")
            continue
        row = run(part, bands, args.no_offsets, args.both_fits)
        (args.out / f"{part}{'_both_fits' if args.both_fits else ''}.json").write_text(
            json.dumps(row, indent=2, default=str) + "\n"
        )


if __name__ == "__main__":
    main()
