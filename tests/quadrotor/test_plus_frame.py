"""Another drone's logs through the same commands, given only a `--map`.

The flights are of a 0.5 kg '+' quadrotor with 17 cm arms whose log records the measured rotor speeds
[rad/s] (600 at hover) under column names of its own, made apart from dynax's model code
(`synthetic_flight.PLUS`: scipy DOP853 under a geometric controller), each log starting with the
vehicle on the floor, motors off, as a real log does. `dynax fit quadrotor`, `dynax evaluate` and
`dynax diagnose quadrotor` run on them as on the NanoBench Crazyflie's PWM logs.
"""

import json

import numpy as np
import pytest

from dynax.internal import cli_main as main

from .synthetic_flight import PLUS, quadrotor_flight

COLUMNS = {
    "t": "time_s",
    "x": "mocap_px",
    "y": "mocap_py",
    "z": "mocap_pz",
    "qw": "att_qw",
    "qx": "att_qx",
    "qy": "att_qy",
    "qz": "att_qz",
    "vx": "mocap_vx",
    "vy": "mocap_vy",
    "vz": "mocap_vz",
    "p": "gyro_x",
    "q": "gyro_y",
    "r": "gyro_z",
    "m1": "rpm_front",  # rad/s despite the name, as loggers name things
    "m2": "rpm_right",
    "m3": "rpm_back",
    "m4": "rpm_left",
}
MAP = ",".join(f"{k}={v}" for k, v in COLUMNS.items())


def _log(path, seed, rest_s=1.0, **effects):
    """A '+' flight written as that drone's CSV: `rest_s` on the floor (motors off, level) before it."""
    flight = quadrotor_flight(15.0, seed=seed, vehicle=PLUS, **effects)
    xs, us = np.asarray(flight.xs), np.asarray(flight.us)
    n = int(round(rest_s / flight.dt))
    pad = np.zeros((n, xs.shape[1]))
    pad[:, :2], pad[:, 2], pad[:, 3] = xs[0, :2], xs[:, 2].min() - 0.3, 1.0
    states = np.concatenate([pad, xs])
    inputs = np.concatenate([np.zeros((n, us.shape[1])), us])
    table = np.column_stack([50.0 + np.arange(len(states)) * flight.dt, states, inputs])
    np.savetxt(path, table, delimiter=",", header=",".join(COLUMNS.values()), comments="", fmt="%.17g")
    return str(path)


@pytest.mark.slow  # a fit, an evaluation and a diagnosis of 15 s flights: 9 minutes on two loaded cores
def test_a_plus_frame_logging_rotor_speeds_needs_only_a_map(tmp_path, capsys):
    drag = (0.3, 0.3, 0.05)  # a larger rotor's drag, 1/s
    train = _log(tmp_path / "train.csv", 21, drag=drag)
    test = _log(tmp_path / "test.csv", 121, drag=drag)
    model = tmp_path / "model.json"
    fit = ["fit", "quadrotor", train, "--map", MAP, "--model", "nominal", "--criterion", "one-step"]
    assert main([*fit, "--out", str(model)]) == 0
    assert "ground segment from t = 0.00" in capsys.readouterr().out  # the second on the floor, left out
    obj = json.loads(model.read_text())
    assert obj["input_scale"][0] == pytest.approx(600, rel=0.1)  # rad/s, as logged
    metrics = tmp_path / "metrics.json"
    assert main(["evaluate", str(model), test, "--map", MAP, "--steps", "1,10,50", "--out", str(metrics)]) == 0
    out = json.loads(metrics.read_text())
    for group in ("position", "body_rate"):
        assert out["model"]["mae"][group][-1] < 0.5 * out["constant_velocity"]["mae"][group][-1], group
    report = tmp_path / "report"
    diagnose = ["diagnose", "quadrotor", train, "--validation", test, "--map", MAP, "--max-terms", "1"]
    assert main([*diagnose, "--no-discovery", "--out", str(report)]) == 0
    j = json.loads((report / "report.json").read_text())
    # The drag leads the refitted candidates at its size on both horizontal axes (as the rotor plane's one
    # cause `u+v`, or each axis's). On this heavier vehicle it is a few per cent of the nominal's 0.5 s error (the
    # rest is the measurement noise of the starts): significant, but short of a finding's practical size; whatever
    # is named must be it.
    leading = [c for c in j["candidates"] if c.get("gain") is not None][:2]
    axes = {axis for c in leading for axis in c["where"].split("+")}
    assert {c["cause"] for c in leading} == {"rotor_drag"} and axes == {"u", "v"}, leading
    for c in leading:
        assert c["coefficient"] == pytest.approx(0.3, rel=0.2) and c["p_value"] < 0.05
    assert {f["cause"] for f in j["findings"]} <= {"rotor_drag"}, j["findings"]
