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

`--command-delays 0,0.02,0.03,0.04` chooses the motor commands' dead time the same way, with the ridge: every
(ridge, delay) pair is fitted on four training shapes with the commands applied that late
(`nanobench_heldout.delayed_commands`, what `dynax.MotorDelay`'s exact shift does for a whole number of samples)
and scored on the fifth with them; every delay of the grid is scored on the same starts (each run from the
longest delay's row on). The chosen delay is a property of the model: its file records it (`command_delay_s`),
and the held-out flights are scored with their commands applied that late.

`--lag-weights relative` runs the same choice with `Lagged(lag_weights="relative")` (each lag's residual
divided by that lag's typical error on the fitted flights, see `dynax.Lagged`) instead of the paper's
uniform sum over lags; `--lag-weights 0.5` divides it by the square root of that error.

Run: `nice -n 5 python experiments/nanobench_ridge.py [--ridges 1e-10,1e-3,1e-2] [--command-delays 0]
[--lag-weights uniform] [--out DIR]` (5 fits per (ridge, delay) pair, a minute or more each). Writes
`DIR/ridge.json` (default `experiments/results/nanobench_ridge`) and the chosen fit as
`DIR/acceleration_lagged_ridge.json`; `--chosen R` (and `--chosen-delay D`) scores a ridge (and delay) already
chosen without the cross-validation.
"""

import argparse
import json
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

from nanobench_heldout import delayed_commands, flights, HORIZON_S, scores, STEPS, TEST, TRAIN
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


def delayed(runs, delay: float, first: int):
    """`runs` with their motor commands `delay` seconds late, each from row `first` on."""
    return [delayed_commands(r, round(delay / 0.01), first) for r in runs]


def label(ridge: float, delay: float) -> str:
    """A (ridge, delay) pair's key in `ridge.json`: the ridge alone where the commands are not delayed."""
    return str(ridge) if delay == 0 else f"{ridge}, delay {delay:g} s"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ridges", default="1e-10,1e-3,1e-2")
    parser.add_argument("--command-delays", default="0", help="the commands' dead times to choose from [s]")
    parser.add_argument(
        "--score-from-delay",
        type=float,
        help="score each run from the row this delay [s] needs (default the longest of --command-delays): a grid run "
        "in parts scores every part on the same starts",
    )
    parser.add_argument("--out", default=str(pathlib.Path(__file__).parent / "results" / "nanobench_ridge"))
    parser.add_argument("--chosen", type=float, help="skip the cross-validation: score this ridge (and the first)")
    parser.add_argument("--chosen-delay", type=float, default=0.0, help="with --chosen: the commands' dead time [s]")
    parser.add_argument("--lag-weights", default="uniform", help="uniform, relative or a power from 0 to 1")
    args = parser.parse_args()
    lag_weights = args.lag_weights if args.lag_weights in ("uniform", "relative") else float(args.lag_weights)
    ridges = [float(r) for r in args.ridges.split(",")]
    delays = [float(d) for d in args.command_delays.split(",")]
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    if args.chosen is not None:  # the held-out part alone, with a ridge already chosen
        table = held_out_scores(ridges[0], args.chosen, lag_weights, out, args.chosen_delay)
        found = out / "ridge.json"
        result = json.loads(found.read_text()) if found.exists() else {}
        write_json(found, {**result, "held_out": table})
        return
    first = round(max(delays if args.score_from_delay is None else [*delays, args.score_from_delay]) / 0.01)
    by_shape = {shape: flights((shape,))[0] for shape in TRAIN}
    folds = {}
    for left_out in TRAIN:
        baseline = scores(dynax.flight_error(dynax.ConstantVelocity(), delayed(by_shape[left_out], 0, first), STEPS))
        folds[left_out] = {"constant velocity": baseline["mae"]}
        for delay in delays:
            train = delayed([r for shape in TRAIN if shape != left_out for r in by_shape[shape]], delay, first)
            held = delayed(by_shape[left_out], delay, first)
            for ridge in ridges:
                start = time.perf_counter()
                mae = scores(dynax.flight_error(fit(train, ridge, lag_weights), held, STEPS))["mae"]
                rel = relative(mae, baseline["mae"])
                folds[left_out][label(ridge, delay)] = {"mae": mae, "relative": rel}
                print(
                    f"left out {left_out:12s} ridge {ridge:8.0e} delay {delay:5.3f} s: mean MAE / constant velocity "
                    f"{np.mean([v for row in rel.values() for v in row]):.4f} ({time.perf_counter() - start:.0f} s)",
                    flush=True,
                )
    pairs = [(r, d) for d in delays for r in ridges]
    cv_score = {
        label(r, d): float(
            np.mean([v for f in folds.values() for row in f[label(r, d)]["relative"].values() for v in row])
        )
        for r, d in pairs
    }
    chosen, chosen_delay = min(pairs, key=lambda p: cv_score[label(*p)])
    print(f"cross-validated scores {cv_score}; chosen ridge {chosen:g}, delay {chosen_delay:g} s", flush=True)
    write_json(
        out / "ridge.json",
        {
            "ridges": ridges,
            "command_delays_s": delays,
            "lag_weights": lag_weights,
            "steps": list(STEPS),
            "folds": folds,
            "cv_score": cv_score,
            "chosen": chosen,
            "chosen_delay_s": chosen_delay,
            "held_out": held_out_scores(ridges[0], chosen, lag_weights, out, chosen_delay),
        },
    )


def held_out_scores(default: float, chosen: float, lag_weights, out: pathlib.Path, delay: float = 0.0) -> dict:
    """Fit on every training shape with the `default` and the `chosen` ridge (the commands `delay` seconds late),
    score on the held-out shapes (MAE, RMSE and cumulative MAE, as `nanobench_heldout.py`); the chosen fit is
    saved as a model file, with its delay."""
    k = round(delay / 0.01)
    train = delayed(flights(TRAIN)[0], delay, k)
    test = delayed(flights(TEST)[0], delay, k)
    table = {"constant velocity": scores(dynax.flight_error(dynax.ConstantVelocity(), test, STEPS))}
    for ridge in sorted({default, chosen}):
        model = fit(train, ridge, lag_weights)
        table[label(ridge, delay)] = scores(dynax.flight_error(model, test, STEPS))
        print(f"held-out flights, {label(ridge, delay)}: {table[label(ridge, delay)]['mae']}", flush=True)
        if ridge == chosen:
            dynax.save_model(
                model,
                out / "acceleration_lagged_ridge.json",
                family="acceleration",
                criterion="lagged",
                command_delay_s=k * 0.01,
            )
    return table


if __name__ == "__main__":
    main()
