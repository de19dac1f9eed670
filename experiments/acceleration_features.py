"""Which feature sets of the acceleration model close the hover gap to the linear model.

On the hover set of `experiments/helicopter_accuracy.py` the 78-weight linear model predicts
velocity better than the acceleration model. This experiment fits the acceleration model with
several feature sets by the same lagged criterion (H = 1 s, every 10th start time, from the one-step
fit) on the same 60 s training flights, and reports the held-out mean squared error at 1 and 2 s
(30 s held-out flights, every 5th start sample):

- `rich`: `RICH_FEATURES` (38 weights), the experiment's acceleration model;
- `full`: every body state, input and a bias on every axis, plus quadratic drag and the gyroscopic
  products (72 weights): is it the feature count?
- `rich, g = 9.12`: the rich model with gravity set to the linear model's fitted attitude coupling;
- `rich + attitude`: the rich model plus learned `roll` and `pitch` features on every axis (on top of
  the exact gravity);
- `linear`: the linear velocity model, for reference.

Run: `python experiments/acceleration_features.py [--out DIR] [--quick]` (default DIR
`experiments/results/acceleration_features`). Writes `DIR/features.json`.
"""

import argparse
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

from dynax import AccelerationModel, Helicopter, Lagged, LinearVelocityModel  # noqa: E402
from dynax.internal import (  # noqa: E402
    fit_lagged,
    fit_one_step,
    prediction_error,
    RICH_FEATURES,
    STATE_GROUPS,
    write_json,
)
from dynax.synthetic import generate_helicopter_flight  # noqa: E402

SEEDS = {"hover": (11, 12), "aerobatic": (21, 22)}  # as in helicopter_accuracy.py
_BASE = ("u", "v", "w", "p", "q", "r", "u1", "u2", "u3", "u4", "1")
FULL_FEATURES = {a: _BASE + (extra,) for a, extra in zip("uvwpqr", ("|u|u", "|v|v", "|w|w", "qr", "pr", "pq"))}
ATTITUDE_FEATURES = {a: features + ("roll", "pitch") for a, features in RICH_FEATURES.items()}


def models():
    rich = AccelerationModel.with_features(RICH_FEATURES)
    return {
        "rich": Helicopter(rich),
        "full": Helicopter(AccelerationModel.with_features(FULL_FEATURES)),
        "rich, g = 9.12": Helicopter(
            AccelerationModel(weights=rich.weights, feature_names=rich.feature_names, mask=rich.mask, gravity=9.12)
        ),
        "rich + attitude": Helicopter(AccelerationModel.with_features(ATTITUDE_FEATURES)),
        "linear": Helicopter(LinearVelocityModel()),
    }


def log(message):
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="experiments/results/acceleration_features")
    parser.add_argument("--quick", action="store_true", help="short hover flights, two iterations (smoke run)")
    args = parser.parse_args()
    train_s, test_s = (20.0, 10.0) if args.quick else (60.0, 30.0)
    sets = ("hover",) if args.quick else ("hover", "aerobatic")
    lagged = Lagged(horizon=1.0, stride=10, max_iterations=2 if args.quick else 15)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for kind in sets:
        train = generate_helicopter_flight(kind, train_s, seed=SEEDS[kind][0])
        test = generate_helicopter_flight(kind, test_s, seed=SEEDS[kind][1])
        results[kind] = {}
        for name, start in models().items():
            fit = fit_lagged(fit_one_step(start, train).model, train, lagged)
            errors = prediction_error(fit.model, test, [1.0, 2.0], stride=5)
            attitude = {
                k: float(v) for k, v in fit.model.body_model.parameters.items() if k.endswith(("/roll", "/pitch"))
            }
            results[kind][name] = {
                "n_weights": int(fit.model.body_model.parameter_vector().shape[0]),
                "mse_1s": {g: float(errors[g][0]) for g in STATE_GROUPS},
                "mse_2s": {g: float(errors[g][1]) for g in STATE_GROUPS},
                "attitude_weights": attitude,
            }
            log(f"{kind}, {name}: held-out MSE at 1 s " + ", ".join(f"{g} {errors[g][0]:.4g}" for g in STATE_GROUPS))
            write_json(
                out / "features.json",
                {"settings": {"train_s": train_s, "test_s": test_s, "quick": args.quick}, "results": results},
            )
    log(f"wrote {out / 'features.json'}")


if __name__ == "__main__":
    main()
