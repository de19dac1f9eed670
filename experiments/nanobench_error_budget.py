"""Where the 0.5 s prediction error of the held-out NanoBench flights comes from.

Takes a fitted quadrotor model (default: the best that `experiments/nanobench_heldout.py` writes,
the acceleration model fitted lagged and refined by backprop) and the held-out star, trefoil and oval flights, and
splits its open-loop error at h = 1, 10, 50 steps (0.01, 0.1, 0.5 s) by replacing one part of the
prediction with the measurement at a time:

- `as scored`: the rollout of the evaluation protocol (`dynax.predict_ahead`), from the measured
  sample;
- `smoothed start`: the same from a start state whose velocity and body rates are smoothed by a
  centred Savitzky-Golay filter (11 samples, quadratic). It uses samples after the start, which no
  predictor has, so it bounds from above what any estimate of the start state can gain;
- `attitude given`, `body rates given`, `attitude and rates given`: at every step the predicted
  attitude, body rates or both are replaced by the measured ones, so the position and velocity
  error left is that of the translational model (thrust and drag) alone;
- the same rows for the constant-velocity baseline where they apply (`smoothed start`).

It also measures how much of the measured angular acceleration (central differences of the body
rates) the motor inputs can explain at all: the share of its variance that a least-squares fit on
$m_i^2, m_i$ (battery-scaled), a constant, the rates and their products explains on the training
flights and on the held-out ones, with the inputs delayed by 0 to 6 samples and, separately,
low-passed as a first-order motor of time constant 0 to 70 ms.

Run: `python experiments/nanobench_error_budget.py [--model MODEL.json] [--out DIR] [--stride N]`
(default DIR `experiments/results/nanobench_error_budget`; `--stride` scores every N-th start).
Writes `DIR/budget.json` and `DIR/budget.png` (the position and body-rate error against horizon
per row).
"""

import argparse
import pathlib
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
from nanobench_heldout import flights, TEST, TRAIN
import numpy as np
from scipy.constants import g as STANDARD_GRAVITY
from scipy.signal import lfilter, savgol_filter
from scipy.spatial.transform import Rotation

import dynax
from dynax.internal import group_errors, write_json

H = 50
GROUPS = ("position", "velocity", "attitude", "body_rate")


def _rk4(model, x, u, dt):
    f = lambda y: model.vector_field(0.0, y, u)
    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _rollouts(model, given: tuple[int, ...]):
    """Rollouts of `H` steps from `x0s`; the states at `given` are set to the measurement before each step."""
    index = np.asarray(given, dtype=int)

    @jax.jit
    def run(x0s, xs, us, starts, dt):
        def window(x0, k):
            measured = jax.lax.dynamic_slice_in_dim(xs, k, H)
            inputs = jax.lax.dynamic_slice_in_dim(us, k, H)

            def step(x, data):
                xm, u = data
                if index.size:
                    x = x.at[index].set(xm[index])
                x = _rk4(model, x, u, dt)
                return x, x

            return jax.lax.scan(step, x0, (measured, inputs))[1]

        return jax.vmap(window)(x0s, starts)

    return run


def _smoothed(xs):
    xs = np.array(xs)
    xs[:, 7:13] = savgol_filter(xs[:, 7:13], 11, 2, axis=0)
    return xs


def mae_curve(model, runs, *, given=(), smooth=False, stride=1):
    """MAE per group at every horizon 1..H over the starts (every `stride`-th) of `runs`."""
    run = _rollouts(model, given)
    total, n = 0.0, 0
    for r in runs:
        xs = np.asarray(r.xs)
        starts = np.arange(5, len(xs) - H - 5, stride)  # room for the centred filter either side
        x0s = (_smoothed(xs) if smooth else xs)[starts]
        paths = run(jnp.asarray(x0s), jnp.asarray(xs), jnp.asarray(r.us), jnp.asarray(starts), r.dt)
        measured = jnp.stack([jnp.asarray(xs)[starts + h] for h in range(1, H + 1)], axis=1)
        total = total + np.asarray(jnp.sum(group_errors(paths, measured), axis=0))
        n += len(starts)
    return total / n, n


def _motor_inputs(us, tau, delay):
    m = np.asarray(us[:, :4]) * np.asarray(us[:, 4:5])
    m = m / np.median(m)
    if tau > 0:
        a = np.exp(-0.01 / tau)
        m = np.stack([lfilter([1 - a], [1, -a], m[:, i], zi=[a * m[0, i]])[0] for i in range(4)], axis=1)
    if delay:
        m = np.concatenate([np.repeat(m[:1], delay, axis=0), m[:-delay]])
    return m


def _moment_design(runs, tau, delay):
    rows, targets = [], []
    for r in runs:
        xs, dt = np.asarray(r.xs), r.dt
        w = xs[:, 10:13]
        m = _motor_inputs(np.asarray(r.us), tau, delay)
        mid = 0.5 * (m[1:-1] + m[:-2])  # the zero-order-held inputs either side of the sample
        wm = w[1:-1]
        products = np.stack([wm[:, 1] * wm[:, 2], wm[:, 0] * wm[:, 2], wm[:, 0] * wm[:, 1]], axis=1)
        rows.append(np.concatenate([mid**2, mid, np.ones((len(mid), 1)), wm, products], axis=1))
        targets.append((w[2:] - w[:-2]) / (2 * dt))
    return np.concatenate(rows), np.concatenate(targets)


