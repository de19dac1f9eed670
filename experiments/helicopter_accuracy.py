"""Simulator accuracy against horizon (Abbeel, Ganapathi and Ng 2005, Figure 2), on the dynax truth simulator.

For the hover and the aerobatic data sets (flown by `HelicopterTruth` under `FlightController` with
excitation; the Stanford logs are not public), five learned simulators are compared on held-out
flights: linear one-step, linear frequency-domain, linear lagged, acceleration one-step and
acceleration lagged. For each, the mean squared open-loop prediction error is plotted against the
horizon (0 to 2 s) for the four state groups. The EM-free lagged fit of the acceleration model is
then checked against the direct minimum of the same loss found by backprop (L-BFGS through the
checkpointed rollouts) and by Gauss-Newton on the true loss (the EM-free least squares with the
rollout's full Jacobian, `Lagged(state_sensitivities=True)`); the direct minimum is the lowest loss
either finds.

Run: `python experiments/helicopter_accuracy.py [--out DIR] [--data-out DIR2] [--quick]` (default DIR
`experiments/results/helicopter_accuracy`, DIR2 `out/helicopter_data`). Writes `DIR/accuracy.json`,
`DIR/accuracy.png` and the generated flights as contract CSVs `DIR2/{hover,aerobatic}_{train,test}.csv`
(seeds 11/12 hover, 21/22 aerobatic), which `dynax fit` / `dynax evaluate` read directly.
"""

import argparse
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dynax import Backprop, FrequencyDomain, Lagged, save_trajectory  # noqa: E402
from dynax.internal import (  # noqa: E402
    fit_backprop,
    fit_frequency,
    fit_lagged,
    fit_one_step,
    initial_helicopter,
    lagged_loss_gradient_norm,
    lagged_loss_of,
    prediction_error,
    recorded_loss,
    STATE_GROUPS,
    write_json,
)
from dynax.synthetic import generate_helicopter_flight  # noqa: E402

METHODS = ("linear one-step", "linear frequency", "linear lagged", "acceleration one-step", "acceleration lagged")
STYLES = {
    "linear one-step": dict(color="tab:gray", ls="--"),
    "linear frequency": dict(color="tab:purple", ls="--"),
    "linear lagged": dict(color="tab:blue", ls="--"),
    "acceleration one-step": dict(color="tab:orange", ls="-"),
    "acceleration lagged": dict(color="tab:red", ls="-"),
}
UNITS = {"velocity": "m$^2$/s$^2$", "angular_rate": "rad$^2$/s$^2$", "position": "m$^2$", "orientation": "rad$^2$"}


