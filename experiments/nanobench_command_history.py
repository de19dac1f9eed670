"""Command history of the NanoBench Crazyflie: how much of the rotation the motor commands' past explains.

`experiments/nanobench_delay.py` regresses the measured angular acceleration on the motor features
$m_i^2, m_i, 1$ taken at one delay through one first-order lag, and finds at most about 10 % of its
variance explained on the held-out flights. A single delay and lag is one particular filter of the
commands; this study asks whether *any* causal filter does better: a finite impulse response over the
last `K` samples of every feature (the regression on the stacked lagged features, ridge-regularised),
fitted on the training flights (circle, figure-eight, helix, ramp, lissajous) and scored on the
held-out ones (star, trefoil, oval), for `K` up to 200 ms. A motor's response, a logging delay or the
rotors' inflow all are causal filters of the commands, so the best FIR bounds what a model of the
commands' history could add to the body-rate prediction.

As a check on what the commands carry, the same regression is run two-sided (the commands up to
`K` samples *after* the acceleration too): the Crazyflie's rate loop computes the commands from the
measured rates, so commands that follow the motion explain it better than those that precede it where
the motion causes the commands rather than the reverse. The body rates themselves (rate damping) are
added as a third variant.

The acceleration's $R^2$ weighs its fast part; the protocol scores the rate 0.5 s ahead. So the study
also predicts that directly: the rates integrated from the fitted acceleration under the recorded
commands, and the best linear predictor of the 0.5 s rate change from the features of every recorded
command over the window (and up to 200 ms before it) and the start rate, fitted on the training
flights. The latter bounds what any model linear in these features of the logged commands could reach
on the body rate at 0.5 s; it is compared with holding the start rate (the constant-velocity baseline's
rates).

Run: `nice python experiments/nanobench_command_history.py [--out DIR]` (default DIR
`experiments/results/nanobench_command_history`; a minute or two). Writes `DIR/history.json` and
`DIR/history.png`.
"""

import argparse
import pathlib
import sys
import time

import numpy as np
from scipy.signal import savgol_filter

from dynax.internal import write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_delay import EDGE, segments  # noqa: E402
from nanobench_heldout import NANOBENCH_MAP, TEST, TRAIN  # noqa: E402

HISTORY = (0, 1, 2, 3, 5, 8, 12, 20)  # samples of command history (10 ms each)
RIDGE = 1e-3  # relative to the mean diagonal of the normal equations
AXES = ("p", "q", "r")
PREDICT_STEPS = 50  # 0.5 s, the protocol's longest horizon


def features(m):
    m = m / 65535.0 if m.max() > 2 else m
    return np.concatenate([m**2, m], axis=1)


def stack(runs, past, future=0, rates=False):
    """Rows of the features at lags -future..past (positive: earlier) and, optionally, the rates, against the
    angular acceleration (Savitzky-Golay derivative of the rates)."""
    xs, ys = [], []
    reach = max(past, future) + EDGE
    for _, dt, m, w in runs:
        if len(m) <= 2 * reach + 10:
            continue
        f = features(m)
        cols = [np.roll(f, k, axis=0) for k in range(-future, past + 1)]
        if rates:
            cols.append(w)
        cols.append(np.ones((len(m), 1)))
        xs.append(np.concatenate(cols, axis=1)[reach:-reach])
        ys.append(savgol_filter(w, 9, 2, deriv=1, delta=dt, axis=0)[reach:-reach])
    return np.concatenate(xs), np.concatenate(ys)


def fit(train, **kw):
    """The acceleration's ridge regression on the training runs' rows (`stack`)."""
    return ridge(*stack(train, **kw))


def ridge(x, y):
    """Ridge coefficients on standardised columns (the last, the constant, left as is): `(coef, mu, sd)`."""
    mu, sd = x.mean(axis=0), x.std(axis=0)
    mu[-1], sd[-1] = 0.0, 1.0
    sd[sd == 0] = 1.0
    z = (x - mu) / sd
    gram = z.T @ z
    coef = np.linalg.solve(gram + RIDGE * np.trace(gram) / len(gram) * np.eye(len(gram)), z.T @ y)
    return coef, mu, sd