def _thrust_design(runs, tau, delay):
    rows, targets = [], []
    for r in runs:
        xs, dt = np.asarray(r.xs), r.dt
        rotation = Rotation.from_quat(xs[:-1, [4, 5, 6, 3]]).as_matrix()  # scipy: scalar last
        body_z = rotation[:, :, 2]  # the body z axis in the world frame
        specific_force = (xs[1:, 7:10] - xs[:-1, 7:10]) / dt + np.array([0.0, 0.0, STANDARD_GRAVITY])
        m = _motor_inputs(np.asarray(r.us), tau, delay)[:-1]
        body_w = np.sum(body_z * xs[:-1, 7:10], axis=1, keepdims=True)
        rows.append(np.concatenate([m**2, m, np.ones((len(m), 1)), body_w], axis=1))
        targets.append(np.sum(body_z * specific_force, axis=1, keepdims=True))
    return np.concatenate(rows), np.concatenate(targets)


def explained_share(train, test, tau, delay, design=None):
    """The share of the target's variance (per axis) explained on train and test by a least-squares
    fit on the training flights: the angular acceleration (default) or, with `_thrust_design`, the
    specific force along the body z axis."""
    design = _moment_design if design is None else design
    a, y = design(train, tau, delay)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    at, yt = design(test, tau, delay)
    share = lambda a, y: 1 - ((y - a @ coef) ** 2).sum(0) / ((y - y.mean(0)) ** 2).sum(0)
    return share(a, y).tolist(), share(at, yt).tolist()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="experiments/results/nanobench_heldout/acceleration_lagged_backprop.json")
    parser.add_argument("--out", default="experiments/results/nanobench_error_budget")
    parser.add_argument("--stride", type=int, default=1)
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the loader's notes on corrupt readings: printed by nanobench_heldout
        test, _ = flights(TEST)
        train, _ = flights(TRAIN)
    model = dynax.load_model(args.model)
    attitude, rates = (3, 4, 5, 6), (10, 11, 12)
    rows = {
        "as scored": dict(model=model),
        "smoothed start": dict(model=model, smooth=True),
        "attitude given": dict(model=model, given=attitude),
        "body rates given": dict(model=model, given=rates),
        "attitude and rates given": dict(model=model, given=attitude + rates),
        "constant velocity": dict(model=dynax.ConstantVelocity()),
        "constant velocity, smoothed start": dict(model=dynax.ConstantVelocity(), smooth=True),
    }
    curves, table, n = {}, {}, 0
    for name, row in rows.items():
        curve, n = mae_curve(row.pop("model"), test, stride=args.stride, **row)
        curves[name] = curve
        table[name] = {g: [float(curve[h - 1, i]) for h in (1, 10, 50)] for i, g in enumerate(GROUPS)}
        print(f"{name:36s} h=50 MAE: " + ", ".join(f"{g} {table[name][g][-1]:.4f}" for g in GROUPS), flush=True)
    moments = {
        "delay_samples": {
            str(d): dict(zip(("train", "test"), explained_share(train, test, 0.0, d))) for d in range(0, 7)
        },
        "motor_time_constant_s": {
            str(t): dict(zip(("train", "test"), explained_share(train, test, t, 0)))
            for t in (0.0, 0.02, 0.03, 0.05, 0.07)
        },
        "thrust_delay_samples": {
            str(d): dict(zip(("train", "test"), explained_share(train, test, 0.0, d, _thrust_design)))
            for d in range(0, 7)
        },
    }
    best = max(moments["delay_samples"].values(), key=lambda v: float(np.mean(v["train"])))
    print(f"angular acceleration explained by the motor inputs (best delay, train / test): {best}")
    scored = table["as scored"]["position"][-1]
    budget = {
        "position_h50_as_scored": scored,
        "position_h50_share_from_start_state": 1 - table["smoothed start"]["position"][-1] / scored,
        "position_h50_share_from_attitude": 1 - table["attitude given"]["position"][-1] / scored,
        "position_h50_share_from_body_rates": 1 - table["body rates given"]["position"][-1] / scored,
        "position_h50_left_with_attitude_and_rates_given": table["attitude and rates given"]["position"][-1],
    }
    write_json(
        out / "budget.json",
        {
            "model": args.model,
            "test": list(TEST),
            "steps": [1, 10, 50],
            "n_starts": n,
            "stride": args.stride,
            "mae": table,
            "budget": budget,
            "angular_acceleration_explained_by_inputs": moments,
        },
    )
    print(budget)
    _figure(out, curves)
    print(f"wrote {out / 'budget.json'} and {out / 'budget.png'}")


def _figure(out, curves):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    horizon = np.arange(1, H + 1) * 0.01
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for ax, (i, group, unit) in zip(axes, ((0, "position", "m"), (2, "attitude", "rad"), (3, "body_rate", "rad/s"))):
        for name, curve in curves.items():
            ax.plot(horizon, curve[:, i], label=name, ls="--" if name.startswith("constant") else "-")
        ax.set(title=group.replace("_", " "), xlabel="horizon [s]", ylabel=f"MAE [{unit}]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Error budget of the 0.5 s prediction on the held-out NanoBench flights")
    fig.tight_layout()
    fig.savefig(out / "budget.png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
