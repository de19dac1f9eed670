"""Which window start states make the DFKI run 12's held-out windows worse, and why (issue 48).

    python experiments/dfki_run12_starts.py --runs 12,02,03

No fit: the lab's `model_3.0` (in-sample on every run, the same for every kind of start) is simulated
open loop from the 200 windows `dfki_default_identification.py` scores, on each run resampled at its
median interval, from five kinds of start velocity:

- `logged`: the rig's `vel_meas` columns (backward differences of the angles on the stamps);
- `central, stamps`: central differences of the angles on the logged stamps (`load_trajectory(velocities=
  "positions")` before the angles' times were read);
- `central, angle times`: the same on the times the angles imply (`sample_times_from_positions`; what
  `load_trajectory(velocities="positions")` does now);
- `central, re-timed rows`: as above with the rows themselves moved to those times before resampling;
- `local cubic`: `velocities_from_positions` (the refinement's Savitzky-Golay cubic, its window half a
  period of the band `choose_filter` reads off the logged record) on the resampled record.

Prints and writes (`experiments/results/dfki_velocities/run12_starts.json`) the position RMSE at 0.1,
0.25 and 0.5 s per run and per stretch (run 12: the pumping before 3.4 s, the fast spin 3.4 to 4.1 s,
the swing down 4.1 to 5 s, the rest under load after 5 s), the start velocities' rms difference from
`central, angle times` per stretch (`dv`) and each kind's peak speeds there (rad/s), the rows whose
stamps the angles move, and the windows whose error rises most from `logged` to `central, stamps`
starts with their distance from the nearest such row.

`--clean-records` instead reads 72 clean arm records made apart from dynax's model code
(`tests.reference.arm_reference` by scipy's DOP853 under a random elbow multisine of two levels, 10 s at
100, 250, 500 and 1000 Hz, time uniform or jittered by 40 % of a step, angles exact, on 14-bit counts
or with 1 mrad of noise) and counts the stamps `sample_times_from_positions` moves (none should move).

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets.
"""

import argparse
import json
import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

from dfki_default_identification import HORIZONS, lab_model, load  # noqa: E402
from dfki_simulation import DFKI, MAPPING, read_parameters  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
from dynax.internal import (  # noqa: E402
    choose_filter,
    position_fit_window,
    sample_times_from_positions,
    velocities_from_positions,
)

STRETCHES = {
    "12": {"pumping": (0.0, 3.4), "spin": (3.4, 4.1), "swing down": (4.1, 5.0), "rest": (5.0, 6.1)},
}


def starts_of(run: str) -> tuple[dict[str, dynax.Trajectory], dict]:
    """The run resampled at its median interval with each kind of start velocity, and what was read."""
    logged = load(run, velocities="measured")
    raw = dynax.load_trajectory(
        DFKI / "sys_id" / f"trajectory_{run}.csv", "double_pendulum", mapping=MAPPING, check=False
    )
    ts, xs, dt = np.asarray(raw.ts), np.asarray(raw.xs), logged.dt
    sampled, rows = sample_times_from_positions(ts, xs[:, :2])

    def record(times, velocities, stamps=ts):
        states = np.column_stack([xs[:, :2], velocities])
        return dynax.resample(
            dynax.Trajectory(stamps, states, raw.us, raw.state_names, raw.input_names, raw.system), dt
        )

    choice = choose_filter(logged)
    assert choice.cutoff_hz is not None
    kinds = {
        "logged": logged,
        "central, stamps": record(ts, np.asarray(dynax.central_difference(ts, xs[:, :2]))),
        "central, angle times": load(run, velocities="positions"),
        "central, re-timed rows": record(sampled, np.asarray(dynax.central_difference(sampled, xs[:, :2])), sampled),
        "local cubic": dynax.Trajectory(
            logged.ts,
            velocities_from_positions(np.asarray(logged.xs), dt, choice.cutoff_hz),
            logged.us,
            logged.state_names,
            logged.input_names,
            logged.system,
        ),
    }
    read = {
        "dt_s": dt,
        "band_hz": choice.cutoff_hz,
        "local_cubic_window": position_fit_window(choice.cutoff_hz, dt),
        "rows_retimed": len(rows),
        "retimed_at_s": [round(float(ts[r]), 4) for r in rows],
        "retime_shift_ms": [round(float(1e3 * (sampled[r] - ts[r])), 2) for r in rows],
    }
    return kinds, read | {"retimed_times": ts[rows]}


