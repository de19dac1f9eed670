"""What a user meets first: version, `python -m dynax`, help text, Ctrl-C, the installed metadata."""

import pathlib
import re
import subprocess
import sys
import tomllib

import pytest

import dynax
from dynax._cli import _identify  # private: `run` replaced: a Ctrl-C, a spy; no public route
from dynax.internal import build_parser, cli_main

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_version_has_one_source():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" in pyproject["project"]["dynamic"] and "version" not in pyproject["project"]
    assert pyproject["tool"]["hatch"]["version"]["path"] == "dynax/_version.py"
    assert re.fullmatch(r"\d+\.\d+\.\d+", dynax.__version__)
    assert f"## {dynax.__version__}" in (ROOT / "CHANGELOG.md").read_text()


def test_python_dash_m_dynax_prints_the_version():
    out = subprocess.run([sys.executable, "-m", "dynax", "--version"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"dynax {dynax.__version__}"


def test_help_starts_with_a_plain_description_and_has_no_literal_percent_signs(capsys):
    parser = build_parser()
    text = parser.format_help()
    first = text.split("\n\n")[1]
    assert first.startswith("dynax: differentiable dynamics") and "Exit status" not in first
    for name, sub in parser._subparsers._group_actions[0].choices.items():
        help_text = sub.format_help()
        assert "%%" not in help_text, name
        assert "--quiet" in help_text and "--progress" in help_text
    assert "last 30% of each training run" in " ".join(
        parser._subparsers._group_actions[0].choices["diagnose"].format_help().split()
    )


def test_ctrl_c_exits_130(monkeypatch, tmp_path, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(_identify, "run", interrupted)
    assert cli_main(["identify", "acrobot", "x.csv", "--out", str(tmp_path / "p.json")]) == 130
    assert "interrupted" in capsys.readouterr().err


@pytest.mark.parametrize("argv, mode", [([], "auto"), (["--quiet"], "never"), (["--progress"], "always")])
@pytest.mark.parametrize("after", [False, True])
def test_quiet_and_progress_reach_the_sub_command(monkeypatch, tmp_path, argv, mode, after):
    from dynax.internal import PROGRESS_MODE

    seen = []
    monkeypatch.setattr(_identify, "run", lambda args: seen.append(PROGRESS_MODE.get()) or 0)
    command = ["identify", "acrobot", "x.csv", "--out", str(tmp_path / "p.json")]
    assert cli_main(command + argv if after else argv + command) == 0
    assert seen == [mode]


def test_quiet_and_progress_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as e:
        cli_main(["--quiet", "--progress", "demo"])
    assert e.value.code == 2


def test_package_ships_license_types_and_changelog():
    assert "Apache License" in (ROOT / "LICENSE").read_text() and "Version 2.0" in (ROOT / "LICENSE").read_text()
    assert (ROOT / "dynax" / "py.typed").exists()
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["project"]["license"] == "Apache-2.0"
    assert any(c.startswith("Typing :: Typed") for c in pyproject["project"]["classifiers"])
    # the benchmark imports evosax.algorithms, which evosax has from 0.2.0 on
    assert "evosax>=0.2.0" in pyproject["project"]["optional-dependencies"]["bench"]


def test_importing_dynax_sets_no_matplotlib_backend_and_skips_heavy_modules():
    code = (
        "import sys, dynax; import matplotlib as m; "
        "print('pyplot' if 'matplotlib.pyplot' in sys.modules else '', "
        "'signal' if 'scipy.signal' in sys.modules else '', 'stats' if 'scipy.stats' in sys.modules else '', "
        "m.rcParams._get_backend_or_none() or 'unset')"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "MPLBACKEND": ""},
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["unset"]


def test_a_real_sigint_exits_130():
    code = (
        "import os, signal, sys, time\n"
        # A terminal's Python has the KeyboardInterrupt handler; a child of a test worker may have inherited
        # SIGINT ignored (as background jobs of a shell do), and Python then installs no handler at all.
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "from dynax._cli import _identify\n"
        "from dynax.internal import cli_main\n"
        # raise_signal delivers to the main thread, as a terminal's Ctrl-C reaches Python's handler; os.kill
        # may land on a thread JAX started (the compilation cache), and the sleep would then run out.
        "_identify.run = lambda args: (signal.raise_signal(signal.SIGINT), time.sleep(30))\n"
        "sys.exit(cli_main(['identify', 'acrobot', 'x.csv', '--out', 'p.json']))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 130 and "interrupted" in out.stderr
