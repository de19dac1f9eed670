"""An encoder-only record (angles and torque, no velocity column) identified through `dynax identify` with
defaults: the velocities estimated from the angles carry no lag, so a clean record gives the true parameters.

The record is made apart from dynax's model code: `tests.reference.arm_reference` (the arm's equations
written out with numpy) integrated by scipy's DOP853 at tight tolerance under a continuous multisine elbow
torque, sampled at the rate under test. A backward difference lags half a sample, which at 100 Hz put the
viscous coefficients 15 % and 34 % low and theta1..theta5 0.5 to 1 % off.
"""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynax
from dynax.internal import cli_main as main
from tests.reference import arm_reference


def _encoder_record(path, rate_hz: float, duration_s: float = 10.0):
    theta = [float(v) for v in dynax.Acrobot().base_parameters.values()]
    rng = np.random.default_rng(0)
    freqs, phases = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6)

    def tau(t):
        return 3.0 * np.sum(np.sin(2 * np.pi * freqs * t + phases)) / np.sqrt(6)

    ts = np.arange(0.0, duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    sol = solve_ivp(
        lambda t, x: arm_reference(theta, x, (0.0, tau(t))),
        (0.0, ts[-1]),
        [0.2, 0.0, 0.0, 0.0],
        t_eval=ts,
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
    )
    table = np.column_stack([ts, sol.y[0], sol.y[1], [tau(t) for t in ts]])
    np.savetxt(path, table, delimiter=",", header="t,q1,q2,tau2", comments="", fmt="%.17g")
    return dict(zip(dynax.Acrobot().base_parameters, theta))


@pytest.mark.parametrize("rate_hz", [100.0, pytest.param(1000.0, marks=pytest.mark.heavy)])
def test_encoder_only_clean_record_gives_the_true_parameters(rate_hz, tmp_path, capsys):
    truth = _encoder_record(tmp_path / "encoders.csv", rate_hz)
    out = tmp_path / "params.json"
    assert main(["identify", "acrobot", str(tmp_path / "encoders.csv"), "--out", str(out)]) == 0
    fitted = json.loads(out.read_text())["parameters"]
    errors = {name: fitted[name] / truth[name] - 1 for name in truth}
    assert all(abs(e) < 0.02 for e in errors.values()), errors
