"""A held-out record of another system: what it does to `identify`'s validation, and whether the inverse-dynamics
(torque) residual tells it from a record of the same system.

Two statistics of the training fit's least-squares estimate on the held-out record's equations (`Dynamic()`'s,
each joint's rows less their mean: a force offset of the record's own): R, its residual's root-mean-square over
that of the record's own least-squares fit (1 plus a few per cent under the null of one system and white
equation noise), and its residual's root-mean-square over the training records' own.

Records are made apart from dynax's model code (`tests.reference.arm_reference`, DOP853 at rtol 1e-10): the
acrobot under a random elbow multisine, 10 s at 100 Hz. Training: one record (seed 0, encoder noise). Held out,
of the same arm: other seeds, three noise levels, other amplitudes, 500 Hz, 4 s, and with a Coulomb friction
(0.05 N m, smoothed) in training and held-out records alike (an effect the model misses); of another arm: every
base parameter x1.1, x1.2, x1.5, the second link's mass x1.5 (theta2, theta3, theta5), the first link x1.3
long (theta1, theta3, theta4), the dampings x3; the torque column x1.1, x2, x6 (another scale or unit). Then
the six DFKI runs (double pendulum, `friction="coulomb"`), each held out against a fit to each other, and each
of runs 00 and 03 against a fit to the five others, as logged and with its `tau2` doubled.

    python experiments/validation_system.py [--skip-dfki] [--out experiments/results/validation_system.json]

Prints, per case, R (pooled and per joint), the ratio to the training residual, and the held-out open-loop
RMSE at 0.5 s (`identify(..., refine=False)`: the harm, a validation that reads as a bad model).
"""

import argparse
import json
import pathlib
import sys
import warnings

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
TRUTH = np.array([1.333, 1.33, 1.0, 14.715, 9.81, 0.1, 0.1])
NOISE = {"none": (0.0, 0.0), "encoder": (1e-4, 0.01), "noisy": (1e-3, 0.1)}


def arm_record(seed, theta=TRUTH, rate_hz=100.0, duration=10.0, amplitude=3.0, noise="encoder", coulomb=0.0):
    from scipy.integrate import solve_ivp

    from tests.reference import arm_reference

    rng = np.random.default_rng(seed)
    freqs, phases = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6)

    def drive(t):
        return amplitude * float(np.sum(np.sin(2 * np.pi * freqs * t + phases))) / np.sqrt(6)

    ts = np.arange(0.0, duration + 0.5 / rate_hz, 1.0 / rate_hz)
    sol = solve_ivp(
        lambda t, x: arm_reference(tuple(theta), x, (0.0, drive(t)), coulomb=(coulomb, coulomb)),
        (0.0, ts[-1]),
        [0.2, 0.0, 0.0, 0.0],
        t_eval=ts,
        method="DOP853",
        rtol=1e-10,
        atol=1e-11,
    )
    xs = sol.y.T.copy()
    sq, sv = NOISE[noise]
    xs[:, :2] += sq * rng.standard_normal((len(ts), 2))
    xs[:, 2:] += sv * rng.standard_normal((len(ts), 2))
    return ts, xs, np.array([drive(t) for t in ts])


