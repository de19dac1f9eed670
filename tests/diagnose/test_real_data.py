"""The diagnosis on real rigs (slow): the EMPS axis needs Coulomb friction, near the published value."""

import pathlib

import jax.numpy as jnp
import pytest

from dynax import LinearAxis
from dynax._data import butterworth_filtfilt, central_difference, load_trajectory, Trajectory
from dynax._diagnose import diagnose, Refit

DATASETS = pathlib.Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets"


@pytest.mark.slow
def test_emps_needs_coulomb_friction_near_the_published_value():
    raw = load_trajectory(DATASETS / "emps" / "DATA_EMPS.mat", "linear_axis",
                          mapping={"t": "t", "q": "qm", "force": "vir"}, scale={"force": 35.15065188})
    q = butterworth_filtfilt(raw.ts, raw.xs[:, 0], cutoff_hz=40.0)
    dq = central_difference(raw.ts, q)
    n = (len(raw) - 1) // 10 * 10
    ts, xs = raw.ts[:n:10], jnp.stack([q, dq], axis=1)[:n:10]
    us = raw.us[:n].reshape(-1, 10, 1).mean(axis=1)
    k = int(0.7 * len(ts))
    train = Trajectory(ts[:k], xs[:k], us[:k], raw.state_names, raw.input_names, "linear_axis")
    validation = Trajectory(ts[k:], xs[k:], us[k:], raw.state_names, raw.input_names, "linear_axis")
    nominal = LinearAxis(mass=jnp.asarray(90.0), viscous=jnp.asarray(200.0), coulomb=jnp.asarray(0.0),
                         offset=jnp.asarray(0.0))
    report = diagnose(nominal, train, validation, mode=Refit(parameters=("mass", "viscous")),
                      reference_horizon_s=0.25)
    causes = {(f["cause"], f["where"]): f for f in report.findings}
    assert ("coulomb_friction", "q") in causes
    # Published: Fc = 20.39 N, M = 95.1 kg, Fv = 203.5 N s/m (Janot, Gautier and Brunot 2019).
    assert 15.0 < causes[("coulomb_friction", "q")]["coefficient"] < 26.0
    assert 85.0 < float(report.extended_model.system.mass) < 105.0
    assert report.gain > 0.3
    assert report.verdict in ("explained", "unexplained")
