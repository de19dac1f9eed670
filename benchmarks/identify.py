"""Speed of `dynax.identify` (energy, power, dynamic) on 100,000 samples against a numpy/scipy reference.

The reference builds the same regressors by hand-written numpy formulas (the acrobot's equations
expanded), with the same differences, zero-order-hold pairing and windows, and solves with
`scipy.linalg.lstsq` (LAPACK gelsd). Both produce the same estimate (checked); the ratio is
reference time / dynax time, warm (after compilation; the compile time is reported separately).

    python benchmarks/identify.py [--samples 100000] [--repeats 5] [--out benchmarks/results/identify.json]
"""

import jax

jax.config.update("jax_enable_x64", True)

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import pathlib  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

from _device import describe, device_info  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402

import dynax  # noqa: E402
from dynax import Dynamic, Energy, identify, Power, Trajectory  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- numpy reference (hand-expanded)


def numpy_dynamic(ts, xs, us):
    q1, q2, dq1, dq2 = xs.T
    h = np.diff(ts)
    h1, h2 = h[:-1], h[1:]
    ddq = np.gradient(xs[:, 2:], ts, axis=0)
    tau2 = us[:, 0].copy()
    tau2[1:-1] = (h2 * us[:-2, 0] + h1 * us[1:-1, 0]) / (h1 + h2)  # zero-order-hold pairing
    s1, c2, s2, s12 = np.sin(q1), np.cos(q2), np.sin(q2), np.sin(q1 + q2)
    a1, a2 = ddq[:, 0], ddq[:, 1]
    z = np.zeros_like(q1)
    row1 = np.stack([a1, a1 + a2, 2 * c2 * a1 + c2 * a2 - 2 * s2 * dq1 * dq2 - s2 * dq2**2, s1, s12, dq1, z], axis=1)
    row2 = np.stack([z, a1 + a2, c2 * a1 + s2 * dq1**2, z, s12, z, dq2], axis=1)
    keep = slice(1, -1)
    a = np.concatenate([row1[keep], row2[keep]])
    y = np.concatenate([z[keep], tau2[keep]])
    return scipy.linalg.lstsq(a, y)[0]


def _energy_columns(xs):
    q1, q2, dq1, dq2 = xs.T
    z = np.zeros_like(q1)
    return np.stack(
        [0.5 * dq1**2, 0.5 * (dq1 + dq2) ** 2, np.cos(q2) * (dq1**2 + dq1 * dq2), -np.cos(q1), -np.cos(q1 + q2), z, z],
        axis=1,
    )


def _interval_integrals(ts, xs, us):
    dq1, dq2 = xs[:, 2], xs[:, 3]
    h = np.diff(ts)
    work = 0.5 * h * (dq2[:-1] + dq2[1:]) * us[:-1, 0]
    friction = np.stack([dq1**2, dq2**2], axis=1)
    dissipated = np.zeros((len(h), 7))
    dissipated[:, 5:] = 0.5 * h[:, None] * (friction[:-1] + friction[1:])
    return work, dissipated


def numpy_power(ts, xs, us):
    w = _energy_columns(xs)
    work, dissipated = _interval_integrals(ts, xs, us)
    h = np.diff(ts)
    h1, h2 = h[:-1], h[1:]
    b1, b2 = h2 / (h1 + h2) / h1, h1 / (h1 + h2) / h2
    a = (
        b1[:, None] * (w[1:-1] - w[:-2])
        + b2[:, None] * (w[2:] - w[1:-1])
        + b1[:, None] * dissipated[:-1]
        + b2[:, None] * dissipated[1:]
    )
    y = b1 * work[:-1] + b2 * work[1:]
    return scipy.linalg.lstsq(a, y)[0]


def numpy_energy(ts, xs, us, window=10):
    w = _energy_columns(xs)
    work, dissipated = _interval_integrals(ts, xs, us)
    work = np.concatenate([[0.0], np.cumsum(work)])
    dissipated = np.concatenate([np.zeros((1, 7)), np.cumsum(dissipated, axis=0)])
    starts = np.arange(0, len(ts) - window, window)
    ends = starts + window
    a = w[ends] - w[starts] + dissipated[ends] - dissipated[starts]
    return scipy.linalg.lstsq(a, work[ends] - work[starts])[0]


# --------------------------------------------------------------------------------------- benchmark


def best_time(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        times.append(time.perf_counter() - start)
    return min(times), out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "identify.json"))
    args = parser.parse_args()

    system = dynax.Acrobot()
    dt = 0.01
    ts = dt * np.arange(args.samples)
    rng = np.random.default_rng(0)
    levels = rng.uniform(-2, 2, size=args.samples // 50 + 1)
    us = np.repeat(levels, 50)[: args.samples, None]
    xs = np.asarray(dynax.simulate(system, jnp.array([0.2, 0.0, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us)).xs)
    data = Trajectory(
        jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot"
    )
    print(
        f"{args.samples} samples of acrobot data; {platform.processor() or platform.machine()}, jax {jax.__version__}"
    )

    cases = {
        # No filter, trim 1, no decimation: the reference's recipe (the default `Dynamic()` chooses a
        # low-pass filter from the spectra, which the reference does not do).
        "dynamic": (Dynamic(lowpass_hz=None), numpy_dynamic),
        "power": (Power(), numpy_power),
        "energy": (Energy(), numpy_energy),
    }
    print(describe(device_info()))
    results = {
        "samples": args.samples,
        "device": device_info(),
        "jax": jax.__version__,
        "methods": {},
        "load_average": os.getloadavg(),
    }
    for name, (method, reference) in cases.items():
        start = time.perf_counter()
        first = identify(system, data, method, refine=False, validation=dynax.Validate(holdout=0), consistency="off")
        compile_s = time.perf_counter() - start
        # Alternating rounds (3 dynax calls, then 3 numpy calls, `repeats` times), best of each: a
        # change in the machine's load touches both alike, and neither library's worker threads,
        # which spin for a while after a call (OpenBLAS's take the cores from XLA's: 20 -> 30 ms for
        # the dynamic model when the calls alternate one by one), run into the other's timing
        # more than once a round.
        t_dynax, t_numpy = [], []
        for _ in range(args.repeats):
            t, result = best_time(
                lambda: (
                    identify(
                        system, data, method, refine=False, validation=dynax.Validate(holdout=0), consistency="off"
                    ).estimate
                ),
                3,
            )
            t_dynax.append(t)
            t, estimate = best_time(lambda: reference(ts, xs, us), 3)
            t_numpy.append(t)
        t_dynax, t_numpy = min(t_dynax), min(t_numpy)
        agree = float(np.max(np.abs(np.asarray(result) - estimate) / np.abs(estimate)))
        results["methods"][name] = {
            "dynax_s": t_dynax,
            "numpy_scipy_s": t_numpy,
            "ratio_numpy_over_dynax": t_numpy / t_dynax,
            "first_call_s": compile_s,
            "max_relative_difference": agree,
        }
        print(
            f"{name:>8s}: dynax {t_dynax * 1e3:8.1f} ms (first call {compile_s:.1f} s), numpy/scipy "
            f"{t_numpy * 1e3:8.1f} ms, ratio {t_numpy / t_dynax:.2f}, estimates agree to {agree:.1e}"
        )
        del first
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
