"""`report.json` follows the contract, `report.md` and figures are written, and `dynax diagnose` works end to end."""

import json

import numpy as np
import pytest

from dynax import Acrobot, diagnose, InputOffset, save_trajectory, Selection
from dynax.internal import cli_main
from dynax.synthetic import demo_data

CONTRACT_KEYS = ["system", "data", "nominal", "verdict", "findings", "extended", "gain", "reference_horizon_s"]


@pytest.fixture(scope="module")
def offset_data(tmp_path_factory):
    _, train, validation = demo_data(InputOffset(0, 0.25), seed=3)
    folder = tmp_path_factory.mktemp("offset")
    save_trajectory(train, folder / "run1.csv")
    save_trajectory(validation, folder / "run2.csv")
    return folder, train, validation


def test_cli_diagnose_writes_the_contract_report(offset_data, tmp_path, capsys):
    folder, _, _ = offset_data
    out = tmp_path / "diag"
    code = cli_main(
        ["diagnose", "acrobot", str(folder / "run1.csv"), "--validation", str(folder / "run2.csv"), "--out", str(out)]
    )
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert list(report)[: len(CONTRACT_KEYS)] == CONTRACT_KEYS
    assert report["system"] == "acrobot"
    assert report["data"]["train"].endswith("run1.csv") and report["data"]["validation"].endswith("run2.csv")
    assert report["data"]["n_train"] == 2001 and report["data"]["n_validation"] == 1000
    assert report["verdict"] == "explained"
    finding = report["findings"][0]
    assert {"cause", "where", "coefficient", "std_error", "gain"} <= set(finding)
    assert (finding["cause"], finding["where"]) == ("input_offset", "tau2")
    assert abs(finding["coefficient"] - 0.25) < 0.05
    assert report["extended"]["terms"] == ["input_offset@tau2"]
    assert "offset_tau2" in report["extended"]["parameters"]
    for model in ("nominal", "extended"):
        sim = report[model]["sim_error"]
        assert len(sim["horizons_s"]) == len(sim["rmse"]) and report["reference_horizon_s"] in sim["horizons_s"]
    h = report["nominal"]["sim_error"]["horizons_s"].index(report["reference_horizon_s"])
    expected_gain = 1 - report["extended"]["sim_error"]["rmse"][h] / report["nominal"]["sim_error"]["rmse"][h]
    assert np.isclose(report["gain"], expected_gain)
    for name in ("report.md", "measured_vs_simulated.png", "sim_error.png", "residuals.png"):
        assert (out / name).stat().st_size > 0
    assert "input_offset" in (out / "report.md").read_text()
    # the validation block (an extension inside the contract's model objects): fit % and residual tests
    for model in ("nominal", "extended"):
        v = report[model]["validation"]
        assert v["horizon_s"] == report["reference_horizon_s"]
        assert set(v["fit_percent"]) == {"q1", "q2", "dq1", "dq2"}
        (tests,) = v["residual_tests"]
        assert tests["run"].endswith("run2.csv") and set(tests["whiteness"]) == {"dq1", "dq2"}
        assert set(tests["cross_correlation"]["dq2"]) == {"tau2"} and 0 <= tests["whiteness"]["dq2"]["p_value"] <= 1
    fits = {m: report[m]["validation"]["fit_percent"] for m in ("nominal", "extended")}
    assert all(fits["extended"][s] > fits["nominal"][s] for s in ("q1", "q2"))  # the offset costs fit, found it is back
    assert "| extended |" in (out / "report.md").read_text() and "fit q1" in (out / "report.md").read_text()
    # every round of the selection: the selected candidate is the finding; the round after it says why it stopped
    rounds = report["rounds"]
    assert rounds[0]["model"] == [] and rounds[0]["outcome"] == "selected input_offset@tau2"
    (chosen,) = [c for c in rounds[0]["candidates"] if c["outcome"] == "selected"]
    assert (chosen["cause"], chosen["where"], chosen["stopped_by"]) == ("input_offset", "tau2", [])
    assert np.isclose(chosen["sim_error_gain"], finding["gain"])  # the finding's gain, from the same fit
    # no second cause is in the data: every candidate of the next round names the rule that stopped it
    assert len(rounds) == 2 and rounds[1]["model"] == ["input_offset@tau2"] and "stops" in rounds[1]["outcome"]
    assert all(c["outcome"] == "stopped" and c["stopped_by"] for c in rounds[1]["candidates"])
    assert "## Selection rounds" in (out / "report.md").read_text()
    captured = capsys.readouterr()
    printed = captured.out
    assert "Cause: input_offset at tau2" in printed and "Gain" in printed
    # stderr is not a terminal here: the stages as log lines (with the candidate batches), no bar
    assert "screening" in captured.err and "batch of 5 fits" in captured.err and "\r" not in captured.err


