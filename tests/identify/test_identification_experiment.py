"""The identification experiment runs end to end in its quick mode and writes its figures and JSON."""

import json
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.mark.slow  # about 80 s: compiling every model for every sample count
def test_quick_experiment_writes_results_and_figures(tmp_path):
    subprocess.run(
        [sys.executable, str(REPO / "experiments" / "acrobot_identification.py"), "--quick", "--out", str(tmp_path)],
        check=True,
        cwd=REPO,
        env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
    )
    results = json.loads((tmp_path / "results.json").read_text())
    for name in ("study_noise_free.png", "study_noisy.png", "filter.png", "excitation.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    # noise-free data: every model within 0.5 % (median over theta1..theta5)
    assert all(v < 5e-3 for curve in results["noise_free"].values() for v in curve.values())
    # the excitation optimiser raised the information
    history = results["excitation"]["log_det_history"]
    assert history[-1][0] > history[0][0]
    # the output-error fit's standard errors are checked for calibration, with and without torque noise
    fit = results["simulation_fit"]
    for key in ("fraction_within_2_std_errors", "exact_torque_fraction_within_2_std_errors"):
        assert 0.0 <= fit[key] <= 1.0
    assert fit["standardised_error_rms"] > 0 and fit["exact_torque_standardised_error_rms"] > 0


@pytest.mark.slow  # about 1 to 4 minutes: one leave-one-run-out fold with the output-error refinement
def test_dfki_default_identification_experiment_writes_a_consistent_fold(tmp_path):
    subprocess.run(
        [
            sys.executable,
            str(REPO / "experiments" / "dfki_default_identification.py"),
            "--runs",
            "05",
            "--out",
            str(tmp_path),
        ],
        check=True,
        cwd=REPO,
        env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
    )
    results = json.loads((tmp_path / "results.json").read_text())
    fold = results["runs"]["05"]
    assert fold["consistency"]["consistent"] and fold["least_squares_consistency"]["consistent"]
    assert results["horizons_s"] == [0.1, 0.25, 0.5]
    # both models are simulated on the same held-out windows; the errors grow with the horizon
    for key in ("dynax", "dynax_least_squares", "lab_model_3.0"):
        assert 0 < fold[key][0] < fold[key][1] < fold[key][2]
    assert (tmp_path / "loro.png").stat().st_size > 10_000


@pytest.mark.slow  # about 30 s: one run identified alone, then simulated on the five others
def test_dfki_single_run_experiment_sets_one_runs_answer_against_the_lab_on_the_others(tmp_path):
    subprocess.run(
        [sys.executable, str(REPO / "experiments" / "dfki_single_run.py"), "--runs", "02", "--out", str(tmp_path)],
        check=True,
        cwd=REPO,
        env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
    )
    entry = json.loads((tmp_path / "single_run.json").read_text())["runs"]["02"]
    assert set(entry["other_runs_rmse"]) == {"00", "01", "03", "05", "12"} == set(entry["lab_other_runs_rmse"])
    for errors in entry["other_runs_rmse"].values():
        assert 0 < errors[0] < errors[1] < errors[2]
    assert entry["poorly_determined"] == {} and max(entry["relative_std_errors"].values()) < 0.25


def test_dfki_single_run_experiment_names_a_run_that_does_not_exist(tmp_path):
    done = subprocess.run(
        [sys.executable, str(REPO / "experiments" / "dfki_single_run.py"), "--runs", "02,99", "--out", str(tmp_path)],
        cwd=REPO,
        env={**__import__("os").environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "no DFKI run 99" in done.stderr
    assert not (tmp_path / "single_run.json").exists()


def test_loro_cell_tests_tell_a_worse_model_from_a_better_one():
    """The paired window test of the leave-one-run-out table (`cell_tests`) points the right way: the lab's
    model_h1.0 (an earlier fit) against its model_3.0 on DFKI run 03, whose windows show 1.3 to 1.8 times
    the error (geometric mean), is significantly worse, and the other way round significantly better."""
    pytest.importorskip("yaml")
    sys.path.insert(0, str(REPO / "experiments"))
    try:
        import dfki_default_identification as loro
        from dfki_simulation import read_parameters
    finally:
        sys.path.remove(str(REPO / "experiments"))
    good, bad = (loro.lab_model(read_parameters(name)) for name in ("model_3.0", "model_h1.0"))
    record = loro.load("03")
    worse = loro.cell_tests(bad, good, record, loro.HORIZONS)
    better = loro.cell_tests(good, bad, record, loro.HORIZONS)
    assert all(c["ratio"] > 1.2 and c["p_worse"] < 0.01 and c["p_better"] > 0.99 for c in worse), worse
    assert all(c["ratio"] < 1 / 1.2 and c["p_better"] < 0.01 and c["p_worse"] > 0.99 for c in better), better
