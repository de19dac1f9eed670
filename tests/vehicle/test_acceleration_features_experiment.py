"""The acceleration-feature experiment runs end to end in --quick mode."""

import json
import math
import pathlib
import subprocess
import sys

import pytest

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "experiments" / "acceleration_features.py"


@pytest.mark.slow
def test_quick_feature_comparison(tmp_path):
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--out", str(tmp_path)], capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-3000:]
    hover = json.loads((tmp_path / "features.json").read_text())["results"]["hover"]
    assert set(hover) == {"rich", "full", "rich, g = 9.12", "rich + attitude", "linear"}
    assert hover["rich"]["n_weights"] == 38 and hover["full"]["n_weights"] == 72
    # Only the attitude variant learns attitude weights (the linear model's roll and pitch columns aside).
    assert set(hover["rich + attitude"]["attitude_weights"]) == {
        f"d{a}/{f}" for a in "uvwpqr" for f in ("roll", "pitch")
    }
    assert hover["rich"]["attitude_weights"] == {}
    for entry in hover.values():
        assert all(math.isfinite(v) and v >= 0 for v in entry["mse_1s"].values())
