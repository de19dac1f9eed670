"""What a user meets first: version, `python -m dynax`, help text, Ctrl-C, the installed metadata."""

import errno
import os
import pathlib
import re
import signal
import subprocess
import sys
import time
import tomllib

import pytest

import dynax
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


@pytest.mark.parametrize("argv, mode", [([], "auto"), (["--quiet"], "never"), (["--progress"], "always")])
@pytest.mark.parametrize("after", [False, True])
def test_quiet_and_progress_reach_the_sub_command(tmp_path, argv, mode, after):
    from dynax.internal import PROGRESS_MODE

    seen = []
    command = ["identify", "acrobot", "x.csv", "--out", str(tmp_path / "p.json")]
    assert cli_main(command + argv if after else argv + command, run=lambda args: seen.append(PROGRESS_MODE.get())) == 0
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


def test_a_real_sigint_exits_130(tmp_path):
    # `dynax identify` reads its record from a named pipe, so that it waits, mid-command, for data: a real Ctrl-C
    # then interrupts real work, and the command says so and exits 130.
    pipe = tmp_path / "run.csv"
    os.mkfifo(pipe)
    code = (
        "import signal, sys\n"
        # A terminal's Python has the KeyboardInterrupt handler; a child of a test worker may have inherited
        # SIGINT ignored (as background jobs of a shell do), and Python then installs no handler at all.
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "from dynax.internal import cli_main\n"
        f"sys.exit(cli_main(['identify', 'acrobot', {str(pipe)!r}, '--out', {str(tmp_path / 'p.json')!r}]))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    child = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env)
    try:
        while True:  # until the command opens the pipe to read its record
            try:
                writer = os.open(pipe, os.O_WRONLY | os.O_NONBLOCK)
                break
            except OSError as e:
                assert e.errno == errno.ENXIO and child.poll() is None, child.stderr.read() if child.stderr else e
                time.sleep(0.05)
        child.send_signal(signal.SIGINT)
        try:
            status = child.wait(timeout=30)
        except subprocess.TimeoutExpired:
            # The signal reached a thread JAX started while the main thread waits in `read`: the handler has
            # run, and the end of the record lets the main thread see it.
            os.close(writer)
            writer = None
            status = child.wait(timeout=120)
        if writer is not None:
            os.close(writer)
    finally:
        child.kill()
    assert status == 130 and "interrupted" in child.communicate()[1]
