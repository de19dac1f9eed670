"""The diagnosis on real rigs: the DFKI double pendulum on runs dynax does not train on (including splits with
the large-amplitude run held out) and the EMPS axis, which needs Coulomb friction near the published value.
All in the default suite (issue 10, item 8)."""

import pathlib

import jax.numpy as jnp
import pytest

from dynax import diagnose, Horizons, Known, LinearAxis, load_trajectory, Refit, Trajectory
from dynax.internal import butterworth_filtfilt, central_difference, resample
from tests.conftest import DFKI_MAPPING

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


DATASETS = pathlib.Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets"


def test_emps_needs_coulomb_friction_near_the_published_value():
    """Refit mode's default keeps the nominal friction (200 N s/m, no Coulomb) and refits mass and offset:
    Coulomb friction is named near the published value. Refitting mass and viscous instead (the earlier
    recipe) lets the viscous coefficient absorb it, and one 7.4 s held-out segment is then too little
    for the test (p = 0.046; docs/tutorials/real_data_diagnosis.md)."""
    raw = load_trajectory(
        DATASETS / "emps" / "DATA_EMPS.mat",
        "linear_axis",
        mapping={"t": "t", "q": "qm", "force": "vir"},
        scale={"force": 35.15065188},
    )
    q = butterworth_filtfilt(raw.ts, raw.xs[:, 0], cutoff_hz=40.0)
    dq = central_difference(raw.ts, q)
    n = (len(raw) - 1) // 10 * 10
    ts, xs = raw.ts[:n:10], jnp.stack([q, dq], axis=1)[:n:10]
    us = raw.us[:n].reshape(-1, 10, 1).mean(axis=1)
    k = int(0.7 * len(ts))
    train = Trajectory(ts[:k], xs[:k], us[:k], raw.state_names, raw.input_names, "linear_axis")
    validation = Trajectory(ts[k:], xs[k:], us[k:], raw.state_names, raw.input_names, "linear_axis")
    nominal = LinearAxis(
        mass=jnp.asarray(90.0), viscous=jnp.asarray(200.0), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)
    )
    report = diagnose(nominal, train, validation, mode=Refit(), horizons=Horizons(reference_s=0.25))
    causes = {(f["cause"], f["where"]): f for f in report.findings}
    assert ("coulomb_friction", "q") in causes
    # Published: Fc = 20.39 N, M = 95.1 kg, Fv = 203.5 N s/m, offset -3.16 N (Janot, Gautier and Brunot 2019).
    assert 15.0 < causes[("coulomb_friction", "q")]["coefficient"] < 26.0
    assert 85.0 < float(report.extended_model.system.mass) < 105.0
    assert -4.5 < float(report.extended_model.system.offset) < -2.0
    assert report.gain > 0.3
    assert report.verdict in ("explained", "unexplained")


# --- the DFKI double pendulum: train on some runs, hold out others ------------------------------------

LAB_EFFECTS = {"coulomb_friction", "viscous_friction", "rotor_inertia"}


def _dfki(run):
    path = DATASETS / "dfki_double_pendulum" / "sys_id" / f"trajectory_{run}.csv"
    return resample(load_trajectory(path, "double_pendulum", mapping=DFKI_MAPPING), 0.005)


def _model_3_1():
    """The lab's rigid-body model 3.1 (no friction, no rotor inertia) in base parameters."""
    from dynax import DoublePendulum

    m1, m2, l1, r1, r2, I1, I2, g = (
        0.6416937799349799,
        0.563935954099688,
        0.2,
        0.2,
        0.3212669909674605,
        0.02671076499939512,
        0.053878129629650884,
        9.81,
    )
    return DoublePendulum.from_base_parameters(
        dict(
            theta1=I1 + m2 * l1**2,
            theta2=I2,
            theta3=m2 * l1 * r2,
            theta4=g * (m1 * r1 + m2 * l1),
            theta5=g * m2 * r2,
            theta6=0.0,
            theta7=0.0,
        )
    )


