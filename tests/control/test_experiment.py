"""The swing-up experiment runs end to end in --quick mode and writes the results the issue asks for."""

import json
import pathlib
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "experiments" / "acrobot_swingup.py"


def _run(tmp_path, *extra):
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--out", str(tmp_path), "--quick", *extra],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads((tmp_path / "results.json").read_text())


def _check_entry(entry, episode_s):
    assert set(entry["params"]) == {"k_e", "k_p", "k_d", "phi"}
    assert 0.0 <= entry["success_rate"] <= 1.0
    assert 0.0 <= entry["mean_time_s"] <= episode_s


@pytest.mark.slow  # about 40 s: the experiment script end to end
def test_quick_experiment_writes_results_and_figures(tmp_path):
    results = _run(tmp_path)
    episode_s = results["config"]["duration"]
    for name in ("drake_defaults", "pgpe_fixed_start", "pgpe_random_starts", "nelder_mead", "evosax_pgpe"):
        _check_entry(results[name], episode_s)
    assert results["drake_defaults"]["params"] == {"k_e": 5.0, "k_p": 50.0, "k_d": 5.0, "phi": 1000.0}
    for name in ("learning_fixed_start.png", "learning_random_starts.png", "baselines.png"):
        assert (tmp_path / name).stat().st_size > 10_000


@pytest.mark.slow
def test_quick_experiment_all_parts(tmp_path):
    results = _run(tmp_path, "--all")
    assert {"region_of_attraction", "soft_handover", "gradient_tuning", "pipeline"} <= set(results)
    pipeline = results["pipeline"]
    # The hidden torque gain is identified as base parameters divided by the gain.
    for name, value in pipeline["truth_base_parameters_over_gain"].items():
        assert abs(pipeline["identified"][name] - value) < 0.02 * abs(value) + 5e-3
