"""The lagged quadrotor fit's ridge, chosen by cross-validation over the training flights' shapes.

The acceleration model's motor map has two features per motor ($m_i^2$ and $m_i$, battery-scaled) and a
constant on every axis; in flight the commands stay near hover, so the three are nearly collinear and the
lagged fit with the criterion's tiny ridge (`Lagged(ridge=1e-10)`, relative to the normal equations'
trace) gives them weights that cancel: on the held-out flights each motor feature's contribution to the
angular acceleration has a spread of 40-170 rad/s^2, and their sum carries the commands' sample-to-sample
noise into the one-step prediction (its body-rate error is above holding the rate). A larger ridge trades
some of the long-horizon fit for a smoother map.

The ridge is chosen on the training flights alone: leave one training shape out (circle, figure-eight,
helix, linear ramp, lissajous), fit `Lagged(horizon=0.5, stride=20, max_iterations=10, ridge=r)` on the
other four, score the left-out shape from every usable start at h = 1, 10, 50 steps; the score of `r` is
the mean over folds, groups (position, velocity, attitude, body rate) and horizons of the MAE divided by
the constant-velocity baseline's on the same starts (every group and horizon counts alike, as the
held-out table is read). The chosen ridge is then fitted on all training shapes and scored on the star,
trefoil and oval flights, beside the default ridge.

`--lag-weights relative` runs the same choice with `Lagged(lag_weights="relative")` (each lag's residual
divided by that lag's typical error on the fitted flights, see `dynax.Lagged`) instead of the paper's
uniform sum over lags; `--lag-weights 0.5` divides it by the square root of that error.

Run: `nice -n 5 python experiments/nanobench_ridge.py [--ridges 1e-10,1e-3,1e-2] [--lag-weights uniform]
[--out DIR]` (about 15 fits of a minute or more each). Writes `DIR/ridge.json` (default
`experiments/results/nanobench_ridge`) and the chosen fit as `DIR/acceleration_lagged_ridge.json`;
`--chosen R` scores a ridge already chosen without the cross-validation.
"""

import argparse
import json
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

from nanobench_heldout import flights, HORIZON_S, scores, STEPS, TEST, TRAIN
import numpy as np

import dynax
from dynax.internal import write_json


def fit(train, ridge, lag_weights="uniform"):
    start = dynax.Quadrotor.from_flights("acceleration", train)
    criterion = dynax.Lagged(horizon=HORIZON_S, stride=20, max_iterations=10, ridge=ridge, lag_weights=lag_weights)
    return dynax.fit_quadrotor(start, train, criterion, progress=False).model


def relative(mae, baseline):
    """MAE over the constant-velocity baseline's, per group and horizon."""
    return {g: [m / b for m, b in zip(mae[g], baseline[g])] for g in mae}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ridges", default="1e-10,1e-3,1e-2")
    parser.add_argument("--out", default=str(pathlib.Path(__file__).parent / "results" / "nanobench_ridge"))
    parser.add_argument("--chosen", type=float, help="skip the cross-validation: score this ridge (and the first)")
    parser.add_argument("--lag-weights", default="uniform", help="uniform, relative or a power from 0 to 1")
    args = parser.parse_args()
    lag_weights = args.lag_weights if args.lag_weights in ("uniform", "relative") else float(args.lag_weights)
    ridges = [float(r) for r in args.ridges.split(",")]
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    if args.chosen is not None:  # the held-out part alone, with a ridge already chosen
        table = held_out_scores(ridges[0], args.chosen, lag_weights, out)
        found = out / "ridge.json"
        result = json.loads(found.read_text()) if found.exists() else {}
        write_json(found, {**result, "held_out": table})
        return
    by_shape = {shape: flights((shape,))[0] for shape in TRAIN}
    folds = {}
    for left_out in TRAIN:
        train = [r for shape in TRAIN if shape != left_out for r in by_shape[shape]]
        held = by_shape[left_out]
        baseline = scores(dynax.flight_error(dynax.ConstantVelocity(), held, STEPS))["mae"]
        folds[left_out] = {"constant velocity": baseline}
        for ridge in ridges:
            start = time.perf_counter()
            mae = scores(dynax.flight_error(fit(train, ridge, lag_weights), held, STEPS))["mae"]
            folds[left_out][str(ridge)] = {"mae": mae, "relative": relative(mae, baseline)}
            score = np.mean([v for row in relative(mae, baseline).values() for v in row])
            print(
                f"left out {left_out:12s} ridge {ridge:8.0e}: mean MAE / constant velocity {score:.4f} "
                f"({time.perf_counter() - start:.0f} s)",
                flush=True,
            )
    cv_score = {
        str(r): float(np.mean([v for f in folds.values() for row in f[str(r)]["relative"].values() for v in row]))
        for r in ridges
    }
    chosen = min(ridges, key=lambda r: cv_score[str(r)])
    print(f"cross-validated scores {cv_score}; chosen ridge {chosen:g}", flush=True)
    write_json(
        out / "ridge.json",
        {
            "ridges": ridges,
            "lag_weights": lag_weights,
            "steps": list(STEPS),
            "folds": folds,
            "cv_score": cv_score,
            "chosen": chosen,
            "held_out": held_out_scores(ridges[0], chosen, lag_weights, out),
        },
    )


def held_out_scores(default: float, chosen: float, lag_weights, out: pathlib.Path) -> dict:
    """Fit on every training shape with the `default` and the `chosen` ridge, score on the held-out shapes (MAE,
    RMSE and cumulative MAE, as `nanobench_heldout.py`); the chosen fit is saved as a model file."""
    train, _ = flights(TRAIN)
    test, _ = flights(TEST)
    table = {"constant velocity": scores(dynax.flight_error(dynax.ConstantVelocity(), test, STEPS))}
    for ridge in sorted({default, chosen}):
        model = fit(train, ridge, lag_weights)
        table[str(ridge)] = scores(dynax.flight_error(model, test, STEPS))
        print(f"held-out flights, ridge {ridge:g}: {table[str(ridge)]['mae']}", flush=True)
        if ridge == chosen:
            dynax.save_model(model, out / "acceleration_lagged_ridge.json", family="acceleration", criterion="lagged")
    return table


if __name__ == "__main__":
    main()
