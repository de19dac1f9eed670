"""What the best NanoBench flight model's first predicted step is made of, and which part the next sample wants.

The lagged acceleration model (`experiments/nanobench_ridge.py`) is behind the nominal model one step ahead on
body rate (`experiments/nanobench_paired.py`). Its angular acceleration at a start is a sum of parts: the motor
map (the $m_i^2$, $m_i$ features), the rate damping (the $p, q, r$ features on their own axes), and the rest (the
constant moment, the gyroscopic products, rotor drag on $u, v$). Over one sample each part moves the predicted rate
by $\\Delta t$ times its share. This scores, on the held-out flights (star, trefoil, oval; each model with its
commands as late as its file records, every model on the same starts: those `flight_error` scores), the one-step
body-rate MAE of the model as fitted and with each part removed (`dynax.predict_ahead`), and the least-squares
scale of each part that the measured one-step change of the rates asks for (the change regressed on the three
parts times $\\Delta t$, pooled over axes and starts): a part the first sample follows has a scale near 1, one it
does not near 0.


    python experiments/nanobench_first_step.py [MODEL.json ...] [--out FILE]

Default models: the ridge study's best (`experiments/results/nanobench_ridge/acceleration_lagged_ridge.json`) and
the nominal one-step fit (`experiments/results/nanobench_heldout/nominal_one-step.json`). Writes FILE (default
`experiments/results/nanobench_first_step/first_step.json`).
"""

import argparse
import json
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import dynax
from dynax.internal import write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import delayed_commands, flights, STEPS, TEST  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / "results"
DEFAULT = (
    RESULTS / "nanobench_ridge" / "acceleration_lagged_ridge.json",
    RESULTS / "nanobench_heldout" / "nominal_one-step.json",
)
RATES = slice(10, 13)


def parts(body) -> dict[str, np.ndarray]:
    """Column masks of the body model's features: motors, rate damping (p, q, r on any rate axis), the rest."""
    names = body.feature_names
    motors = np.array([any(f"m{i}" in n for i in range(1, 5)) and "sum" not in n for n in names])
    damping = np.array([n in ("p", "q", "r") for n in names])
    return {"motors": motors, "rate damping": damping, "rest": ~(motors | damping)}


def without(model, columns: np.ndarray):
    """`model` with the rate axes' weights of `columns` set to zero."""
    w = np.asarray(model.body_model.weights).copy()
    w[3:, columns] = 0.0
    body = eqx.tree_at(lambda b: b.weights, model.body_model, jnp.asarray(w))
    return model.with_body_model(body)


def one_step_mae(model, runs) -> float:
    """The body-rate MAE one step ahead, on the starts `flight_error` scores (the last `max(STEPS)` left out)."""
    total, n = 0.0, 0
    for run in runs:
        predicted = np.asarray(dynax.predict_ahead(model, run, (1, max(STEPS))))[:, 0, RATES]
        measured = np.asarray(run.xs)[1 : 1 + len(predicted), RATES]
        total += np.linalg.norm(predicted - measured, axis=-1).sum()
        n += len(predicted)
    return total / n


def shares(model, runs, masks):
    """Per start and rate axis: each part's angular acceleration times dt, and the measured one-step change."""
    body = model.body_model
    w = np.asarray(body.masked_weights())[3:]
    x_parts, changes = [], []
    for run in runs:
        frame = model.body_frame(run)
        n = len(run) - max(STEPS)  # the starts `one_step_mae` scores
        xs, us = frame.xs[:n], frame.us[:n]
        phi = np.asarray(jax.vmap(lambda x, u: body.features(x[3:7], x[7:13], u))(xs, us))  # (starts, features)
        dt = float(run.dt)
        x_parts.append(np.stack([dt * phi[:, m] @ w[:, m].T for m in masks.values()], axis=-1))  # (starts, 3, parts)
        rates = np.asarray(run.xs)[:, RATES]
        changes.append(rates[1 : n + 1] - rates[:n])
    return np.concatenate(x_parts), np.concatenate(changes)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", default=[str(p) for p in DEFAULT])
    parser.add_argument("--out", default=str(RESULTS / "nanobench_first_step" / "first_step.json"))
    args = parser.parse_args()
    test = flights(TEST)[0]
    out = {}
    paths = [pathlib.Path(m).resolve() for m in args.models]
    delays = [round(float(json.loads(p.read_text()).get("command_delay_s", 0.0)) / 0.01) for p in paths]
    first = max(delays)  # every model scored on the same starts
    for path, k in zip(paths, delays):
        runs = [delayed_commands(r, k, first) for r in test if len(r) > max(STEPS) + first]
        model = dynax.load_model(path)
        masks = parts(model.body_model)
        row = {"command_delay_samples": k, "as fitted": one_step_mae(model, runs)}
        for name, m in masks.items():
            row[f"without {name}"] = one_step_mae(without(model, m), runs)
        row["holding the rates"] = one_step_mae(dynax.ConstantVelocity(), runs)
        x, y = shares(model, runs, masks)
        a = x.reshape(-1, x.shape[-1])
        scale, *_ = np.linalg.lstsq(a, y.reshape(-1), rcond=None)
        row["least-squares scale"] = dict(zip(masks, scale.tolist()))
        row["rms share [rad/s]"] = dict(zip(masks, np.sqrt(np.mean(x**2, axis=(0, 1))).tolist()))
        row["rms measured change [rad/s]"] = float(np.sqrt(np.mean(y**2)))
        out[str(path.relative_to(RESULTS.parent.parent))] = row
        print(path.name, json.dumps(row, indent=1), flush=True)
    file = pathlib.Path(args.out)
    file.parent.mkdir(parents=True, exist_ok=True)
    write_json(file, out)


if __name__ == "__main__":
    main()
