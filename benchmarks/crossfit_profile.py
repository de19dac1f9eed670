"""Where `diagnose`'s cross-fitting spends its time: the fold fits and the cross-fitted rollouts.

The workload is `benchmarks/diagnose.py`'s (a 40 s, 100 Hz acrobot file with Coulomb friction hidden at
the elbow; the full candidate library; the last 30 % held out), a first call and a call on another file
of the same size. For each call: its CPU time, the CPU time inside the cross-fitting (`_cross_fit`), and
within it the fold fits (`fit_configurations`) and the rollouts of the cross-fitted windows
(`validate_configurations`), with how many of the windows it simulates each fold keeps.

    python benchmarks/crossfit_profile.py

Prints only. Read the CPU times (user + system of every thread).
"""

import pathlib
import tempfile
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from dynax import Acrobot, CoulombFriction, diagnose, Extended, load_trajectory, save_trajectory  # noqa: E402
from dynax._diagnose import _forward as forward  # noqa: E402  # private: inner calls wrapped, timed
from dynax.synthetic import DEMO_TRUTH_PHYSICAL, Multisine, synthetic_trajectory  # noqa: E402


def records():
    """`benchmarks/diagnose.py`'s two files, written as contract CSVs and read back."""
    truth = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (CoulombFriction(1, 0.25),))
    out = []
    with tempfile.TemporaryDirectory() as folder:
        for seed in (0, 1):
            record = synthetic_trajectory(
                truth, duration=40.0, dt=0.01, excitation=Multisine(amplitude=2.0), seed=seed, system_name="acrobot"
            )
            path = pathlib.Path(folder) / f"acrobot_40s_{seed}.csv"
            save_trajectory(record, path)
            out.append(load_trajectory(path, "acrobot"))
    return out


def main():
    seconds: dict[str, float] = {}
    kept: list[float] = []
    simulated: list[int] = []  # windows each fold's rollout simulates
    fit, validate, cross_fit, fold_of = (
        forward.fit_configurations,
        forward.validate_configurations,
        forward._cross_fit,
        forward.cv_fold_of,
    )
    inside = [False]

    def timed(name, f):
        def call(*args, **kwargs):
            if inside[0] and name == "validate_configurations":
                simulated.append(args[1].ts.shape[0])
            start = time.process_time()
            out = jax.block_until_ready(f(*args, **kwargs))
            key = f"{name} ({'cross-fit' if inside[0] else 'batch'})"
            seconds[key] = seconds.get(key, 0.0) + time.process_time() - start
            return out

        return call

    def timed_cross_fit(problem, yard, *args, **kwargs):
        start, inside[0] = time.process_time(), True
        simulated.clear()
        try:
            return cross_fit(problem, yard, *args, **kwargs)
        finally:
            if yard.cv_windows is not None:
                folds = fold_of(problem.folds, yard.cv_windows)
                kept.extend(float(np.sum(folds == i)) / n for i, n in enumerate(simulated))
            inside[0] = False
            seconds["cross-fit, all"] = seconds.get("cross-fit, all", 0.0) + time.process_time() - start

    forward.fit_configurations = timed("fit_configurations", fit)
    forward.validate_configurations = timed("validate_configurations", validate)
    forward._cross_fit = timed_cross_fit
    first, other = records()
    for label, record in (("first call (with compilation)", first), ("another file of the same size", other)):
        seconds.clear()
        kept.clear()
        start = time.process_time()
        diagnose(Acrobot(), record)
        total = time.process_time() - start
        print(f"{label}: {total:.2f} s CPU")
        for key, value in sorted(seconds.items()):
            print(f"  {key:45s} {value:6.2f} s CPU")
        if kept:
            print(f"  each fold keeps {min(kept):.0%} to {max(kept):.0%} of the cross-fitted windows it simulates")


if __name__ == "__main__":
    main()
