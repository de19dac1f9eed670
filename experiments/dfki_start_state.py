"""The start state of a simulation window at rest on DFKI run 12: what the measured speed, the refinement's own
velocity and the start-state rule give there.

    DYNAX_SHARED=/work/shared python experiments/dfki_start_state.py

Prints, for run 12 (whole, and its head and tail at 5.25 s): per rest stretch (`rest_stretches`) the logged speed's
share of exact zeros, its noise (`speed_noise_at_rest`), the share beyond three times it and its largest; the speed
the output-error refinement starts from there (`motion_records`: a local cubic fit of the positions), rms and
largest; how many speed samples the rule (`speeds_zeroed_at_rest`) and zeroing every rest sample change; and, for
the training sets of the 5.25 s split and of the leave-one-run-out folds 01, 05, 03, whether the refinement's noise
weights (the median over the records of `measurement_noise_std`) move when the measured speeds at rest are zeroed.

Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
../shared/datasets (or `$DYNAX_SHARED/datasets`).
"""

import jax

jax.config.update("jax_enable_x64", True)

# The script's folder is on sys.path.
from dfki_default_identification import load, RUNS
from dfki_stiction import cut, speeds_zeroed_everywhere_at_rest
import numpy as np  # noqa: E402

from dynax.internal import (  # noqa: E402
    measurement_noise_std,
    motion_records,
    resample,
    rest_stretches,
    speed_noise_at_rest,
    speeds_zeroed_at_rest,
)


def at_rest(name, record):
    (fitted,), _ = motion_records([record])
    xs, ts = np.asarray(record.xs), np.asarray(record.ts)
    own, own_ts = np.asarray(fitted.xs), np.asarray(fitted.ts)
    for s in rest_stretches(record):
        v = xs[(ts >= s.start_s) & (ts <= s.stop_s), 2 + s.joint]
        sigma = speed_noise_at_rest(v)
        w = own[(own_ts >= s.start_s) & (own_ts <= s.stop_s), 2 + s.joint]
        print(
            f"{name} {s.coordinate} {s.start_s:.2f}-{s.stop_s:.2f} s: logged zeros {np.mean(v == 0):.3f}, noise "
            f"{sigma:.4f}, beyond 3x {np.mean(np.abs(v) > 3 * sigma):.4f}, largest {np.abs(v).max():.3f}; "
            f"refinement's start speed rms {np.sqrt(np.mean(w**2)):.4f}, largest {np.abs(w).max():.4f}"
        )
    (ruled,) = speeds_zeroed_at_rest([record])
    (every,) = speeds_zeroed_everywhere_at_rest(record)
    print(
        f"{name}: samples changed by the rule {int(np.sum(xs != np.asarray(ruled.xs)))}, by zeroing every rest "
        f"sample {int(np.sum(xs != np.asarray(every.xs)))}"
    )


def noise_weights(records):
    return np.median(
        np.stack([measurement_noise_std(r if r.is_uniform else resample(r, r.dt)) for r in records]), axis=0
    )


def main():
    runs = {r: load(r) for r in RUNS}
    head, tail = cut(runs["12"], 5.25)
    for name, record in (("run 12", runs["12"]), ("head to 5.25 s", head), ("tail from 5.25 s", tail)):
        at_rest(name, record)
    sets = {"split 5.25": [runs[r] for r in RUNS if r != "12"] + [head]}
    sets |= {f"fold {f}": [runs[r] for r in RUNS if r != f] for f in ("01", "05", "03")}
    for name, records in sets.items():
        before, after = noise_weights(records), noise_weights(speeds_zeroed_at_rest(records))
        print(
            f"{name}: noise weights {before}, with the speeds at rest zeroed identical: {np.array_equal(before, after)}"
        )


if __name__ == "__main__":
    main()
