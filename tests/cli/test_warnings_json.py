"""The JSON every command writes carries the warnings and notes its run gave, under `warnings` (docs/cli.md).

A script that reads `parameters.json`, a model, metrics or `report.json` sees what the terminal said about
trusting the answer: each data check's finding with its file, column, rows and times, each Python warning the
work raised (its class as the kind), each of the command's own notes; an empty list when nothing was said.
The records are made apart from dynax's model code (`tests.reference`, via `tests/cli/hostile_cases.py`). The
flight commands' notes are held to the same rule by the hostile flight corpus, whose `warn` cases need the note
in the written JSON too (`hostile_cases.judge`).
"""

import json
import sys
import warnings

import numpy as np
import pytest

import dynax
from dynax.internal import cli_main, command_warnings
from tests.cli.hostile_cases import _arm, _multisine, _stamped_late, ACROBOT, PENDULUM, TRUTH, write_table

# --- the collector ------------------------------------------------------------------------------------


def _to_stderr(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def test_a_dynax_warning_is_kept_and_shown_once_even_where_python_filters_hide_it(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = _to_stderr  # as the console script shows them (pytest would record them instead)
        with command_warnings() as said:
            for _ in range(2):  # the same warning twice: shown once, as Python's "default" shows it, kept once
                warnings.warn("the records disagree", dynax.DataWarning, stacklevel=1)
            warnings.warn("something else", UserWarning, stacklevel=1)
        assert [(e["kind"], e["message"]) for e in said.to_json()] == [
            ("DataWarning", "the records disagree"),
            ("UserWarning", "something else"),
        ]
        assert capsys.readouterr().err.count("DataWarning: the records disagree") == 1
        warnings.simplefilter("ignore")  # a script that silences the terminal
        with command_warnings() as said:
            warnings.warn("the records disagree", dynax.DataWarning, stacklevel=1)
            warnings.warn("not dynax's", UserWarning, stacklevel=1)
        assert [e["kind"] for e in said.to_json()] == ["DataWarning"]  # dynax's own kept; the rest as filtered
        assert capsys.readouterr().err == ""


# --- identify ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    root = tmp_path_factory.mktemp("warnings_json")
    theta = list(TRUTH.values())
    ts, xs, taus = _arm(theta, 8.0, 100.0, lambda t, elbow=_multisine(0): (0.0, elbow(t)))
    acrobot = np.column_stack([ts, xs, taus[:, 1]])
    shoulder, elbow = _multisine(1, 2.0), _multisine(2)
    ts, xs, taus = _arm(theta, 8.0, 100.0, lambda t: (shoulder(t), elbow(t)))
    pendulum = np.column_stack([ts, xs, taus])
    pendulum[400:, 6] *= 0.5  # the elbow's torque logged at half its size from 4 s on (a unit changed)
    return {
        "clean": write_table(root / "clean.csv", ACROBOT, acrobot),
        "late": write_table(root / "late.csv", ACROBOT, _stamped_late((150, 320, 480, 650))(acrobot.copy())),
        "halved": write_table(root / "halved.csv", PENDULUM, pendulum),
    }


def _identify(path, tmp_path, *extra, system="acrobot", method="power"):
    out = tmp_path / "parameters.json"
    argv = ["identify", system, str(path), "--method", method, "--refine", "no", *extra, "--out", str(out)]
    assert cli_main(argv) == 0
    return json.loads(out.read_text())


@pytest.mark.heavy
def test_identify_on_a_clean_record_writes_an_empty_list(records, tmp_path):
    assert _identify(records["clean"], tmp_path)["warnings"] == []


@pytest.mark.heavy
def test_identify_writes_the_data_checks_warning_with_its_location_and_the_exclude_note(records, tmp_path, capsys):
    written = _identify(records["late"], tmp_path, "--exclude", "7.5:")["warnings"]
    err = capsys.readouterr().err
    stamps = [w for w in written if w["kind"] == "stamps"]
    assert len(stamps) == 1 and stamps[0]["category"] == "data"
    assert (stamps[0]["file"], stamps[0]["column"], stamps[0]["rows"]) == (records["late"], "t", [151, 651])
    assert stamps[0]["t0"] == pytest.approx(1.507) and stamps[0]["t1"] == pytest.approx(6.507)
    assert f"warning: {stamps[0]['message']}" in err  # the same words as on the terminal
    excluded = [w for w in written if w["kind"] == "exclude"]
    assert len(excluded) == 1 and excluded[0]["file"] == records["late"] and excluded[0]["message"] in err


@pytest.mark.heavy
def test_identify_writes_the_partway_torque_scale_warning_with_its_stretch(records, tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = _to_stderr  # as the console script shows them
        written = _identify(records["halved"], tmp_path, system="double_pendulum", method="dynamic")["warnings"]
    scaled = [w for w in written if "looks scaled by" in w["message"]]
    assert len(scaled) == 1, written
    w = scaled[0]
    assert w["kind"] == w["category"] == "InconsistentEstimateWarning"
    assert (w["file"], w["column"]) == ("halved.csv", "tau2")  # the record's label, as the message names it
    assert 3.9 <= w["t0"] <= 4.1 and "t1" not in w  # from about 4 s to the record's end: no end of its own
    assert f"--exclude halved.csv@{w['t0']:.6g}:" in w["fix"]
    assert "InconsistentEstimateWarning: " + w["message"] in capsys.readouterr().err  # still on stderr, once


# --- fit and evaluate (helicopter) --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def hover(tmp_path_factory):
    from dynax.synthetic import generate_helicopter_flight

    path = tmp_path_factory.mktemp("hover") / "hover.csv"
    dynax.save_trajectory(generate_helicopter_flight("hover", 6.0, seed=3, truth=dynax.Helicopter()), path)
    return path


def test_fit_and_evaluate_of_a_clean_flight_write_empty_lists_and_evaluate_keeps_a_resampling_note(hover, tmp_path):
    model, metrics = tmp_path / "model.json", tmp_path / "metrics.json"
    assert cli_main(["fit", "helicopter", str(hover), "--out", str(model)]) == 0
    assert json.loads(model.read_text())["warnings"] == []
    argv = ["evaluate", str(model), str(hover), "--horizons", "0.1,0.5", "--stride", "10", "--out", str(metrics)]
    assert cli_main(argv) == 0
    assert json.loads(metrics.read_text())["warnings"] == []
    # the same flight with jittered stamps: resampled, and the note says so in the JSON as on the terminal
    lines = hover.read_text().splitlines()
    rng = np.random.default_rng(0)
    jittered = [lines[0]]
    for k, line in enumerate(lines[1:]):
        t, rest = line.split(",", 1)
        jittered.append(f"{float(t) + (rng.uniform(-2e-4, 2e-4) if 0 < k < len(lines) - 2 else 0.0):.9f},{rest}")
    path = tmp_path / "jittered.csv"
    path.write_text("\n".join(jittered) + "\n")
    argv = ["evaluate", str(model), str(path), "--horizons", "0.1", "--stride", "10", "--out", str(metrics)]
    assert cli_main(argv) == 0
    written = json.loads(metrics.read_text())["warnings"]
    assert [(w["kind"], w["file"]) for w in written] == [("resampled", str(path))]


# --- diagnose ------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_diagnose_writes_its_warnings_into_report_json(records, tmp_path, capsys):
    nominal = tmp_path / "nominal.json"
    nominal.write_text(json.dumps({"parameters": TRUTH}))
    out = tmp_path / "report"
    argv = ["diagnose", "acrobot", records["late"], "--nominal", str(nominal), "--mode", "known", "--exclude", "7.5:"]
    argv += ["--max-terms", "1", "--no-discovery", "--no-cross-fit", "--out", str(out)]
    assert cli_main(argv) == 0
    written = json.loads((out / "report.json").read_text())["warnings"]
    kinds = {w["kind"]: w for w in written}
    assert {"stamps", "exclude"} <= set(kinds)
    assert (kinds["stamps"]["column"], kinds["stamps"]["rows"]) == ("t", [151, 651])
