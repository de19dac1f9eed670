"""The numbers of the vehicle fits, to compare two versions of the code bit for bit.

Fits, through `dynax.fit_vehicle` and `dynax.fit_quadrotor` (whatever they call), and saves each fit's
weights, estimate, loss, loss history and standard errors:

- the synthetic hover helicopter (`generate_helicopter_flight("hover", 12.0, seed=3)`): `OneStep`,
  `Lagged` (H = 0.2 s, every 5th start, 5 iterations), `Backprop` (H = 0.1 s, every 5th start, 10
  steps), one-step and lagged with breaks at samples 300 and 700, backprop warm-started from a lagged
  fit, and `FrequencyDomain` on the linear model;
- a quadrotor on two NanoBench flights (`B8_star_fast_rep1`, `B2_circle_slow_rep2`: their usable runs,
  joined): one-step of the acceleration and linear models on both flights and on the first run alone,
  lagged (H = 0.2 s, every 20th start, 3 iterations) and backprop warm-started from it (5 steps).

Run `python experiments/vehicle_fit_numbers.py save OUT.npz` on each version (e.g. a `git archive`
of the older one on `PYTHONPATH`), then `python experiments/vehicle_fit_numbers.py compare A.npz
B.npz`, which prints per array `bitwise` or the largest relative difference.
"""

import pathlib
import sys

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import dynax

DATA = pathlib.Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "nanobench"
NANOBENCH_MAP = dict(
    item.split("=")
    for item in (
        "x=px,y=py,z=pz,p=wx_vicon,q=wy_vicon,r=wz_vicon,m1=motor_motor_m1,m2=motor_motor_m2,"
        "m3=motor_motor_m3,m4=motor_motor_m4,vbat=pwr_pm_vbat"
    ).split(",")
)


def save(out: str) -> None:
    res = {}

    def keep(name, sol):
        res[name + "/weights"] = np.asarray(sol.model.body_model.weights)
        res[name + "/value"] = np.asarray(sol.value)
        res[name + "/loss"] = np.asarray(sol.loss)
        res[name + "/loss_history"] = np.asarray(sol.loss_history)
        res[name + "/std"] = np.asarray(sol.std_errors)

    flight = dynax.synthetic.generate_helicopter_flight("hover", 12.0, seed=3)
    heli = dynax.Helicopter()
    lagged = dynax.Lagged(horizon=0.2, stride=5, max_iterations=5)
    backprop = dynax.Backprop(horizon=0.1, stride=5, max_steps=10)
    for name, criterion in (("one-step", dynax.OneStep()), ("lagged", lagged), ("backprop", backprop)):
        keep("heli/" + name, dynax.fit_vehicle(heli, flight, criterion, progress=False))
    keep("heli/one-step-breaks", dynax.fit_vehicle(heli, flight, dynax.OneStep(), breaks=[300, 700]))
    short = dynax.Lagged(horizon=0.2, stride=5, max_iterations=3)
    keep("heli/lagged-breaks", dynax.fit_vehicle(heli, flight, short, breaks=[300, 700], progress=False))
    start = dynax.fit_vehicle(heli, flight, short, progress=False).model
    warm = dynax.Backprop(horizon=0.2, stride=5, max_steps=5)
    keep("heli/backprop-warm", dynax.fit_vehicle(start, flight, warm, warm_start=True, progress=False))
    linear = dynax.Helicopter(dynax.LinearVelocityModel())
    keep("heli/frequency", dynax.fit_vehicle(linear, flight, dynax.FrequencyDomain()))

    runs = []
    for name in ("B8_star_fast_rep1", "B2_circle_slow_rep2"):
        trajectory, notes = dynax.load_flight(DATA / f"{name}.csv.gz", mapping=NANOBENCH_MAP)
        runs += dynax.usable_segments(trajectory, notes, min_samples=52)
    res["quad/nruns"] = np.asarray(len(runs))
    for family in ("acceleration", "linear"):
        quad = dynax.Quadrotor.from_flights(family, runs)
        keep(f"quad/{family}/one-step", dynax.fit_quadrotor(quad, runs, dynax.OneStep()))
        keep(f"quad/{family}/one-step-1run", dynax.fit_quadrotor(quad, runs[0], dynax.OneStep()))
    quad = dynax.Quadrotor.from_flights("acceleration", runs)
    lag = dynax.fit_quadrotor(quad, runs, dynax.Lagged(horizon=0.2, stride=20, max_iterations=3), progress=False)
    keep("quad/lagged", lag)
    refine = dynax.Backprop(horizon=0.2, stride=20, max_steps=5)
    keep("quad/backprop-warm", dynax.fit_quadrotor(lag.model, runs, refine, warm_start=True, progress=False))
    np.savez(out, **res)
    print(f"{len(res)} arrays; losses:", {k: float(v) for k, v in res.items() if k.endswith("/loss")})


def compare(first: str, second: str) -> None:
    a, b = np.load(first), np.load(second)
    if set(a.files) != set(b.files):
        raise SystemExit(f"different arrays: {sorted(set(a.files) ^ set(b.files))}")
    for key in sorted(a.files):
        x, y = a[key], b[key]
        if np.array_equal(x, y, equal_nan=True):
            print(f"{key:45s} bitwise")
            continue
        both = np.isfinite(x) & np.isfinite(y)
        worst = np.max(np.abs(x - y)[both] / np.maximum(np.abs(x[both]), 1e-300)) if both.any() else np.nan
        changed = " (NaN where the other has a value)" if np.any(np.isnan(x) != np.isnan(y)) else ""
        print(f"{key:45s} largest relative difference {worst:.3g}{changed}")


if __name__ == "__main__":
    if sys.argv[1:2] == ["save"] and len(sys.argv) == 3:
        save(sys.argv[2])
    elif sys.argv[1:2] == ["compare"] and len(sys.argv) == 4:
        compare(sys.argv[2], sys.argv[3])
    else:
        raise SystemExit(__doc__)
