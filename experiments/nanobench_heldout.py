"""Held-out flight prediction on NanoBench: fit on some trajectory shapes, score on shapes never seen.

Fits the quadrotor models on the circle, figure-eight, helix, linear-ramp and lissajous flights and
scores them on the star, trefoil and oval flights (`../shared/datasets/nanobench`), as flight models
are scored: from every usable sample, open loop under the recorded motor commands, h = 1, 10, 50
steps (0.01, 0.1, 0.5 s); MAE and RMSE per group (position m, world velocity m/s, attitude rad,
body rate rad/s) and the cumulative MAE over h = 1..50, beside the constant-velocity baseline.

Models: the rigid-body nominal (one-step and lagged), the acceleration model (one-step, lagged
EM-free, H = 0.5 s, and that lagged fit refined by backprop on the same loss: L-BFGS through the
rollouts, warm-started from the EM-free weights, which stop above the loss's minimum) and the
linear velocity-prediction baseline (one-step). Ground segments and
glitches are left out of both fitting and scoring (`dynax.load_flight`, `dynax.usable_segments`).

Run: `python experiments/nanobench_heldout.py [--out DIR] [--quick]` (default DIR
`experiments/results/nanobench_heldout`). Writes `DIR/heldout.json`, `DIR/heldout.md` (MAE at h = 1 /
10 / 50 and, in brackets, the cumulative MAE), `DIR/horizon.png` (MAE per group against the horizon)
and `DIR/path.png` (a held-out flight's 3-D path with 0.5 s predictions).
"""

import argparse
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import dynax
from dynax.internal import write_json

DATA = pathlib.Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "nanobench"
# The documented map of the NanoBench logs (docs/flight_data.md).
NANOBENCH_MAP = {
    "x": "px",
    "y": "py",
    "z": "pz",
    "p": "wx_vicon",
    "q": "wy_vicon",
    "r": "wz_vicon",
    "m1": "motor_motor_m1",
    "m2": "motor_motor_m2",
    "m3": "motor_motor_m3",
    "m4": "motor_motor_m4",
    "vbat": "pwr_pm_vbat",
}
TRAIN = ("circle", "figure8", "helix", "linear_ramp", "lissajous")
TEST = ("star", "trefoil", "oval")
STEPS = (1, 10, 50)
HORIZON_S = 0.5


def flights(shapes):
    runs, notes = [], {}
    for path in sorted(DATA.glob("*.csv.gz")):
        if any(f"_{shape}_" in path.name for shape in shapes):
            trajectory, found = dynax.load_flight(path, mapping=NANOBENCH_MAP)
            notes[path.name] = found.describe()
            runs += dynax.usable_segments(trajectory, found, max(STEPS) + 2)
    return runs, notes


def command_delay(option: str, train) -> int:
    """The commands' dead time in samples: `option` seconds, or 'scan' (chosen on the training flights only)."""
    if option != "scan":
        return int(round(float(option) / 0.01))
    from nanobench_delay import DELAYS, scan

    runs = []
    for r in train:
        if len(r) >= 400:
            rates = [r.state_names.index(n) for n in ("p", "q", "r")]
            motors = [r.input_names.index(f"m{i}") for i in range(1, 5)]
            runs.append((r.source, float(r.dt), np.asarray(r.us)[:, motors], np.asarray(r.xs)[:, rates]))
    fit_r2, _ = scan(runs, runs[:1], lags=(0.0,))
    return int(DELAYS[int(np.argmax(fit_r2[0, :, :2].mean(axis=-1)))])


def delayed_commands(run, k: int, first: int | None = None):
    """`run` with its motor commands applied `k` samples late (row i carries the commands of row i - k) from row
    `first` on (default k: the rows without commands that early are left out; a larger `first` lines up runs
    delayed by different times on the same rows); `vbat` is left as it is."""
    first = k if first is None else first
    if first < k:
        raise ValueError(f"delayed_commands: row {first} has no commands {k} samples earlier")
    if first == 0:
        return run
    us = np.asarray(run.us)[first:].copy()
    motors = [run.input_names.index(f"m{i}") for i in range(1, 5)]
    us[:, motors] = np.asarray(run.us)[first - k : len(run) - k, motors]
    return dynax.Trajectory(
        run.ts[first:], run.xs[first:], us, run.state_names, run.input_names, run.system, run.source
    )