def _assert_lab_effect(report, min_gain=0.25):
    j = report.to_json()
    assert j["verdict"] != "none", (j["candidates"][:4], j["test"])
    assert j["findings"] and j["findings"][0]["cause"] in LAB_EFFECTS, j["findings"]
    assert j["gain"] >= min_gain, (j["gain"], j["findings"])
    # The horizon came from the training runs, and the report says how.
    assert j["horizon"]["rule"].startswith("predictability horizon") or "already" in j["horizon"]["rule"]
    # The driver's noisy velocity estimates were replaced by ones from the encoder positions, and the report says so.
    assert j["data"]["velocities"].startswith("from positions"), j["data"]
    return j


def test_dfki_known_mode_names_the_labs_effects_on_held_out_runs():
    """Train on runs 00, 01; hold out 02 and the elbow-only run 03 (split S1 of experiments/diagnose_real_splits.py)."""
    report = diagnose(_model_3_1(), [_dfki("00"), _dfki("01")], [_dfki("02"), _dfki("03")], mode=Known())
    j = _assert_lab_effect(report)
    causes = {(f["cause"], f["where"]) for f in j["findings"]}
    assert ("rotor_inertia", "q2") in causes  # the lab's gr^2 Ir = 0.0036 kg m^2
    assert 0.002 < next(f["coefficient"] for f in j["findings"] if f["cause"] == "rotor_inertia") < 0.01
    assert all(r["gain"] > 0 for r in j["runs"])  # better on each held-out run


@pytest.mark.slow  # about 100 s: refit mode on real runs
def test_dfki_refit_mode_names_coulomb_friction():
    """Train on 01, 03 and the large-amplitude run 12; hold out 05 (shoulder motor only) and 02 (split S4)."""
    report = diagnose(_model_3_1(), [_dfki("01"), _dfki("03"), _dfki("12")], [_dfki("05"), _dfki("02")], mode=Refit())
    j = _assert_lab_effect(report)
    assert any(f["cause"] == "coulomb_friction" for f in j["findings"]), j["findings"]
    # Every finding rests on a significant test: its own or, named for a look-alike that passed (closed testing:
    # the shoulder's stiction here, Coulomb friction predicting the held-out runs better), that look-alike's.
    for f in j["findings"]:
        assert (f["named_for"]["p_value"] if "named_for" in f else f["p_value"]) < 0.01, f
    # Rotor inertia at the shoulder adds to theta1, which the refit fits: reported as absorbed. The lab's
    # rigid-body model has no friction (theta6 = theta7 = 0), which the refit keeps and the candidates test.
    absorbed = {(c["cause"], c["where"]) for c in j["not_identifiable"]}
    assert ("rotor_inertia", "q1") in absorbed and ("viscous_friction", "q1") not in absorbed


@pytest.mark.slow  # about 3 min on 2 cores; the quick suite keeps the known-mode case on held-out runs
@pytest.mark.parametrize("train, validation", [(("00", "01", "02"), ("12",)), (("02", "03", "05"), ("00", "12"))])
def test_dfki_known_mode_with_the_large_amplitude_run_held_out(train, validation):
    report = diagnose(_model_3_1(), [_dfki(r) for r in train], [_dfki(r) for r in validation], mode=Known())
    _assert_lab_effect(report)


@pytest.mark.slow  # about 80 s: another DFKI split
def test_dfki_refit_mode_with_the_large_amplitude_run_and_a_small_one_held_out():
    """Train on 02, 03, 05 (two drive one motor only); hold out 00 and the large-amplitude run 12 (split S3)."""
    report = diagnose(_model_3_1(), [_dfki(r) for r in ("02", "03", "05")], [_dfki("00"), _dfki("12")], mode=Refit())
    j = _assert_lab_effect(report)
    assert all(r["gain"] > 0 for r in j["runs"])  # a cause must help on each held-out run, run 12 included


