"""The command line keeps compiled code between runs (JAX's persistent compilation cache), and the
cached run answers exactly as the first; `--no-cache` keeps nothing."""

import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


def _identify(csv, out, cache_dir, *extra):
    env = {k: v for k, v in os.environ.items() if k != "DYNAX_NO_CACHE"}
    env["DYNAX_CACHE_DIR"] = str(cache_dir)
    cmd = [
        sys.executable,
        "-m",
        "dynax",
        "identify",
        "acrobot",
        str(csv),
        "--method",
        "simulation",
        "--out",
        str(out),
        *extra,
    ]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(out.read_text())


def _cached_files(folder):
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


def test_second_run_reads_the_cache_and_answers_the_same(acrobot_csv, tmp_path):
    cache = tmp_path / "cache"
    first = _identify(acrobot_csv, tmp_path / "a.json", cache)
    entries = _cached_files(cache)
    assert entries, "the first run compiled but left nothing in the cache folder"
    second = _identify(acrobot_csv, tmp_path / "b.json", cache)
    assert second["parameters"] == first["parameters"]
    assert second["std_errors"] == first["std_errors"]


@pytest.mark.slow  # about 20 s
def test_no_cache_keeps_nothing(acrobot_csv, tmp_path):
    cache = tmp_path / "cache"
    _identify(acrobot_csv, tmp_path / "a.json", cache, "--no-cache")
    assert not _cached_files(cache)
