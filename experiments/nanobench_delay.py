"""Command-to-motion delay of the NanoBench Crazyflie: how late the body rates answer the motor commands.

A rigid body's angular acceleration follows the moments of its rotors, and the moments follow the
motor commands through the motors' response (and any latency of the logging chain). This scan
regresses the measured angular acceleration (a Savitzky-Golay derivative of the body rates) on the
motor features $m_i^2, m_i, 1$ taken $k$ samples earlier and passed through a first-order lag of
time constant $\\tau$, over a grid of $(k, \\tau)$: the regression's coefficients are fitted on the
training flights (circle, figure-eight, helix, ramp, lissajous) and its $R^2$ is scored on the
held-out flights (star, trefoil, oval), for the body rates of the motion capture (the map's `p, q, r`)
and of the on-board gyro (`imu_gyro_*`, a second, independent sensor). The grid point the training
flights choose is then checked on the flights no fit has seen.

A dead time shows as a peak of $R^2$ at $k > 0$ with $\\tau = 0$; a motor lag as a peak at $k = 0$,
$\\tau > 0$. The motion capture and the gyro agreeing on the delay says it lies between the commands and
the motion, not between the two sensors (whose own offset the scan measures by cross-correlation).

Run: `python experiments/nanobench_delay.py [--out DIR]` (default DIR
`experiments/results/nanobench_delay`; about a minute). Writes `DIR/delay.json` (the grids, the
chosen delay, held-out $R^2$ with and without it, the per-run best delays, the sensors' offset) and
`DIR/delay.png`.
"""

import argparse
import pathlib
import sys
import time

import numpy as np
from scipy.signal import lfilter, savgol_filter

import dynax
from dynax.internal import write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import DATA, NANOBENCH_MAP, TEST, TRAIN  # noqa: E402

DELAYS = tuple(range(0, 9))  # samples (10 ms each)
LAGS_S = (0.0, 0.01, 0.02, 0.03, 0.04, 0.06)
IMU_MAP = {**NANOBENCH_MAP, "p": "imu_gyro_x", "q": "imu_gyro_y", "r": "imu_gyro_z"}
EDGE = 30  # samples left out at each end of a segment (the filters' start-up)


def segments(shapes, mapping):
    """Usable flight segments of the flights of `shapes`: (file, dt, motor commands, body rates)."""
    out = []
    for path in sorted(DATA.glob("*.csv.gz")):
        if not any(f"_{shape}_" in path.name for shape in shapes):
            continue
        trajectory, notes = dynax.load_flight(path, mapping=mapping)
        for run in dynax.usable_segments(trajectory, notes, 400):
            rates = [run.state_names.index(n) for n in ("p", "q", "r")]
            motors = [run.input_names.index(f"m{i}") for i in range(1, 5)]
            out.append((path.name, float(run.dt), np.asarray(run.us)[:, motors], np.asarray(run.xs)[:, rates]))
    return out


def design(m, dt, k, tau):
    """Motor features $m^2, m, 1$ (commands scaled to 0..1) lagged by `tau` [s] and taken `k` samples earlier."""
    m = m / 65535.0 if m.max() > 2 else m
    if tau > 0:
        a = np.exp(-dt / tau)
        m = lfilter([1 - a], [1, -a], m, axis=0, zi=m[:1] * a)[0]
    f = np.concatenate([m**2, m, np.ones((len(m), 1))], axis=1)
    return np.roll(f, k, axis=0)  # row i holds the features of sample i - k


def stack(runs, k, tau):
    xs, ys = [], []
    for _, dt, m, w in runs:
        alpha = savgol_filter(w, 9, 2, deriv=1, delta=dt, axis=0)
        xs.append(design(m, dt, k, tau)[EDGE:-EDGE])
        ys.append(alpha[EDGE:-EDGE])
    return np.concatenate(xs), np.concatenate(ys)


def r2(x, y, coef):
    e = y - x @ coef
    return 1.0 - np.sum(e**2, axis=0) / np.sum((y - y.mean(axis=0)) ** 2, axis=0)


def scan(train, test, lags=LAGS_S):
    """Training and held-out R^2 (p, q, r) over the (k, tau) grid; coefficients from the training flights."""
    fit_r2 = np.zeros((len(lags), len(DELAYS), 3))
    held_r2 = np.zeros_like(fit_r2)
    for i, tau in enumerate(lags):
        for j, k in enumerate(DELAYS):
            x, y = stack(train, k, tau)
            coef, *_ = np.linalg.lstsq(x, y, rcond=None)
            fit_r2[i, j] = r2(x, y, coef)
            xt, yt = stack(test, k, tau)
            held_r2[i, j] = r2(xt, yt, coef)
    return fit_r2, held_r2