def scores(error):
    return {
        "mae": error.table("mae"),
        "rmse": error.table("rmse"),
        "cumulative_mae": {g: float(v) for g, v in zip(error.state_names, error.cumulative_mae)},
        "n_starts": error.n_windows,
        "diverged_fraction": error.diverged_fraction,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="experiments/results/nanobench_heldout")
    parser.add_argument("--quick", action="store_true", help="one-step fits only (minutes less)")
    parser.add_argument("--stride", type=int, default=20, help="lagged fit: every N-th start (default 20)")
    parser.add_argument("--backprop-steps", type=int, default=30, help="backprop refinement's L-BFGS steps")
    parser.add_argument(
        "--command-delay",
        default="0",
        help="apply the motor commands this many seconds late ('scan': the dead time the training flights' "
        "commands-to-angular-acceleration scan chooses, experiments/nanobench_delay.py; default 0)",
    )
    parser.add_argument(
        "--plans", default="", help="comma-separated models to fit, e.g. 'acceleration (lagged)' (default all)"
    )
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    train, train_notes = flights(TRAIN)
    test, test_notes = flights(TEST)
    delay_samples = command_delay(args.command_delay, train)
    if delay_samples:
        train = [delayed_commands(r, delay_samples) for r in train]
        test = [delayed_commands(r, delay_samples) for r in test]
        print(f"motor commands applied {delay_samples} samples ({delay_samples * 10} ms) late", flush=True)
    print(
        f"train: {len(train)} runs, {sum(len(r) for r in train)} samples; "
        f"test: {len(test)} runs, {sum(len(r) for r in test)} samples",
        flush=True,
    )
    plans = [("nominal", "one-step"), ("acceleration", "one-step"), ("linear", "one-step")]
    if not args.quick:
        plans += [("nominal", "lagged"), ("acceleration", "lagged"), ("acceleration", "lagged + backprop")]
    if args.plans:
        wanted = [p.strip() for p in args.plans.split(",")]
        plans = [(f, c) for f, c in plans if f"{f} ({c})" in wanted]
    fitted, table = {}, {}
    table["constant velocity"] = scores(dynax.flight_error(dynax.ConstantVelocity(), test, STEPS))
    for family, criterion in plans:
        name = f"{family} ({criterion})"
        start = time.perf_counter()
        if criterion == "lagged + backprop":  # refines the lagged fit just made (its time added)
            refine = dynax.Backprop(horizon=HORIZON_S, stride=args.stride, max_steps=args.backprop_steps)
            solution = dynax.fit_quadrotor(fitted[f"{family} (lagged)"], train, refine, warm_start=True)
            seconds = time.perf_counter() - start + table[f"{family} (lagged)"]["fit_seconds"]
        else:
            strategy = (
                dynax.OneStep()
                if criterion == "one-step"
                else dynax.Lagged(horizon=HORIZON_S, stride=args.stride, max_iterations=10)
            )
            solution = dynax.fit_quadrotor(dynax.Quadrotor.from_flights(family, train), train, strategy)
            seconds = time.perf_counter() - start
        fitted[name] = solution.model
        table[name] = scores(dynax.flight_error(solution.model, test, STEPS))
        table[name]["fit_seconds"] = seconds
        table[name]["n_weights"] = int(solution.value.shape[0])
        if solution.history:  # lagged, backprop: the lagged loss on the training flights
            table[name]["train_lagged_loss"] = float(solution.history[-1][1])
        mae = table[name]["mae"]
        print(
            f"{name:28s} fit {seconds:6.1f} s   h=50 MAE: position {mae['position'][-1]:.4f} m, velocity "
            f"{mae['velocity'][-1]:.4f} m/s, attitude {mae['attitude'][-1]:.4f} rad, body rate "
            f"{mae['body_rate'][-1]:.4f} rad/s",
            flush=True,
        )
        file = f"{family}_{criterion.replace(' + ', '_')}.json"
        dynax.save_model(
            solution.model, out / file, family=family, criterion=criterion, command_delay_s=delay_samples * 0.01
        )

    cv = table["constant velocity"]["mae"]
    nominal_names = [n for n in table if n.startswith("nominal")]
    summary = {}
    for name in table:
        if name == "constant velocity":
            continue
        mae = table[name]["mae"]
        beats_nominal = all(
            mae[g][i] < table[nom]["mae"][g][i] for nom in nominal_names for g in mae for i in range(len(STEPS))
        )
        summary[name] = {
            "position_gain_over_cv_h50": cv["position"][-1] / mae["position"][-1],
            "body_rate_gain_over_cv_h50": cv["body_rate"][-1] / mae["body_rate"][-1],
            "beats_every_nominal_everywhere": bool(beats_nominal) if not name.startswith("nominal") else None,
        }
    result = {
        "train": list(TRAIN),
        "test": list(TEST),
        "steps": list(STEPS),
        "dt_s": 0.01,
        "map": NANOBENCH_MAP,
        "command_delay_samples": delay_samples,
        "table": table,
        "summary": summary,
        "notes": {"train": train_notes, "test": test_notes},
    }
    write_json(out / "heldout.json", result)
    (out / "heldout.md").write_text(markdown_table(table))
    print(markdown_table(table))
    print(f"wrote {out / 'heldout.json'} and {out / 'heldout.md'}")
    _figures(out, fitted, test)