def log(message):
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def run_set(kind, args, out):
    seeds = {"hover": (11, 12), "aerobatic": (21, 22)}[kind]
    train = generate_helicopter_flight(kind, args.train_s, seed=seeds[0])
    test = generate_helicopter_flight(kind, args.test_s, seed=seeds[1])
    data_dir = pathlib.Path(args.data_out)
    save_trajectory(train, data_dir / f"{kind}_train.csv")
    save_trajectory(test, data_dir / f"{kind}_test.csv")
    log(f"{kind}: generated {args.train_s:g} s train and {args.test_s:g} s held-out flights")
    lagged = Lagged(horizon=args.horizon, stride=args.stride, max_iterations=args.iterations)
    fits, times = {}, {}

    def timed(name, fn):
        t0 = time.perf_counter()
        fits[name] = fn()
        times[name] = time.perf_counter() - t0
        log(f"{kind}: {name} fitted in {times[name]:.1f} s")

    linear, acceleration = initial_helicopter("linear"), initial_helicopter("acceleration", "rich")
    timed("linear one-step", lambda: fit_one_step(linear, train))
    timed("linear frequency", lambda: fit_frequency(linear, train, FrequencyDomain()))
    timed("linear lagged", lambda: fit_lagged(fits["linear one-step"].model, train, lagged))
    timed("acceleration one-step", lambda: fit_one_step(acceleration, train))
    timed("acceleration lagged", lambda: fit_lagged(fits["acceleration one-step"].model, train, lagged))

    horizons = np.round(np.arange(0, args.max_horizon + 1e-9, 0.1), 10)
    mse = {}
    for name in METHODS:
        errors = prediction_error(fits[name].model, test, horizons, stride=args.eval_stride)
        mse[name] = {g: np.asarray(errors[g]).tolist() for g in STATE_GROUPS}
        log(f"{kind}: {name}: held-out MSE at 1 s " + ", ".join(f"{g} {mse[name][g][10]:.4g}" for g in STATE_GROUPS))

    # The EM-free approximation against the direct minimum of the same lagged loss. The minimum is
    # found twice: by Gauss-Newton on the true loss (`Lagged(state_sensitivities=True)`, the EM-free
    # least squares with the rollout's full Jacobian) and by backprop (L-BFGS) started from the
    # better of the EM-free and Gauss-Newton results; the direct minimum is the lowest loss found.
    check_stride = args.check_stride
    em_free = fits["acceleration lagged"]
    em_loss = lagged_loss_of(em_free.model, train, args.horizon, stride=check_stride)
    t0 = time.perf_counter()
    gauss_newton = fit_lagged(
        fits["acceleration one-step"].model,
        train,
        Lagged(horizon=args.horizon, stride=check_stride, max_iterations=args.iterations, state_sensitivities=True),
    )
    gn_time = time.perf_counter() - t0
    log(f"{kind}: Gauss-Newton lagged loss {recorded_loss(gauss_newton):.6g} in {gn_time:.1f} s")
    start = gauss_newton if recorded_loss(gauss_newton) < em_loss else em_free
    t0 = time.perf_counter()
    direct = fit_backprop(
        start.model,
        train,
        Backprop(horizon=args.horizon, stride=check_stride, max_steps=args.backprop_steps),
        callback=lambda i, loss: log(f"{kind}: backprop step {i + 1}: {loss:.6g}") if (i + 1) % 5 == 0 else None,
    )
    direct_time = time.perf_counter() - t0
    minimum = min(recorded_loss(direct), recorded_loss(gauss_newton), em_loss)
    # The gradient of the true loss at the EM-free and Gauss-Newton points (zero at a minimum).
    grad_norm = {
        name: lagged_loss_gradient_norm(fit.model, train, args.horizon, stride=check_stride)
        for name, fit in (("em_free", em_free), ("gauss_newton", gauss_newton))
    }
    check = {
        "horizon_s": args.horizon,
        "stride": check_stride,
        "one_step_loss": lagged_loss_of(fits["acceleration one-step"].model, train, args.horizon, stride=check_stride),
        "em_free_loss": em_loss,
        "em_free_iterations": len(em_free.history) - 1,
        "em_free_seconds": times["acceleration lagged"],
        "em_free_gradient_norm": grad_norm["em_free"],
        "gauss_newton_loss": recorded_loss(gauss_newton),
        "gauss_newton_iterations": len(gauss_newton.history) - 1,
        "gauss_newton_seconds": gn_time,
        "gauss_newton_gradient_norm": grad_norm["gauss_newton"],
        "backprop_start": "gauss_newton" if start is gauss_newton else "em_free",
        "backprop_loss": recorded_loss(direct),
        "backprop_steps": len(direct.history) - 1,
        "backprop_seconds": direct_time,
        "direct_minimum": minimum,
        "relative_gap": em_loss / minimum - 1,
        "gauss_newton_relative_gap": recorded_loss(gauss_newton) / minimum - 1,
    }
    log(
        f"{kind}: EM-free lagged loss {em_loss:.6g}, Gauss-Newton {check['gauss_newton_loss']:.6g}, "
        f"backprop {check['backprop_loss']:.6g}; "
        f"EM-free gap to the minimum {check['relative_gap']:.2%}"
    )
    return {
        "horizons_s": horizons.tolist(),
        "mse": mse,
        "fit_seconds": times,
        "lagged_history": {n: [h[1] for h in fits[n].history] for n in ("linear lagged", "acceleration lagged")},
        "em_free_check": check,
        "parameters": {
            n: {k: float(v) for k, v in fits[n].model.body_model.parameters.items()}
            for n in ("acceleration one-step", "acceleration lagged")
        },
    }


def figure(results, path):
    sets = list(results)
    fig, axes = plt.subplots(len(sets), 4, figsize=(16, 3.6 * len(sets)), squeeze=False)
    for row, kind in enumerate(sets):
        horizons = results[kind]["horizons_s"]
        for col, group in enumerate(STATE_GROUPS):
            ax = axes[row, col]
            for name in METHODS:  # from the first sample on (the error at horizon 0 is zero)
                ax.plot(horizons[1:], results[kind]["mse"][name][group][1:], label=name, **STYLES[name])
            ax.set_yscale("log")
            ax.set_title(f"{kind}: {group.replace('_', ' ')}")
            ax.set_xlabel("horizon [s]")
            ax.set_ylabel(f"MSE [{UNITS[group]}]")
            ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Held-out open-loop prediction error against horizon (dynax truth simulator)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="experiments/results/helicopter_accuracy")
    parser.add_argument(
        "--data-out",
        default="out/helicopter_data",
        help="where the generated flights are written as contract CSVs (not committed)",
    )
    parser.add_argument("--quick", action="store_true", help="short flights, for a smoke run")
    parser.add_argument("--sets", default="hover,aerobatic")
    args = parser.parse_args()
    args.train_s, args.test_s = (20.0, 10.0) if args.quick else (60.0, 30.0)
    args.horizon, args.max_horizon = 1.0, 2.0
    args.stride = 10  # lagged fits use every 10th start time (600 windows of 1 s on 60 s of data)
    args.iterations = 3 if args.quick else 15
    args.eval_stride = 5
    args.check_stride = args.stride  # the direct minimum of the same objective the EM-free fit minimised
    args.backprop_steps = 5 if args.quick else 30
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for kind in args.sets.split(","):
        results[kind] = run_set(kind, args, out)
        write_json(out / "accuracy.json", {"settings": {k: v for k, v in vars(args).items()}, "results": results})
    figure(results, out / "accuracy.png")
    log(f"wrote {out / 'accuracy.json'} and {out / 'accuracy.png'}")


if __name__ == "__main__":
    main()
