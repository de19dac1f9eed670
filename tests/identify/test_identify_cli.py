"""`dynax identify` writes the contract's JSON, and refuses bad input with exit status 2 and no output."""

import json

import pytest

import dynax
from dynax.internal import cli_main


def test_identify_writes_the_contract_json(acrobot_csv, tmp_path, capsys):
    out = tmp_path / "params.json"
    assert cli_main(["identify", "acrobot", str(acrobot_csv), "--method", "power", "--out", str(out)]) == 0
    report = json.loads(out.read_text())
    contract = {"system", "method", "friction", "parameters", "std_errors", "condition_number", "n_samples"}
    assert contract <= set(report)  # the contract's keys, extended with the validation and consistency
    assert report["consistency"]["consistent"] and report["validation"]["horizons_s"] == [0.1, 0.25, 0.5]
    assert "held-out last 20%" in report["validation"]["source"]
    assert report["system"] == "acrobot" and report["method"] == "power" and report["friction"] == "viscous"
    assert list(report["parameters"]) == [f"theta{i}" for i in range(1, 8)]
    truth = dynax.Acrobot().base_parameters
    for name, value in report["parameters"].items():
        assert abs(value / float(truth[name]) - 1) < 0.02, name
    assert report["n_samples"] > 400 and report["condition_number"] > 1
    printed = capsys.readouterr().out
    assert "theta3" in printed and "open-loop RMSE" in printed