def r2(model, runs, **kw):
    coef, mu, sd = model
    x, y = stack(runs, **kw)
    e = y - (x - mu) / sd @ coef
    return 1.0 - np.sum(e**2, axis=0) / np.sum((y - y.mean(axis=0)) ** 2, axis=0)


def rate_mae(model, runs, past, rates=False, steps=PREDICT_STEPS, every=5):
    """MAE (norm of the body-rate error) `steps` samples ahead of the rates predicted open loop from each start by
    integrating the fitted acceleration under the recorded commands (with `rates`, the predicted rates feed the
    damping columns). `model=None` holds the start rate (the constant-velocity baseline's rates)."""
    errors = []
    for _, dt, m, w in runs:
        reach = past + EDGE
        if len(m) <= 2 * reach + steps + 10:
            continue
        starts = np.arange(reach, len(m) - reach - steps, every)
        predicted = w[starts].copy()
        if model is not None:
            coef, mu, sd = model
            f = features(m)
            cmd = np.concatenate([np.roll(f, k, axis=0) for k in range(past + 1)], axis=1)
            width = cmd.shape[1]
            drive = (cmd - mu[:width]) / sd[:width] @ coef[:width] + coef[-1]  # commands' and constant's share
            for j in range(steps):
                accel = drive[starts + j]
                if rates:
                    accel = accel + (predicted - mu[width:-1]) / sd[width:-1] @ coef[width:-1]
                predicted = predicted + dt * accel
        errors.append(np.linalg.norm(predicted - w[starts + steps], axis=1))
    return float(np.mean(np.concatenate(errors)))


def direct_rows(runs, past, steps=PREDICT_STEPS, every=2, quadratic=False):
    """Rows for the direct regression of the rate change `steps` samples ahead: the features of the commands from
    `past` samples before the start to the last one before the end (all recorded: the protocol predicts open loop
    under the recorded inputs), the start rate and a constant; targets the change and the start rate."""
    xs, ys, w0 = [], [], []
    for _, _, m, w in runs:
        reach = past + EDGE
        if len(m) <= 2 * reach + steps + 10:
            continue
        starts = np.arange(reach, len(m) - reach - steps, every)
        f = features(m)
        window = np.concatenate([f[starts + j] for j in range(-past, steps)], axis=1)
        extra = []
        if quadratic:  # the start rate's products with itself and with the window's mean features
            rate = w[starts]
            mean = np.mean([f[starts + j] for j in range(steps)], axis=0)
            extra = [rate[:, i : i + 1] * rate[:, i:] for i in range(3)]
            extra += [rate[:, i : i + 1] * mean for i in range(3)]
        xs.append(np.concatenate([window, *extra, w[starts], np.ones((len(starts), 1))], axis=1))
        ys.append(w[starts + steps] - w[starts])
        w0.append(w[starts])
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(w0)