@pytest.mark.slow  # other record lengths: compiles the fits again
def test_cli_diagnose_without_validation_holds_out_and_says_so(offset_data, tmp_path):
    folder, _, _ = offset_data
    out = tmp_path / "diag"
    assert cli_main(["diagnose", "acrobot", str(folder / "run1.csv"), "--out", str(out), "--max-terms", "1"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert "held out" in " ".join(report["notes"])
    assert report["data"]["n_train"] + report["data"]["n_validation"] == 2001


def test_cli_diagnose_refuses_bad_input_and_writes_nothing(offset_data, tmp_path, capsys):
    folder, _, _ = offset_data
    bad = tmp_path / "bad.csv"
    bad.write_text("t,q1,q2,dq1\n0,0,0,0\n")
    out = tmp_path / "never"
    assert cli_main(["diagnose", "acrobot", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "dq2" in err
    assert not out.exists()
    assert cli_main(["diagnose", "acrobot", str(folder / "run1.csv"), "--max-terms", "0", "--out", str(out)]) == 2
    assert not out.exists()
    # Too short to judge: the one-step residuals drop about 0.1 s at each end (this crashed with a division by zero).
    _, train, _ = offset_data
    short = tmp_path / "short.csv"
    save_trajectory(
        type(train)(train.ts[:141], train.xs[:141], train.us[:141], train.state_names, train.input_names, "acrobot"),
        short,
    )
    assert cli_main(["diagnose", "acrobot", str(short), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "short.csv" in err and "held-out part of the record" in err and "42 samples" in err and "at least 44" in err
    assert not out.exists()


def test_cli_diagnose_helicopter_refuses_a_file_without_its_columns(offset_data, tmp_path, capsys):
    folder, _, _ = offset_data
    out = tmp_path / "heli"
    assert cli_main(["diagnose", "helicopter", str(folder / "run1.csv"), "--out", str(out)]) == 2
    assert "run1.csv" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow  # about 1 min
def test_cli_diagnose_takes_several_runs_and_keeps_them_apart(offset_data, tmp_path, capsys):
    folder, train, validation = offset_data
    runs = {}
    for name, record, cut in (("a", train, 1000), ("b", validation, 500)):
        for part, (lo, hi) in zip("12", ((0, cut), (cut, len(record)))):
            path = folder / f"{name}{part}.csv"
            save_trajectory(
                type(record)(
                    record.ts[lo:hi],
                    record.xs[lo:hi],
                    record.us[lo:hi],
                    record.state_names,
                    record.input_names,
                    "acrobot",
                ),
                path,
            )
            runs[name + part] = (path, hi - lo)
    out = tmp_path / "multi"
    code = cli_main(
        [
            "diagnose",
            "acrobot",
            str(runs["a1"][0]),
            str(runs["a2"][0]),
            "--validation",
            str(runs["b1"][0]),
            str(runs["b2"][0]),
            "--max-terms",
            "1",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert [p.rsplit("/", 1)[-1] for p in report["data"]["validation_runs"]] == ["b1.csv", "b2.csv"]
    assert report["data"]["n_train"] == runs["a1"][1] + runs["a2"][1]
    # No window crosses a run boundary: each run has as many windows as fit inside it alone.
    longest = int(round(max(report["nominal"]["sim_error"]["horizons_s"]) / 0.01))
    for row, key in zip(report["runs"], ("b1", "b2")):
        n = runs[key][1]
        assert row["run"].endswith(f"{key}.csv") and row["n_windows"] == len(range(0, n - longest, 5))
    assert report["horizon"]["rule"].startswith("predictability horizon")
    assert report["test"]["multiple_comparisons"].startswith("Benjamini-Hochberg")
    assert (out / "measured_vs_simulated_run2.png").stat().st_size > 0
    assert "b2.csv" in (out / "report.md").read_text()
    assert (report["findings"][0]["cause"], report["findings"][0]["where"]) == ("input_offset", "tau2")


@pytest.mark.slow  # about 30 s: another grid compiles the fits again
def test_cli_diagnose_on_irregularly_sampled_files_without_dt(offset_data, tmp_path, capsys):
    """Real rigs jitter (the DFKI files: 2 ms +- a few %). `diagnose` resamples them to their median interval;
    the report's figures must be drawn from the same grid, not fail on the user's unresampled records."""
    _, train, validation = offset_data
    rng = np.random.default_rng(1)
    paths = []
    for name, record in (("train", train), ("held", validation)):
        ts = np.asarray(record.ts) + rng.uniform(-0.002, 0.002, len(record)) * (np.arange(len(record)) > 0)
        path = tmp_path / f"{name}.csv"
        save_trajectory(type(record)(ts, record.xs, record.us, record.state_names, record.input_names, "acrobot"), path)
        paths.append(path)
    out = tmp_path / "diag"
    # A nominal file from `dynax identify --friction coulomb` carries fc1, fc2, which the two-link nominal
    # model cannot hold: set aside, and said so on stderr and in the report.
    nominal = tmp_path / "nominal.json"
    nominal.write_text(json.dumps({"parameters": {"fc2": 0.05}}))
    code = cli_main(
        [
            "diagnose",
            "acrobot",
            str(paths[0]),
            "--validation",
            str(paths[1]),
            "--max-terms",
            "1",
            "--nominal",
            str(nominal),
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    assert "fc2 = 0.05 (coulomb_friction at q2)" in err
    report = json.loads((out / "report.json").read_text())
    assert any("resampled" in n for n in report["notes"])
    assert any("fc2 = 0.05" in n and "set aside" in n for n in report["notes"])
    assert abs(report["data"]["dt"] - 0.01) < 1e-3
    for name in ("measured_vs_simulated.png", "sim_error.png", "residuals.png"):
        assert (out / name).stat().st_size > 0
    assert (report["findings"][0]["cause"], report["findings"][0]["where"]) == ("input_offset", "tau2")


def test_cli_nominal_sets_aside_term_coefficients_and_refuses_unknown_names():
    """`dynax identify` writes `Ir2` (its refinement's rotor inertia) and `fc1`, `fc2`; the nominal two-link
    model has no such terms. They are set aside with a note naming the cause; a name that is neither a field
    nor a term's coefficient is still refused."""
    from dynax import UsageError
    from dynax.internal import nominal_system, split_term_coefficients

    given = {"theta1": 0.05, "theta7": 0.02, "Ir2": 0.003, "fc1": 0.1}
    kept, note = split_term_coefficients("double_pendulum", given)
    assert kept == {"theta1": 0.05, "theta7": 0.02}
    assert "Ir2 = 0.003 (rotor_inertia at q2)" in note and "fc1 = 0.1 (coulomb_friction at q1)" in note
    assert float(nominal_system("double_pendulum", kept).theta7) == 0.02
    assert split_term_coefficients("linear_axis", {"mass": 90.0, "coulomb": 20.0}) == (
        {"mass": 90.0, "coulomb": 20.0},
        None,
    )
    kept, note = split_term_coefficients("acrobot", {"theta1": 1.0, "Ir9": 1.0})
    assert note is None
    with pytest.raises(UsageError, match="Ir9"):
        nominal_system("acrobot", kept)


@pytest.mark.slow  # about 35 s: its own record sizes compile the fits again
def test_cli_without_nominal_on_another_axis_diagnoses_against_its_identified_rigid_body(tmp_path, capsys):
    """An axis of another size than the default (EMPS: 95 kg, 203.5 N s/m): 5 kg, viscous 10 N s/m, Coulomb
    2 N, offset 0.3 N. Without `--nominal` the CLI sees least squares put the mass 19 times below the
    default's, diagnoses against the identified mass and offset with zero friction, and names both frictions
    with their sizes. (Against the EMPS defaults the refit must first find the mass from 19 times too large.)"""
    import jax.numpy as jnp

    from dynax import LinearAxis, Trajectory
    from dynax.synthetic import Multisine, synthetic_trajectory

    truth = LinearAxis(
        mass=jnp.asarray(5.0), viscous=jnp.asarray(10.0), coulomb=jnp.asarray(2.0), offset=jnp.asarray(0.3)
    )
    run = synthetic_trajectory(
        truth,
        duration=30.0,
        dt=0.01,
        seed=5,
        excitation=Multisine(amplitude=10.0),
        noise=(1e-5, 1e-3),
        system_name="linear_axis",
    )
    for name, (a, b) in (("train", (0, 2001)), ("held", (2001, len(run.ts)))):
        save_trajectory(
            Trajectory(run.ts[a:b], run.xs[a:b], run.us[a:b], run.state_names, run.input_names, "linear_axis"),
            tmp_path / f"{name}.csv",
        )
    out = tmp_path / "axis"
    code = cli_main(
        [
            "diagnose",
            "linear_axis",
            str(tmp_path / "train.csv"),
            "--validation",
            str(tmp_path / "held.csv"),
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    assert "not the default LinearAxis" in err and "mass" in err
    j = json.loads((out / "report.json").read_text())
    assert j["verdict"] == "explained"
    found = {f["cause"]: f["coefficient"] for f in j["findings"]}
    assert set(found) == {"viscous_friction", "coulomb_friction"}, j["findings"]
    assert abs(found["viscous_friction"] / 10.0 - 1) < 0.05 and abs(found["coulomb_friction"] / 2.0 - 1) < 0.05
    assert abs(j["extended"]["parameters"]["mass"] / 5.0 - 1) < 0.05


@pytest.mark.slow  # about 30 s: its own record sizes
@pytest.mark.xfail(
    strict=True,
    reason="with the single training run cross-fitted by blocks, the shoulder's viscous friction (refitted at "
    "0.0108 for 0.01, p = 4e-9, helping on 4 of 4 runs) gains 5.3 % on the held-out run but 4.0 % pooled, under "
    "min_gain (5 %), so it is not named and the elbow's viscous friction takes 0.0112 for 0.01",
)
def test_cli_without_nominal_on_a_small_acrobot_names_every_friction_with_its_size(tmp_path, capsys):
    """A 0.3 m acrobot (not Drake's 1 m one) with viscous friction 0.01 N m s at both joints and Coulomb
    friction 0.03 N m at the elbow, 30 s under a small multisine elbow torque (the shoulder swings 0.17 rad).
    Without `--nominal` the CLI diagnoses against the identified rigid body with zero friction, so the three
    frictions are the hidden effects. The third, viscous at the shoulder, is small (23 %); screening ranked
    its look-alike quadratic drag above it and left it off the shortlist, and quadratic drag was named with
    look-alikes 'told apart' although none had been refitted. The leader's look-alikes are now refitted too."""
    from dynax import CoulombFriction, Extended, Trajectory
    from dynax.synthetic import Multisine, synthetic_trajectory

    truth = Extended(
        Acrobot.from_physical(m1=0.5, m2=0.45, l1=0.3, lc1=0.15, lc2=0.16, Ic1=0.004, Ic2=0.0035, b1=0.01, b2=0.01),
        (CoulombFriction(1, 0.03),),
    )
    run = synthetic_trajectory(
        truth, duration=30.0, dt=0.01, excitation=Multisine(amplitude=0.15), seed=4, system_name="acrobot"
    )
    for name, (a, b) in (("train", (0, 2001)), ("held", (2001, len(run.ts)))):
        save_trajectory(
            Trajectory(run.ts[a:b], run.xs[a:b], run.us[a:b], run.state_names, run.input_names, "acrobot"),
            tmp_path / f"{name}.csv",
        )
    out = tmp_path / "small"
    code = cli_main(
        [
            "diagnose",
            "acrobot",
            str(tmp_path / "train.csv"),
            "--validation",
            str(tmp_path / "held.csv"),
            "--out",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    j = json.loads((out / "report.json").read_text())
    found = {(f["cause"], f["where"]): f for f in j["findings"]}
    assert set(found) == {("viscous_friction", "q1"), ("viscous_friction", "q2"), ("coulomb_friction", "q2")}, j[
        "findings"
    ]
    for (cause, where), size in {
        ("viscous_friction", "q1"): 0.01,
        ("viscous_friction", "q2"): 0.01,
        ("coulomb_friction", "q2"): 0.03,
    }.items():
        assert abs(found[(cause, where)]["coefficient"] / size - 1) < 0.1, found[(cause, where)]
    # Every finding was compared with each of its look-alikes that could be fitted.
    shoulder = found[("viscous_friction", "q1")]
    assert {a["cause"] for a in shoulder["look_alikes"]} >= {"quadratic_drag", "coulomb_friction"}


@pytest.mark.slow  # about 45 s: a diagnosis of its own
def test_a_nominal_model_of_another_machine_is_said_to_be_one(offset_data):
    """Every base parameter four times the demo's (a heavier arm whose accelerations under the same torque are a
    quarter): the refit of theta1..theta5 has to move them by about 4, and the report says that the nominal
    model describes another machine (the Python API's counterpart of the CLI's check without --nominal)."""
    _, train, validation = offset_data
    heavy = Acrobot.from_base_parameters({k: 4 * float(v) for k, v in Acrobot().base_parameters.items()})
    report = diagnose(heavy, train, validation, selection=Selection(max_terms=1, discovery=False))
    moved = [n for n in report.notes if n.startswith("The refit moved")]
    assert moved and "theta1 from 5.33" in moved[0] and "another machine" in moved[0], report.notes
    # The demo's own nominal is close to its truth: no such note (the offset test above diagnoses it).
    assert not any(
        n.startswith("The refit moved")
        for n in diagnose(Acrobot(), train, validation, selection=Selection(max_terms=1, discovery=False)).notes
    )
