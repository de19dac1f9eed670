"""The command line's contract: exit status 0 / 2 / 1, messages that name the problem, nothing written on refusal."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

import dynax
from dynax.internal import cli_main


@pytest.fixture
def acrobot_csv(tmp_path):
    ts = np.arange(0, 2.0, 0.01)
    us = np.sin(3 * ts)[:, None]
    sim = dynax.simulate(dynax.Acrobot(), np.array([0.3, 0.0, 0.0, 0.0]), ts, us)
    path = tmp_path / "run.csv"
    dynax.save_trajectory(
        dynax.Trajectory(ts, np.asarray(sim.xs), us, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot"), path
    )
    return path


def test_console_script_is_installed():
    exe = shutil.which("dynax") or str(__import__("pathlib").Path(sys.executable).with_name("dynax"))
    out = subprocess.run([exe, "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    for command in ("demo", "identify", "diagnose", "fit", "evaluate"):
        assert command in out.stdout


def test_bad_usage_exits_2(capsys):
    with pytest.raises(SystemExit) as e:
        cli_main(["identify"])
    assert e.value.code == 2
    with pytest.raises(SystemExit) as e:
        cli_main(["no-such-command"])
    assert e.value.code == 2


@pytest.mark.parametrize(
    "rewrite, message",
    [
        (lambda text: text.replace("dq2,", "dqX,", 1), "column 'dq2'"),
        (
            lambda text: "\n".join(
                l if i != 7 else l.replace(l.split(",")[1], "oops", 1) for i, l in enumerate(text.splitlines())
            ),
            "column 'q1', row 7: non-numeric",
        ),
        (
            lambda text: "\n".join(
                l if i != 9 else l.replace(l.split(",")[3], "nan", 1) for i, l in enumerate(text.splitlines())
            ),
            "column 'dq1', row 9: non-finite value nan",
        ),
        (
            lambda text: "\n".join(l if i != 5 else "0.0" + l[l.index(",") :] for i, l in enumerate(text.splitlines())),
            "column 't', row 5: time does not strictly increase",
        ),
    ],
    ids=["missing-column", "non-numeric", "non-finite", "time-order"],
)
def test_bad_file_exits_2_names_it_and_writes_nothing(acrobot_csv, tmp_path, capsys, rewrite, message):
    acrobot_csv.write_text(rewrite(acrobot_csv.read_text()))
    out = tmp_path / "out" / "params.json"
    code = cli_main(["identify", "acrobot", str(acrobot_csv), "--method", "power", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert str(acrobot_csv) in err and message in err
    assert not out.exists()


def test_bad_map_and_scale_exit_2(acrobot_csv, tmp_path, capsys):
    out = tmp_path / "params.json"
    assert cli_main(["identify", "acrobot", str(acrobot_csv), "--map", "q1", "--out", str(out)]) == 2
    assert "--map: 'q1' is not of the form NAME=VALUE" in capsys.readouterr().err
    assert cli_main(["identify", "acrobot", str(acrobot_csv), "--scale", "tau2=abc", "--out", str(out)]) == 2
    assert "not a number" in capsys.readouterr().err
    assert cli_main(["identify", "acrobot", str(acrobot_csv), "--map", "tau7=x", "--out", str(out)]) == 2
    assert "tau7" in capsys.readouterr().err
    assert not out.exists()


def test_identify_succeeds_with_mapping(acrobot_csv, tmp_path):
    renamed = tmp_path / "renamed.csv"
    renamed.write_text(acrobot_csv.read_text().replace("t,q1,q2,dq1,dq2,tau2", "time,a,b,c,d,volts", 1))
    out = tmp_path / "params.json"
    code = cli_main(
        [
            "identify",
            "acrobot",
            str(renamed),
            "--method",
            "power",
            "--out",
            str(out),
            "--map",
            "t=time,q1=a,q2=b,dq1=c,dq2=d,tau2=volts",
            "--scale",
            "tau2=1.0",
            "--offset",
            "tau2=0",
        ]
    )
    assert code == 0
    report = json.loads(out.read_text())
    assert report["system"] == "acrobot" and report["method"] == "power"
    assert set(report["parameters"]) >= {f"theta{i}" for i in range(1, 8)}