def best_per_run(runs):
    """Each run's own best dead time (tau = 0), per axis, from its own fit."""
    out = []
    for run in runs:
        scores = []
        for k in DELAYS:
            x, y = stack([run], k, 0.0)
            coef, *_ = np.linalg.lstsq(x, y, rcond=None)
            scores.append(r2(x, y, coef))
        out.append({"file": run[0], "samples": len(run[2]), "best_delay_samples": np.argmax(scores, axis=0).tolist()})
    return out


def sensor_offset(mocap, imu, max_shift=10):
    """Shift [samples] of the gyro's roll and pitch rates against the motion capture's (cross-correlation)."""
    shifts = np.arange(-max_shift, max_shift + 1)
    total = np.zeros(len(shifts))
    for (_, _, _, a), (_, _, _, b) in zip(mocap, imu):
        a, b = a[EDGE:-EDGE, :2], b[EDGE:-EDGE, :2]
        total += [np.sum(np.roll(b, s, axis=0) * a) for s in shifts]
    return int(shifts[np.argmax(total)])


def sub_sample(curve):
    """The peak of a curve over DELAYS refined by a parabola through the best point and its neighbours."""
    j = int(np.argmax(curve))
    if 0 < j < len(curve) - 1:
        a, b, c = curve[j - 1], curve[j], curve[j + 1]
        den = a - 2 * b + c
        if den < 0:
            return DELAYS[j] + 0.5 * (a - c) / den
    return float(DELAYS[j])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="experiments/results/nanobench_delay")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    result = {"train": list(TRAIN), "test": list(TEST), "delays_samples": list(DELAYS), "lags_s": list(LAGS_S)}
    sensors = {}
    for sensor, mapping in (("motion capture", NANOBENCH_MAP), ("gyro", IMU_MAP)):
        train, test = segments(TRAIN, mapping), segments(TEST, mapping)
        sensors[sensor] = (train, test)
        dt = train[0][1]
        print(f"[{time.perf_counter() - start:6.1f} s] {sensor}: {len(train)} training, {len(test)} held-out segments")
        fit_r2, held_r2 = scan(train, test)
        mean_fit = fit_r2[..., :2].mean(axis=-1)  # roll and pitch: the axes the rotors' thrust differences drive
        i, j = np.unravel_index(int(np.argmax(mean_fit)), mean_fit.shape)
        delay = sub_sample(mean_fit[0])
        entry = {
            "r2_train": fit_r2.tolist(),
            "r2_heldout": held_r2.tolist(),
            "chosen_on_train": {"delay_samples": int(DELAYS[j]), "lag_s": LAGS_S[i]},
            "dead_time_s": delay * dt,
            "heldout_r2_chosen": held_r2[i, j].tolist(),
            "heldout_r2_no_delay": held_r2[0, 0].tolist(),
            "heldout_r2_best_lag_only": held_r2[int(np.argmax(mean_fit[:, 0])), 0].tolist(),
            "best_lag_only_s": LAGS_S[int(np.argmax(mean_fit[:, 0]))],
            "per_run": best_per_run(train + test),
        }
        result[sensor] = entry
        print(
            f"[{time.perf_counter() - start:6.1f} s] {sensor}: training flights choose a dead time of "
            f"{DELAYS[j]} samples with lag {LAGS_S[i] * 1e3:.0f} ms (dead time {entry['dead_time_s'] * 1e3:.0f} ms "
            f"without lag); held-out R2 p/q/r {np.round(held_r2[i, j], 3)} against {np.round(held_r2[0, 0], 3)} "
            f"undelayed and {np.round(entry['heldout_r2_best_lag_only'], 3)} for the best lag alone "
            f"({entry['best_lag_only_s'] * 1e3:.0f} ms)",
            flush=True,
        )
    offset = sensor_offset(sensors["motion capture"][0], sensors["gyro"][0])
    result["gyro_vs_motion_capture_shift_samples"] = offset
    print(f"gyro against motion capture: best alignment at a shift of {offset} samples", flush=True)
    result["seconds"] = time.perf_counter() - start
    write_json(out / "delay.json", result)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), sharey=True)
    for ax, sensor in zip(axes, ("motion capture", "gyro")):
        held = np.asarray(result[sensor]["r2_heldout"])[..., :2].mean(axis=-1)
        for i, tau in enumerate(LAGS_S):
            ax.plot(np.asarray(DELAYS) * 10, held[i], "o-", label=f"lag {tau * 1e3:.0f} ms")
        ax.set_title(f"{sensor} body rates")
        ax.set_xlabel("commands taken earlier by [ms]")
    axes[0].set_ylabel("held-out R² of roll/pitch acceleration")
    axes[1].legend(fontsize=8)
    fig.suptitle("NanoBench: motor commands against measured angular acceleration (fit on training shapes)")
    fig.tight_layout()
    fig.savefig(out / "delay.png", dpi=120)
    print(f"wrote {out} in {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