def clean_records() -> dict:
    """The stamps moved on clean arm records (module docstring), by record."""
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
    from scipy.integrate import solve_ivp

    from tests.reference import arm_reference

    theta = [float(v) for v in dynax.Acrobot().base_parameters.values()]
    count = 2 * np.pi / 16384
    moved = {}
    for seed in range(3):
        rng = np.random.default_rng(seed)
        freqs, phases, level = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6), (3.0, 8.0)[seed % 2]

        def tau(t, freqs=freqs, phases=phases, level=level):
            return level * np.sum(np.sin(2 * np.pi * freqs * t + phases)) / np.sqrt(6)

        for rate in (100, 250, 500, 1000):
            for jitter in (0.0, 0.4):
                n = 10 * rate
                ts = np.sort(np.arange(n) / rate + rng.uniform(-jitter, jitter, n) / rate)
                sol = solve_ivp(
                    lambda t, x: arm_reference(theta, x, (0.0, tau(t))),
                    (ts[0], ts[-1]),
                    [0.2, 0.0, 0.0, 0.0],
                    t_eval=ts,
                    method="DOP853",
                    rtol=1e-11,
                    atol=1e-12,
                )
                q = sol.y[:2].T
                for noise, angles in (
                    ("exact", q),
                    ("14-bit", np.round(q / count) * count),
                    ("1 mrad", q + rng.normal(0, 1e-3, q.shape)),
                ):
                    rows = sample_times_from_positions(ts, angles)[1]
                    moved[f"seed {seed}, level {level:g}, {rate} Hz, jitter {jitter:g}, {noise}"] = len(rows)
    print(f"{len(moved)} clean records, {sum(moved.values())} stamps moved")
    return moved


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="12,02,03")
    parser.add_argument("--out", default="experiments/results/dfki_velocities/run12_starts.json")
    parser.add_argument("--clean-records", action="store_true", help="the clean arm records instead of the DFKI runs")
    args = parser.parse_args(argv)
    if args.clean_records:
        path = pathlib.Path(args.out).with_name("clean_record_stamps.json")
        path.write_text(json.dumps(clean_records(), indent=1))
        return
    lab = lab_model(read_parameters("model_3.0"))
    out = {"horizons_s": list(HORIZONS), "runs": {}}
    for run in args.runs.split(","):
        kinds, read = starts_of(run)
        retimed = read.pop("retimed_times")
        errors = {k: dynax.simulation_error(lab, v, HORIZONS) for k, v in kinds.items()}
        starts = np.asarray(errors["logged"].starts)
        t0 = np.asarray(kinds["logged"].ts)[starts]
        stretches = STRETCHES.get(run, {"all": (0.0, np.inf)})
        reference = np.asarray(kinds["central, angle times"].xs)[starts, 2:]
        result = {"read": read, "kinds": {}}
        print(
            f"run {run}: {read['rows_retimed']} rows re-timed; band {read['band_hz']:.3g} Hz, local cubic of "
            f"{read['local_cubic_window']} samples ({read['local_cubic_window'] * read['dt_s'] * 1e3:.0f} ms)"
        )
        for kind, error in errors.items():
            mse = np.asarray(error.window_mse)
            velocities = np.asarray(kinds[kind].xs)[starts, 2:]
            whole, t_all = np.asarray(kinds[kind].xs)[:, 2:], np.asarray(kinds[kind].ts)
            per = {}
            for name, (a, b) in stretches.items():
                inside = (t0 >= a) & (t0 < b)
                per[name] = {
                    "windows": int(inside.sum()),
                    "rmse": [float(np.sqrt(mse[inside, h].mean())) for h in range(len(HORIZONS))],
                    "start_velocity_rms_difference": float(
                        np.sqrt(np.mean((velocities[inside] - reference[inside]) ** 2))
                    ),
                    # on every sample of the stretch, not only the windows' starts
                    "peak_speed": [float(v) for v in np.abs(whole[(t_all >= a) & (t_all < b)]).max(axis=0)],
                }
            result["kinds"][kind] = {"rmse": [float(r) for r in np.asarray(error.rmse)], "stretches": per}
            cells = " | ".join(
                f"{name} "
                + " ".join(f"{r:.4f}" for r in cell["rmse"])
                + f" (dv {cell['start_velocity_rms_difference']:.2f}, peak "
                + "/".join(f"{v:.1f}" for v in cell["peak_speed"])
                + ")"
                for name, cell in per.items()
            )
            print(f"  {kind:24s} all " + " ".join(f"{r:.4f}" for r in result["kinds"][kind]["rmse"]) + f" | {cells}")
        # the windows that carry the difference between the logged and the stamp-based central starts at 0.1 s
        logged, central = (np.asarray(errors[k].window_mse)[:, 0] for k in ("logged", "central, stamps"))
        increase = central - logged
        order = np.argsort(-increase)[:5]
        nearest = [float(np.min(np.abs(retimed - t0[k]))) if retimed.size else float("inf") for k in order]
        result["largest_increases"] = [
            {"start_s": float(t0[k]), "increase": float(increase[k]), "nearest_retimed_row_ms": 1e3 * d}
            for k, d in zip(order, nearest)
        ]
        total = float(increase.sum())
        # the share the three largest carry, where the stamp-based starts are worse overall
        result["share_of_increase_top3"] = float(np.sort(increase)[::-1][:3].sum() / total) if total > 0 else None
        print(
            f"  windows whose 0.1 s error rises most from logged to central-on-stamps starts (total change {total:+.3g}"
            + (f", top 3 {result['share_of_increase_top3']:.0%} of it" if total > 0 else "")
            + "): "
            + ", ".join(
                f"t={e['start_s']:.3f} s ({e['nearest_retimed_row_ms']:.1f} ms from a re-timed row)"
                for e in result["largest_increases"][:3]
            )
        )
        out["runs"][run] = result
    path = pathlib.Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
