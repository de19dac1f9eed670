"""Can the record show the helicopter's body-frame quadratic drag at any reference horizon? Measured outside dynax.

For each of the calibration battery's three helicopter drag cases (`tests/hidden_cases.py`), the truth (numpy, the
written-out Tempest law with its drag) and the truth without its effect are rolled out from every window start
0.05 s apart (the diagnosis's stride) on the held-out record and on the training record, by RK4 at two steps a
sample, the recorded input held, to 3 s; each window is scored as the diagnosis scores a candidate (the mean over
steps 1 to the horizon and over states of the squared error in units of each state's spread on the training
record). At every horizon from 0.1 to 3 s this gives, for the truth over the truth without the effect:

- `pooled`: 1 - mean score with / mean score without, on the held-out windows (`tests.hidden_cases.truth_gain`);
- `typical`: the typical window's gain with the test's floor (`1 - exp(-mean(log_ratio_differences))`, the
  diagnosis's `typical_gain`), on the held-out windows;
- `typical_all`: the same over the held-out and the training record's windows (the windows the test reads);
- `p_held_out`, `p_all`: the diagnosis's paired HAC test (`dynax.internal.paired_block_test`) of the truth against
  the truth without the effect, on the held-out run alone and with the training record's windows in three blocks
  (the cross-fitted blocks the diagnosis adds), with its degrees of freedom: the best any candidate can do, since
  it is the effect itself, with no coefficient to estimate (the best of the helicopter's 12 vehicle candidates
  is named only below Benjamini-Hochberg's 0.01 / 12 = 0.00083, and with a typical gain of 5 % or more);
- `typical_all_without_rates`, `p_all_without_rates`: `typical_all` and `p_all` with the body rates left out of
  the score (their window error is the gyros' noise, which the drag does not change);
- `by_state`: the share of the effect-free model's mean window score that each group of states carries, and the
  share of the truth's improvement that each carries.

The case's spread of every state and RMS body speeds on the training record go beside them. About 30 s.

    nice -n 5 python experiments/heli_drag_horizons.py [OUT]

OUT defaults to `experiments/results/heli_drag_horizons`; writes `horizons.json`.
"""

import dataclasses
import json
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from dynax.internal import log_ratio_differences, paired_block_test
from tests.hidden_cases import CASES, DT, heli_rhs, records, SYSTEMS, TEMPEST

STRIDE = 5  # samples between window starts (0.05 s, the diagnosis's)
LONGEST = 300  # samples (3 s)
HORIZONS_S = (0.1, 0.2, 0.3, 0.45, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0)
GROUPS = {"position": [0, 1, 2], "attitude": [3, 4, 5, 6], "velocity": [7, 8, 9], "rates": [10, 11, 12]}
BLOCKS = 3  # the training record's cross-fitted blocks


def batched_rhs(case):
    """`heli_rhs(case)` over a batch of states `(B, 13)` and inputs `(B, 4)` (checked against it below)."""
    c = TEMPEST
    axis = {"u": 0, "v": 1, "w": 2}.get(case.where)

    def rhs(y, u):
        qw, qx, qy, qz = y[:, 3], y[:, 4], y[:, 5], y[:, 6]
        nu, om = y[:, 7:10], y[:, 10:13]
        R = np.stack(
            [
                np.stack([1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)], -1),
                np.stack([2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)], -1),
                np.stack([2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)], -1),
            ],
            -2,
        )
        g_body = np.einsum("bji,j->bi", R, np.array([0.0, 0.0, c["g"]]))
        acc = -np.cross(om, nu) + g_body
        acc[:, 0] += c["Ax"] * nu[:, 0]
        acc[:, 1] += c["Ay"] * nu[:, 1] + c["Dv"]
        acc[:, 2] += c["Az"] * nu[:, 2] + c["C4"] * u[:, 3]
        rates = np.stack(
            [
                c["Bx"] * om[:, 0] + c["C1"] * u[:, 0],
                c["By"] * om[:, 1] + c["C2"] * u[:, 1],
                c["Bz"] * om[:, 2] + c["C3"] * u[:, 2],
            ],
            -1,
        )
        if case.cause == "quadratic_drag":
            acc[:, axis] -= case.size * np.abs(nu[:, axis]) * nu[:, axis]
        p, q, r = om[:, 0], om[:, 1], om[:, 2]
        dquat = 0.5 * np.stack(
            [-qx * p - qy * q - qz * r, qw * p + qy * r - qz * q, qw * q - qx * r + qz * p, qw * r + qx * q - qy * p],
            -1,
        )
        dquat += (1.0 - np.sum(y[:, 3:7] ** 2, axis=1))[:, None] * y[:, 3:7]
        return np.concatenate([np.einsum("bij,bj->bi", R, nu), dquat, acc, rates], axis=1)

    return rhs


