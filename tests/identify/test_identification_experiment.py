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