@pytest.mark.slow  # about 50 s: another DFKI split
def test_dfki_refit_mode_with_only_the_large_amplitude_run_held_out():
    """Split S2: train on the small-amplitude runs 00, 01, 02; hold out only the 6 s large-amplitude run 12.
    Before cross-fitting, refit mode named nothing here: the one short chaotic held-out run was too little
    for the test (Coulomb friction at the elbow p = 0.13), and screening on it ranked friction last. With
    each training run also held out in turn, the elbow's Coulomb friction is named (0.12 N m after the joint
    refit with the shoulder's viscous friction; the lab's c_f pi/2 = 0.12 N m) and helps on every run. On run
    12 itself the extension gains 27 % at 0.1 s (25 % is the practical bar); it was 21 % while the signal
    band's edge was the last Welch bin above the threshold, which read run 12's band as 1.6 Hz instead of 3.1
    and started its windows from velocities of a 325 ms cubic fit. The cross-fitted runs gain about 50 %."""
    report = diagnose(_model_3_1(), [_dfki(r) for r in ("00", "01", "02")], [_dfki("12")], mode=Refit())
    j = _assert_lab_effect(report)
    assert (j["findings"][0]["cause"], j["findings"][0]["where"]) == ("coulomb_friction", "q2"), j["findings"]
    assert 0.08 < j["findings"][0]["coefficient"] < 0.3
    cross_fitted = [r for r in j["runs"] if r["held_out"] == "cross-fitted"]
    assert len(cross_fitted) == 3 and all(r["gain"] > 0.25 for r in cross_fitted), j["runs"]


@pytest.mark.slow  # about 70 s: another DFKI split
def test_dfki_refit_mode_names_nothing_the_held_out_runs_reject():
    """Train on 00, 02 and the shoulder-only run 05; hold out 01 and the elbow-only run 03 (a split outside
    the documented four). A Coulomb friction is named first: the shoulder's, then the elbow's (it gains 75 and 32 %
    on the held-out runs, 20 % on the typical window, 3 % pooled, where run 02's windows score ten times the
    others'), then the ratio of the motors' torque gains (10 % on the held-out runs): 73 % at 0.1 s (66 % when
    the smallest gain read the pooled gain). Before the `held_out` rule the cross-fitted runs carried a torque
    gain and an offset on the shoulder through the pooled test (6 % and 71 % pooled) although both made the
    held-out runs worse (8 % and 15 %), and the returned model's held-out gain fell to 45 %. A finding must not
    make the returned model worse on held-out data."""
    report = diagnose(_model_3_1(), [_dfki(r) for r in ("00", "02", "05")], [_dfki("01"), _dfki("03")], mode=Refit())
    j = _assert_lab_effect(report)
    assert j["findings"][0]["cause"] == "coulomb_friction", j["findings"]
    assert j["gain"] >= j["findings"][0]["gain"] - 0.01, (j["gain"], j["findings"])
    for r in j["rounds"]:
        for c in r["candidates"]:
            assert c["outcome"] == "stopped" or c["gain"] > 0, (r["round"], c)
    stopped = [
        c for r in j["rounds"] for c in r["candidates"] if any(t.startswith("held_out") for t in c["stopped_by"])
    ]
    assert any(c["cause"] == "input_offset" and c["where"] == "tau1" for c in stopped), j["rounds"]
    # That offset is the recordings': the shoulder torque reads 0.14 N m high in run 00 and 0.07 in held-out run
    # 01, about nothing in 02 and 03 (both halves of each run agree), and the report says so.
    offsets = [n for n in j["notes"] if "offset that differs from record to record at q1" in n]
    assert offsets and "trajectory_00.csv +0.1" in offsets[0] and "trajectory_01.csv +0.0" in offsets[0], j["notes"]
    # And the five runs disagree on the elbow's Coulomb friction (0.05 to 0.12 N m in the least-squares
    # equations; the four parts of each run agree more closely), which the report says too.
    friction = [n for n in j["notes"] if n.startswith("The Coulomb friction differs from record to record")]
    assert friction and "fc2 (trajectory_00.csv 0.1" in friction[0], j["notes"]