def check_batched(case, rng):
    slow, _ = heli_rhs(case)
    fast = batched_rhs(case)
    y = rng.standard_normal((20, 13))
    y[:, 3:7] /= np.linalg.norm(y[:, 3:7], axis=1, keepdims=True)
    u = rng.standard_normal((20, 4))
    assert np.allclose(fast(y, u), np.stack([slow(a, b) for a, b in zip(y, u)]), rtol=1e-12, atol=1e-12)


def rollouts(rhs, xs, us, starts):
    """`(window, step, state)`: each window from its measured state, RK4 at two steps a sample, the input held; steps
    past the record's end are NaN."""
    n = len(xs)
    y = xs[starts].copy()
    out = np.full((len(starts), LONGEST, xs.shape[1]), np.nan)
    h = DT / 2
    for j in range(LONGEST):
        u = us[np.minimum(starts + j, n - 1)]
        for _ in range(2):
            a = rhs(y, u)
            b = rhs(y + 0.5 * h * a, u)
            c = rhs(y + 0.5 * h * b, u)
            y = y + h / 6 * (a + 2 * b + 2 * c + rhs(y + h * c, u))
        inside = starts + j + 1 < n
        out[inside, j] = y[inside]
    return out


def window_errors(case, rec, scale):
    """Squared scaled errors `(model, window, step, state)` of the truth and of the truth without its effect."""
    xs, us = np.asarray(rec.xs, float), np.asarray(rec.us, float)
    starts = np.arange(0, len(xs) - 1, STRIDE)
    target = np.full((len(starts), LONGEST, xs.shape[1]), np.nan)
    for w, k in enumerate(starts):
        seg = xs[k + 1 : k + 1 + LONGEST]
        target[w, : len(seg)] = seg
    models = [case, dataclasses.replace(case, cause=None)]
    return starts, np.stack([((rollouts(batched_rhs(m), xs, us, starts) - target) / scale) ** 2 for m in models])


def typical_gain(ref, new):
    return float(1.0 - np.exp(-np.mean(log_ratio_differences(ref, new))))


def scores_at(sq, starts, n, steps, states=slice(None)):
    """Window scores at a horizon of `steps` samples, for the windows that fit in the record (over `states`)."""
    keep = starts + steps < n
    return sq[:, keep, :steps, states].mean(axis=(2, 3)), keep


