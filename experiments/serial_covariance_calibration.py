"""How well `serial_covariance` (the least-squares stage's standard errors) gives the spread of an
estimate whose rows are correlated in time, with and without prewhitening.

    python experiments/serial_covariance_calibration.py --out experiments/results/serial_covariance_calibration

Each case fits `--reps` regressions of two records (two equations per time step, as two joints
give) whose regressors and errors are correlated in time, and compares the mean standard error to
the spread of the estimates over the repetitions (1 is calibrated, below 1 too small):

- **AR(1)** errors and regressors at a correlation of 0.5, 0.9 and 0.95 (500 steps per record);
- **low-passed**: white noise through a third-order Butterworth low-pass at 0.2, 0.1, 0.05 and
  0.03 of Nyquist (1000 steps per record), what the stage's filtered rows carry.

Three estimators: the usual one (rows independent), `serial_covariance` (Bartlett kernel,
Andrews' 1991 bandwidth) and the same prewhitened by a VAR(1) fitted to the scores, its singular
values capped at 0.97 (Andrews and Monahan 1992), which dynax does not use. Writes
`OUT/calibration.json`; about 40 s on 2 CPU cores.

??? cite

    D. W. K. Andrews, "Heteroskedasticity and autocorrelation consistent covariance matrix
    estimation", Econometrica 59(3), 1991; D. W. K. Andrews and J. C. Monahan, "An improved
    heteroskedasticity and autocorrelation consistent covariance matrix estimator", Econometrica
    60(4), 1992.
"""

import argparse
import json
import pathlib

import numpy as np
import scipy.signal

from dynax.internal import bartlett_lags, serial_bandwidth, serial_covariance


def prewhitened_covariance(jac, residuals, steps, record_steps, cap=0.97):
    """`serial_covariance` with the scores prewhitened by a VAR(1) (Andrews and Monahan 1992)."""
    n_steps = int(sum(record_steps))
    scale = np.linalg.norm(jac, axis=0)
    scores = np.zeros((n_steps, jac.shape[1]))
    np.add.at(scores, steps, jac / scale * residuals[:, None])
    bounds = np.cumsum((0,) + tuple(record_steps))
    pieces = [scores[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    lead = np.concatenate([p[1:] for p in pieces])
    lag = np.concatenate([p[:-1] for p in pieces])
    a = np.linalg.lstsq(lag, lead, rcond=None)[0].T
    u, s, vt = np.linalg.svd(a)
    a = u @ np.diag(np.minimum(s, cap)) @ vt
    white = [p[1:] - p[:-1] @ a.T for p in pieces]
    bandwidth = min(serial_bandwidth(white), min(len(w) for w in white) - 1)
    meat = sum(w.T @ w for w in white)
    for w in white:
        lagged = bartlett_lags(w, bandwidth)
        meat += lagged + lagged.T
    recolour = np.linalg.inv(np.eye(len(a)) - a)
    meat = recolour @ meat @ recolour.T
    bread = np.linalg.inv((jac / scale).T @ (jac / scale))
    n = jac.shape[1]
    return bread @ meat @ bread * n_steps / (n_steps - n) / np.outer(scale, scale)


def _series(rng, kind, value, shape):
    if kind == "ar1":
        e = rng.normal(size=shape)
        e[0] /= np.sqrt(1 - value**2)
        return scipy.signal.lfilter([1.0], [1.0, -value], e, axis=0)
    b, a = scipy.signal.butter(3, value)
    return scipy.signal.lfilter(b, a, rng.normal(size=(shape[0] + 400,) + tuple(shape[1:])), axis=0)[400:]


def case(kind, value, reps, per_record, seed=0):
    rng = np.random.default_rng(seed)
    steps = np.arange(4 * per_record) % (2 * per_record)
    estimates, errors = [], {"independent": [], "kernel": [], "prewhitened": []}
    for _ in range(reps):
        drift = [_series(rng, kind, value, (per_record, 2)) for _ in range(2)]
        x = np.concatenate([np.concatenate([np.ones((per_record, 1)), d], axis=1) for d in drift])
        x = np.concatenate([x, x * np.array([1.0, -1.0, 0.5])])
        e = np.concatenate([_series(rng, kind, value, (per_record,)) for _ in range(4)])
        y = x @ np.array([1.0, 2.0, -1.0]) + e
        beta, *_ = np.linalg.lstsq(x, y, rcond=None)
        r = y - x @ beta
        estimates.append(beta)
        errors["independent"].append(np.sqrt(np.diag(r @ r / (len(y) - 3) * np.linalg.inv(x.T @ x))))
        errors["kernel"].append(np.sqrt(np.diag(np.asarray(serial_covariance(x, r, steps, (per_record,) * 2)[0]))))
        errors["prewhitened"].append(np.sqrt(np.diag(prewhitened_covariance(x, r, steps, (per_record,) * 2))))
    spread = np.std(estimates, axis=0)
    return {name: (np.mean(v, axis=0) / spread).round(3).tolist() for name, v in errors.items()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, required=True)
    parser.add_argument("--reps", type=int, default=200)
    args = parser.parse_args()
    cases = [("ar1", v, 500) for v in (0.5, 0.9, 0.95)] + [("lowpass", v, 1000) for v in (0.2, 0.1, 0.05, 0.03)]
    out = []
    for kind, value, per_record in cases:
        ratios = case(kind, value, args.reps, per_record)
        print(f"{kind} {value}: " + ", ".join(f"{k} {v}" for k, v in ratios.items()), flush=True)
        out.append(
            {
                "kind": kind,
                "value": value,
                "steps_per_record": per_record,
                "reps": args.reps,
                "standard_error_over_spread": ratios,
            }
        )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "calibration.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