def markdown_table(table) -> str:
    """MAE at h = 1, 10, 50 (0.01, 0.1, 0.5 s) and the cumulative MAE per group, one row per model."""
    groups = ("position", "velocity", "attitude", "body_rate")
    units = {"position": "m", "velocity": "m/s", "attitude": "rad", "body_rate": "rad/s"}
    head = "| model | " + " | ".join(f"{g.replace('_', ' ')} [{units[g]}]" for g in groups) + " |"
    lines = [head, "|---|" + "---|" * len(groups)]
    for name, row in table.items():
        cells = [" / ".join(f"{v:.4f}" for v in row["mae"][g]) + f" ({row['cumulative_mae'][g]:.4f})" for g in groups]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _figures(out, fitted, test):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    horizon = list(range(1, max(STEPS) + 1))
    models = {"constant velocity": dynax.ConstantVelocity(), **fitted}
    curves = {name: dynax.flight_error(model, test, horizon) for name, model in models.items()}
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.8))
    for ax, (i, group) in zip(axes, enumerate(next(iter(curves.values())).state_names)):
        for name, error in curves.items():
            ax.plot(
                np.asarray(horizon) * 0.01,
                np.asarray(error.mae_per_state)[:, i],
                label=name,
                ls="--" if name == "constant velocity" else "-",
            )
        unit = {"position": "m", "velocity": "m/s", "attitude": "rad", "body_rate": "rad/s"}[group]
        ax.set(title=group.replace("_", " "), xlabel="horizon [s]", ylabel=f"MAE [{unit}]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("NanoBench held-out flights (star, trefoil, oval): open-loop error against horizon")
    fig.tight_layout()
    fig.savefig(out / "horizon.png", dpi=120)
    plt.close(fig)

    run = max(test, key=len)
    best = min(fitted, key=lambda n: float(np.asarray(curves[n].mae_per_state)[-1, 0]))
    predicted = np.asarray(dynax.predict_ahead(fitted[best], run, range(1, max(STEPS) + 1)))
    baseline = np.asarray(dynax.predict_ahead(dynax.ConstantVelocity(), run, range(1, max(STEPS) + 1)))
    xs = np.asarray(run.xs)
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    ax.plot(*xs[:, :3].T, color="k", lw=1, label="measured")
    for j, k in enumerate(range(0, predicted.shape[0], 100)):
        ax.plot(*predicted[k, :, :3].T, color="tab:red", lw=1.5, label=f"{best}, 0.5 s ahead" if j == 0 else None)
        ax.plot(
            *baseline[k, :, :3].T,
            color="tab:blue",
            lw=1,
            ls="--",
            label="constant velocity, 0.5 s ahead" if j == 0 else None,
        )
    ax.set(
        xlabel="x [m]",
        ylabel="y [m]",
        zlabel="z [m]",
        title=f"{pathlib.Path(run.source).name}: predicted against measured",
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "path.png", dpi=120)
    plt.close(fig)
    print(f"wrote {out / 'horizon.png'} and {out / 'path.png'}")


if __name__ == "__main__":
    main()