def trajectory(ts, xs, tau, source):
    import dynax

    return dynax.Trajectory(ts, xs, tau[:, None], ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", source)


def scaled(theta, factor, which):
    out = np.array(theta, dtype=float)
    out[list(which)] *= factor
    return out


def demeaned_equations(system, record, friction):
    """`(a, y, n_joints)`: the record's inverse-dynamics equations (`Dynamic()`'s, settings chosen from its
    spectra), stacked joint by joint, each joint's rows less their mean (a force offset of the record's own)."""
    import dynax
    from dynax.internal import stacked_equations

    _, a, y, _, _, _, _, _, counts, _ = stacked_equations(
        system, [record], dynax.Dynamic(offsets=False), friction, None, 1e-7
    )
    a, y = np.asarray(a, dtype=float), np.asarray(y, dtype=float)
    n = len(y) // sum(counts)
    a, y = a.reshape(n, -1, a.shape[1]), y.reshape(n, -1)
    a, y = a - a.mean(axis=1, keepdims=True), y - y.mean(axis=1, keepdims=True)
    return a.reshape(-1, a.shape[2]), y.ravel(), n


def residual_ratios(system, friction, estimate, names, training, held):
    """`(R, per-joint R, rms held-out / rms training)` of the module notes for the one held-out record: the
    training estimate's inverse-dynamics residual on `held` over the residual of `held`'s own least-squares fit
    (each joint's rows less their mean), and over the training estimate's residual on its own records."""
    from dynax.internal import parameter_names, with_friction

    full = parameter_names(with_friction(system, friction), friction)
    theta = np.zeros(len(full))
    for name, value in zip(names, np.asarray(estimate, dtype=float)):
        theta[full.index(name)] = value
    squares = rows = 0
    for record in training:
        a, y, _ = demeaned_equations(system, record, friction)
        squares, rows = squares + float(np.sum((y - a @ theta) ** 2)), rows + len(y)
    a, y, n = demeaned_equations(system, held, friction)
    own = np.linalg.lstsq(a, y, rcond=None)[0]
    given, mine = (y - a @ theta).reshape(n, -1), (y - a @ own).reshape(n, -1)
    ratio = float(np.sqrt(np.sum(given**2) / np.sum(mine**2)))
    per_joint = [float(v) for v in np.sqrt(np.sum(given**2, axis=1) / np.sum(mine**2, axis=1))]
    return ratio, per_joint, float(np.sqrt(np.mean(given**2)) / np.sqrt(squares / rows))


def fit_and_check(system, train, held, friction="viscous"):
    """`((R, per-joint R, rms ratio), rmse at 0.5 s)` of a least-squares fit to `train` held out on `held`."""
    import dynax

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = dynax.identify(system, train, friction=friction, refine=False, validation=dynax.Validate(held))
    solution = fit.stages[0].solution
    found = residual_ratios(system, friction, solution.value, tuple(solution.parameters.names), train, held[0])
    rmse = float(fit.validation.rmse[-1]) if fit.validation is not None else float("nan")
    return found, rmse


def synthetic_cases():
    base = {"noise": "encoder"}
    same = {f"same arm, seed {s}, {n}": dict(seed=s, noise=n) for s in (1, 2, 3) for n in ("none", "encoder", "noisy")}
    same["same arm, amplitude 1.5"] = dict(seed=4, amplitude=1.5, **base)
    same["same arm, amplitude 5"] = dict(seed=5, amplitude=5.0, **base)
    same["same arm, 500 Hz"] = dict(seed=6, rate_hz=500.0, **base)
    same["same arm, 4 s"] = dict(seed=7, duration=4.0, **base)
    other = {
        "every base parameter x1.1": dict(seed=1, theta=scaled(TRUTH, 1.1, range(5)), **base),
        "every base parameter x1.2": dict(seed=1, theta=scaled(TRUTH, 1.2, range(5)), **base),
        "every base parameter x1.5": dict(seed=1, theta=scaled(TRUTH, 1.5, range(5)), **base),
        "second link's mass x1.5": dict(seed=1, theta=scaled(TRUTH, 1.5, (1, 2, 4)), **base),
        "first link x1.3 long": dict(seed=1, theta=scaled(TRUTH, 1.3, (0, 2, 3)), **base),
        "dampings x3": dict(seed=1, theta=scaled(TRUTH, 3.0, (5, 6)), **base),
    }
    return same, other


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(REPO / "experiments" / "results" / "validation_system.json"))
    parser.add_argument("--skip-dfki", action="store_true")
    args = parser.parse_args()
    sys.path.insert(0, str(REPO))
    import jax

    jax.config.update("jax_enable_x64", True)
    import dynax

    rows = []

    def report(group, name, found, rmse):
        ratio, per_joint, to_training = found
        rows.append(
            {
                "group": group,
                "case": name,
                "ratio": round(ratio, 3),
                "joint_ratios": [round(v, 3) for v in per_joint],
                "rms_ratio_to_training": round(to_training, 3),
                "rmse_0.5s": round(rmse, 4),
            }
        )
        print(
            f"{group:>6} | {name:<42} | R {ratio:6.3g} | per joint "
            + " ".join(f"{v:5.3g}" for v in per_joint)
            + f" | rms / training's {to_training:6.3g} | RMSE 0.5 s {rmse:.4f}",
            flush=True,
        )

    train = [trajectory(*arm_record(0), "train.csv")]
    same, other = synthetic_cases()
    for name, kw in same.items():
        report("same", name, *fit_and_check(dynax.Acrobot(), train, [trajectory(*arm_record(**kw), "held.csv")]))
    for name, kw in other.items():
        report("other", name, *fit_and_check(dynax.Acrobot(), train, [trajectory(*arm_record(**kw), "held.csv")]))
    for factor in (1.1, 2.0, 6.0):
        ts, xs, tau = arm_record(1)
        report(
            "other",
            f"torque x{factor:g}",
            *fit_and_check(dynax.Acrobot(), train, [trajectory(ts, xs, factor * tau, "held.csv")]),
        )
    coulomb_train = [trajectory(*arm_record(0, coulomb=0.05), "train.csv")]
    for seed in (1, 2, 3):
        held = [trajectory(*arm_record(seed, coulomb=0.05), "held.csv")]
        report("same", f"Coulomb 0.05 in both, seed {seed}", *fit_and_check(dynax.Acrobot(), coulomb_train, held))
    for amplitude in (1.0, 6.0):
        held = [trajectory(*arm_record(8, amplitude=amplitude, coulomb=0.05), "held.csv")]
        report("same", f"Coulomb 0.05, amplitude {amplitude:g}", *fit_and_check(dynax.Acrobot(), coulomb_train, held))

    if not args.skip_dfki:
        from tests.conftest import DFKI_MAPPING

        folder = REPO.parent / "shared" / "datasets" / "dfki_double_pendulum" / "sys_id"
        runs = {}
        for n in ("00", "01", "02", "03", "05", "12"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runs[n] = dynax.load_trajectory(folder / f"trajectory_{n}.csv", "double_pendulum", mapping=DFKI_MAPPING)
        for a in runs:
            for b in runs:
                if a != b:
                    found, rmse = fit_and_check(dynax.DoublePendulum(), [runs[a]], [runs[b]], friction="coulomb")
                    report("dfki", f"train {a}, held out {b}", found, rmse)
        for n in ("00", "03"):
            others = [runs[m] for m in runs if m != n]
            for factor, label in ((1.0, ""), (2.0, ", tau2 x2")):
                held = runs[n]
                if factor != 1.0:
                    held = dynax.Trajectory(
                        held.ts,
                        held.xs,
                        np.asarray(held.us) * np.array([1.0, factor]),
                        held.state_names,
                        held.input_names,
                        held.system,
                        held.source,
                    )
                found, rmse = fit_and_check(dynax.DoublePendulum(), others, [held], friction="coulomb")
                report("dfki" if factor == 1.0 else "other", f"train the 5 others, held out {n}{label}", found, rmse)

    pathlib.Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pathlib.Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")
    for group in ("same", "dfki", "other"):
        for key in ("ratio", "rms_ratio_to_training"):
            values = [r[key] for r in rows if r["group"] == group]
            if values:
                print(f"{group}: {len(values)} cases, {key} from {min(values):.3g} to {max(values):.3g}")


if __name__ == "__main__":
    main()