def analyse(case):
    train, held = records(case)
    scale = np.maximum(np.asarray(train.xs).std(axis=0), 1e-9)
    st_h, sq_h = window_errors(case, held, scale)
    st_t, sq_t = window_errors(case, train, scale)
    n_h, n_t = len(held.ts), len(train.ts)
    out = {}
    for h in HORIZONS_S:
        steps = round(h / DT)
        (truth_h, free_h), _ = scores_at(sq_h, st_h, n_h, steps)
        (truth_t, free_t), keep_t = scores_at(sq_t, st_t, n_t, steps)
        overlap = max(1, round(steps / STRIDE))
        d_h = log_ratio_differences(free_h, truth_h)
        test_h = paired_block_test(d_h, np.zeros(d_h.size, int), overlap)
        # The training record's windows in three contiguous blocks, each a run of its own (a block's windows that
        # reach past it are dropped, as the cross-fit's are), beside the held-out run.
        block_of = np.minimum(st_t[keep_t] * BLOCKS // n_t, BLOCKS - 1)
        ends = (block_of + 1) * n_t // BLOCKS
        inside = st_t[keep_t] + steps < ends
        free_all = np.concatenate([free_h, free_t[inside]])
        truth_all = np.concatenate([truth_h, truth_t[inside]])
        runs = np.concatenate([np.zeros(free_h.size, int), 1 + block_of[inside]])
        test_all = paired_block_test(log_ratio_differences(free_all, truth_all), runs, overlap)
        # The same without the rates, whose window error is the gyros' noise (no model here changes them).
        (truth_r, free_r), _ = scores_at(sq_h, st_h, n_h, steps, slice(0, 10))
        (truth_rt, free_rt), _ = scores_at(sq_t, st_t, n_t, steps, slice(0, 10))
        free_r_all = np.concatenate([free_r, free_rt[inside]])
        truth_r_all = np.concatenate([truth_r, truth_rt[inside]])
        test_r = paired_block_test(log_ratio_differences(free_r_all, truth_r_all), runs, overlap)
        sq_free = sq_h[1][st_h + steps < n_h][:, :steps]
        sq_truth = sq_h[0][st_h + steps < n_h][:, :steps]
        total = float(np.mean(sq_free.mean(axis=(1, 2))))
        improvement = float(np.mean(sq_free) - np.mean(sq_truth))
        out[f"{h:g}"] = {
            "pooled": float(1 - truth_h.mean() / free_h.mean()),
            "typical": typical_gain(free_h, truth_h),
            "p_held_out": test_h.p_value,
            "df_held_out": test_h.df,
            "p_all": test_all.p_value,
            "df_all": test_all.df,
            "typical_all": typical_gain(free_all, truth_all),
            "typical_all_without_rates": typical_gain(free_r_all, truth_r_all),
            "p_all_without_rates": test_r.p_value,
            "by_state_share_of_error": {
                g: float(np.mean(sq_free[:, :, ix].sum(axis=2)) / sq_free.shape[2] / total) for g, ix in GROUPS.items()
            },
            "by_state_share_of_improvement": {
                g: float(
                    (np.mean(sq_free[:, :, ix].sum(axis=2)) - np.mean(sq_truth[:, :, ix].sum(axis=2)))
                    / sq_free.shape[2]
                    / improvement
                )
                if improvement
                else None
                for g, ix in GROUPS.items()
            },
        }
        row = out[f"{h:g}"]
        print(
            f"{case.name} {h:5.2f} s: pooled {row['pooled']:6.1%} typical {row['typical']:6.1%} "
            f"p held-out {row['p_held_out']:.3g} (df {row['df_held_out']:.1f}) p all {row['p_all']:.3g} "
            f"(df {row['df_all']:.1f}) without rates: typical {row['typical_all_without_rates']:.1%} "
            f"p {row['p_all_without_rates']:.3g}; "
            f"velocity share of error {row['by_state_share_of_error']['velocity']:.2f}, "
            f"rates {row['by_state_share_of_error']['rates']:.2f}",
            flush=True,
        )
    speeds = np.asarray(train.xs)[:, 7:10]
    return {
        "horizons": out,
        "spread": dict(zip(SYSTEMS["helicopter"]["states"], scale.tolist())),
        "speed_rms_training": np.sqrt(np.mean(speeds**2, axis=0)).tolist(),
    }


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "experiments/results/heli_drag_horizons")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    cases = [c for c in CASES if c.cause == "quadratic_drag"]
    result, t0 = {}, time.perf_counter()
    for case in cases:
        check_batched(case, rng)
        result[case.name] = analyse(case)
    result["wall_s"] = time.perf_counter() - t0
    (out / "horizons.json").write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