def test_identify_prints_each_validation_record_and_the_median_window(acrobot_csv, tmp_path, capsys):
    import jax.numpy as jnp
    import numpy as np

    from dynax import save_trajectory, Trajectory

    # two held-out records of the acrobot, one of them from another start and under another torque
    ts = np.arange(0.0, 4.0, 0.01)
    us = (1.5 * np.sin(2.1 * ts + 1.0))[:, None]
    sim = dynax.simulate(dynax.Acrobot(), jnp.array([-0.3, 0.2, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us))
    other = tmp_path / "other.csv"
    save_trajectory(Trajectory(jnp.asarray(ts), sim.xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",)), other)
    # and a second one (the training record itself would be refused: held-out error on it is in-sample)
    sim2 = dynax.simulate(dynax.Acrobot(), jnp.array([0.1, -0.2, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(-us))
    held = tmp_path / "held.csv"
    save_trajectory(Trajectory(jnp.asarray(ts), sim2.xs, jnp.asarray(-us), ("q1", "q2", "dq1", "dq2"), ("tau2",)), held)
    out = tmp_path / "params.json"
    assert (
        cli_main(
            [
                "identify",
                "acrobot",
                str(acrobot_csv),
                "--method",
                "power",
                "--validation",
                str(held),
                str(other),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    report = json.loads(out.read_text())
    assert list(report["validation"]["per_record"]) == ["held.csv", "other.csv"]
    assert len(report["validation"]["median"]) == 3 and report["validation"]["concentrated"] == {}
    printed = capsys.readouterr().out
    assert "(median window: " in printed
    for name, rmse in report["validation"]["per_record"].items():
        assert f"    {name}: 0.1 s: {rmse[0]:.4g}, 0.25 s: {rmse[1]:.4g}, 0.5 s: {rmse[2]:.4g}" in printed


def test_identify_warns_when_the_record_hardly_moves(tmp_path, capsys):
    import pytest

    from dynax import PoorlyDeterminedWarning, save_trajectory
    from tests.identify.test_identify_defaults import recorded, rig_model

    path = tmp_path / "still.csv"
    save_trajectory(recorded(rig_model(), 6.0, 3, torque_scale=0.05), path)  # 3 mrad of motion
    out = tmp_path / "params.json"
    with pytest.warns(PoorlyDeterminedWarning):
        assert (
            cli_main(
                ["identify", "double_pendulum", str(path), "--friction", "coulomb", "--refine", "no", "--out", str(out)]
            )
            == 0
        )
    report = json.loads(out.read_text())
    assert {"theta1", "theta2"} <= set(report["poorly_determined"])
    printed = capsys.readouterr().out
    assert "WARNING: the data determine these parameters poorly (relative standard error): theta1" in printed
    # the least-squares model is the answer here: the CLI says how its errors allow for the rows' correlation
    serial = report["stages"]["least_squares"]["serial_correlation"]
    assert serial["bandwidth_steps"] >= 1 and set(serial["inflation"]) == set(report["parameters"])
    assert "standard errors robust to the equations' correlation in time" in printed


def test_identify_refuses_bad_input_without_writing(acrobot_csv, tmp_path, capsys):
    out = tmp_path / "params.json"
    bad = tmp_path / "bad.csv"
    bad.write_text(acrobot_csv.read_text().replace("tau2", "torque"))
    assert cli_main(["identify", "acrobot", str(bad), "--out", str(out)]) == 2
    assert "tau2" in capsys.readouterr().err and not out.exists()
    # a method the system does not have
    assert cli_main(["identify", "linear_axis", str(acrobot_csv), "--method", "energy", "--out", str(out)]) == 2
    assert "not available" in capsys.readouterr().err and not out.exists()
    # a record that cannot determine the parameters: the arm never moves
    still = tmp_path / "still.csv"
    lines = acrobot_csv.read_text().splitlines()
    header, rows = lines[0], lines[1:40]
    still.write_text("\n".join([header] + [f"{0.01 * k},0,0,0,0,0" for k in range(len(rows))]) + "\n")
    assert cli_main(["identify", "acrobot", str(still), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "column 'q1', rows 1-39" in err and "never moves" in err and not out.exists()


def test_the_jointly_determined_note_gives_an_estimate_at_its_bound_as_value_and_error():
    # As printed for DFKI run 00 alone: theta1 is known to 39 %, while the shoulder's viscous
    # friction sits at its bound of zero (2e-6 +- 0.037), where a relative error (1.8e6 %) says nothing.
    from dynax.internal import jointly_determined_cell

    report = {"parameters": {"theta1": 0.0471, "theta6": 2.0e-6}, "std_errors": {"theta1": 0.018, "theta6": 0.037}}
    joint = {"with": ["Ir2", "theta2"], "correlations": [-0.99, 0.95], "inflation": 108.3}
    assert jointly_determined_cell("theta1", joint, report) == "theta1 (108x, +- 38 %) with Ir2 (-0.99), theta2 (+0.95)"
    cell = jointly_determined_cell("theta6", dict(joint, inflation=13.0), report)
    assert cell.startswith("theta6 (13x, 2e-06 +- 0.037) with")
    lone = jointly_determined_cell(
        "theta6", {"with": [], "correlations": [], "inflation": 13.0}, {"parameters": {"theta6": 0.0}, "std_errors": {}}
    )
    assert lone == "theta6 (13x) with several others"


@pytest.mark.slow  # about 45 s
def test_identify_says_that_one_record_cannot_show_what_changes_between_recordings(acrobot_csv, tmp_path, capsys):
    # Refined on one record, the answer's errors and validation come from within it. On the DFKI rig
    # such answers (run 03 or 12 alone) are determined to 2 to 12 % and 2 to 4 times the lab's error
    # on the runs whose motion they did not see (experiments/dfki_single_run.py): the CLI says so.
    out = tmp_path / "params.json"
    assert cli_main(["identify", "acrobot", str(acrobot_csv), "--refine", "yes", "--out", str(out)]) == 0
    report = json.loads(out.read_text())
    assert "output_error" in report["stages"] and report.get("record_std_errors") is None
    assert "NOTE: fitted on 1 record: the standard errors and the validation come from within the records" in (
        capsys.readouterr().out
    )
    # given a record of its own to validate on, the note is about the errors alone
    import jax.numpy as jnp
    import numpy as np

    ts = np.arange(0.0, 4.0, 0.01)
    us = (1.5 * np.sin(2.1 * ts + 1.0))[:, None]
    sim = dynax.simulate(dynax.Acrobot(), jnp.array([-0.3, 0.2, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us))
    held = tmp_path / "held.csv"
    dynax.save_trajectory(
        dynax.Trajectory(jnp.asarray(ts), sim.xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",)), held
    )
    assert (
        cli_main(
            ["identify", "acrobot", str(acrobot_csv), "--refine", "yes", "--validation", str(held), "--out", str(out)]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "NOTE: fitted on 1 record: the standard errors come from within the records" in printed
    assert "to --validation" not in printed