def direct_mae(train, test, past, quadratic=False, steps=PREDICT_STEPS):
    """Body-rate MAE `steps` samples ahead of the best linear predictor of the rate change from the commands over
    the window (and `past` samples before it) and the start rate, fitted on `train` with the ridge, scored on
    `test`: `(training, held out, holding the start rate on the same held-out starts)`."""
    x, y, _ = direct_rows(train, past, steps=steps, quadratic=quadratic)
    coef, mu, sd = ridge(x, y)
    z = (x - mu) / sd
    xt, yt, _ = direct_rows(test, past, steps=steps, quadratic=quadratic)
    fitted = np.mean(np.linalg.norm(y - z @ coef, axis=1))
    held = np.mean(np.linalg.norm(yt - (xt - mu) / sd @ coef, axis=1))
    return float(fitted), float(held), float(np.mean(np.linalg.norm(yt, axis=1)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="experiments/results/nanobench_command_history")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    train, test = segments(TRAIN, NANOBENCH_MAP), segments(TEST, NANOBENCH_MAP)
    print(f"[{time.perf_counter() - start:6.1f} s] {len(train)} training, {len(test)} held-out segments", flush=True)
    variants = {
        "causal": {},
        "two-sided": {"future": None},
        "causal with rates": {"rates": True},
    }
    result = {"train": list(TRAIN), "test": list(TEST), "history_samples": list(HISTORY), "ridge": RIDGE}
    hold = rate_mae(None, test, max(HISTORY))
    result["rate_mae_hold"] = hold
    print(f"holding the start rate: body-rate MAE at 0.5 s {hold:.4f} rad/s", flush=True)
    for name, kw in variants.items():
        rows = []
        for k in HISTORY:
            args_k = {"past": k, "future": k if "future" in kw else 0, "rates": kw.get("rates", False)}
            model = fit(train, **args_k)
            fitted, held = r2(model, train, **args_k), r2(model, test, **args_k)
            row = {"samples": k, "r2_train": fitted.tolist(), "r2_heldout": held.tolist()}
            line = f"held-out R2 p/q/r {np.round(held, 3)} (training {np.round(fitted, 3)})"
            if "future" not in kw:  # a prediction may use the recorded commands up to its start only... and after:
                # open loop under the recorded inputs, as the protocol scores it
                row["rate_mae_0.5s"] = rate_mae(model, test, k, rates=args_k["rates"])
                line += f"; body-rate MAE at 0.5 s {row['rate_mae_0.5s']:.4f}"
            rows.append(row)
            print(f"[{time.perf_counter() - start:6.1f} s] {name:18s} {k * 10:4d} ms: {line}", flush=True)
        result[name] = rows
    direct = []
    for k in (0, 5, 20):
        fitted, held, _ = direct_mae(train, test, k)
        direct.append({"past_samples": k, "rate_mae_train": fitted, "rate_mae_heldout": held})
        print(
            f"[{time.perf_counter() - start:6.1f} s] direct 0.5 s regression on the window's commands and "
            f"{k * 10} ms before: body-rate MAE at 0.5 s {held:.4f} held out ({fitted:.4f} training)",
            flush=True,
        )
    fitted, held, _ = direct_mae(train, test, 0, quadratic=True)
    direct.append({"past_samples": 0, "quadratic": True, "rate_mae_train": fitted, "rate_mae_heldout": held})
    print(
        f"[{time.perf_counter() - start:6.1f} s] direct, with the start rate's products (with itself and the window's "
        f"mean features): body-rate MAE at 0.5 s {held:.4f} held out ({fitted:.4f} training)",
        flush=True,
    )
    result["direct"] = direct
    by_horizon = []
    for h in (1, 10, 50):  # the protocol's horizons: what the best linear map gains over holding the rate
        fitted, held, holding = direct_mae(train, test, 0, steps=h)
        by_horizon.append({"steps": h, "rate_mae_heldout": held, "rate_mae_hold": holding})
        print(
            f"[{time.perf_counter() - start:6.1f} s] direct, {h} step(s) ahead: body-rate MAE {held:.4f} held out, "
            f"holding the rate {holding:.4f} ({holding / held:.2f}x)",
            flush=True,
        )
    result["direct_by_horizon"] = by_horizon
    result["seconds"] = time.perf_counter() - start
    write_json(out / "history.json", result)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(15, 3.4))
    for i, (ax, axis) in enumerate(zip(axes, AXES)):
        for name in variants:
            ax.plot(
                [10 * r["samples"] for r in result[name]], [r["r2_heldout"][i] for r in result[name]], "o-", label=name
            )
        ax.set_title(f"angular acceleration about {axis}")
        ax.set_xlabel("command history [ms]")
        ax.set_ylim(-0.05, 0.5)
    axes[0].set_ylabel("held-out R²")
    axes[0].legend(fontsize=8)
    bars = {"hold the start rate": hold}
    bars["integrate the causal FIR (best history)"] = min(r["rate_mae_0.5s"] for r in result["causal"])
    bars |= {
        f"direct 0.5 s regression, {d['past_samples'] * 10} ms before"
        + (", quadratic" if d.get("quadratic") else ""): d["rate_mae_heldout"]
        for d in direct
    }
    axes[3].barh(list(bars), list(bars.values()))
    axes[3].axvline(hold / 2, color="k", ls="--", lw=0.8)
    axes[3].set_xlabel("body-rate MAE at 0.5 s [rad/s]")
    axes[3].set_title("held out (dashed: half of holding)", fontsize=9)
    axes[3].tick_params(axis="y", labelsize=7)
    fig.suptitle("NanoBench: motor-command history against measured rotation (fit on training shapes)")
    fig.tight_layout()
    fig.savefig(out / "history.png", dpi=120)
    print(f"wrote {out} in {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