@pytest.mark.slow  # about 2 min: the CLI on raw DFKI files end to end
def test_dfki_cli_on_the_raw_files_with_no_nominal_and_no_resampling(tmp_path, capsys):
    """A new user's first command: the raw recordings (irregular ~2 ms sampling), no `--nominal`, no `--dt`.
    The default DoublePendulum is another machine (theta1 1.33 against the rig's 0.047): the CLI says so and
    diagnoses against the rigid body least squares identifies from the training runs, friction zero. Split S1
    (train 00, 01; hold out 02, 03) must then name the lab's Coulomb friction at the elbow, as with the lab's
    model_3.1 as nominal (0.11 N m, the lab's 0.12; 79 % with the shoulder's Coulomb friction and a torque
    gain; docs/tutorials/real_data_diagnosis.md)."""
    import json

    from dynax.internal import cli_main

    runs = DATASETS / "dfki_double_pendulum" / "sys_id"
    mapping = ",".join(f"{k}={v}" for k, v in DFKI_MAPPING.items())
    out = tmp_path / "s1"
    code = cli_main(
        [
            "diagnose",
            "double_pendulum",
            str(runs / "trajectory_00.csv"),
            str(runs / "trajectory_01.csv"),
            "--validation",
            str(runs / "trajectory_02.csv"),
            str(runs / "trajectory_03.csv"),
            "--map",
            mapping,
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    assert "not the default DoublePendulum" in err
    j = json.loads((out / "report.json").read_text())
    assert abs(j["data"]["dt"] - 0.002) < 2e-4 and any("resampled" in n for n in j["notes"])
    assert any("rigid body identified from the training runs" in n for n in j["notes"])
    # the rig's size (the lab: theta1 = 0.049; the default 1.33), refitted; the friction kept at zero
    assert 0.02 < j["nominal"]["parameters"]["theta1"] < 0.15 and j["nominal"]["parameters"]["theta7"] == 0.0
    causes = {(f["cause"], f["where"]): f for f in j["findings"]}
    assert ("coulomb_friction", "q2") in causes, j["findings"]
    # the lab: c_f pi/2 = 0.12 N m; with no viscous term beside it, a Coulomb term also carries the viscous
    # losses (known mode on the lab's model: 0.12-0.22 N m over the splits)
    assert 0.05 < causes[("coulomb_friction", "q2")]["coefficient"] < 0.3
    assert j["gain"] >= 0.25
    # Two training runs are not cross-fitted (each fold would fit one run), and the note says so.
    assert j["test"]["cross_fitting"] is None and any(n.startswith("Not cross-fitted") for n in j["notes"])
    # A gain on the shoulder motor's torque is one on the elbow's once theta1..theta5 are refitted: the refit
    # determines only their ratio, so the finding cannot claim to be told apart from the other (its paired
    # test of two fits of one model can still come out below alpha), and a note says why.
    gain = causes[("input_gain", "tau1")] if ("input_gain", "tau1") in causes else causes[("input_gain", "tau2")]
    assert gain["confidence"] == "low" and any(a["equivalent"] for a in gain["look_alikes"]), gain
    assert any("are one model with a refit of the nominal parameters" in n and "ratio" in n for n in j["notes"])
    assert (out / "measured_vs_simulated_run2.png").stat().st_size > 0


def test_dfki_nominal_from_a_run_that_hardly_moves_the_elbow_says_what_it_cannot_determine():
    """Run 05 drives the shoulder motor only: least squares on it alone sees the rig's size (not the default's)
    but pins the elbow's gravity term theta5 poorly; the CLI's note says so rather than trusting it silently.
    On runs 00 and 01 every size parameter is determined within 10 %: no such warning."""
    from dynax import DoublePendulum
    from dynax.internal import nominal_from_data

    nominal, note = nominal_from_data(DoublePendulum(), [_dfki("05")])
    assert "not the default DoublePendulum" in note and "theta5 only to ±" in note
    assert float(nominal.theta6) == float(nominal.theta7) == 0.0 and float(nominal.theta1) < 0.1
    _, note = nominal_from_data(DoublePendulum(), [_dfki("00"), _dfki("01")])
    assert "not the default" in note and "only to ±" not in note
