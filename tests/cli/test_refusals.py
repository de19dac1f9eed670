"""Issue 13: every malformed input of `malformed_cases.CASES`, through the console script's entry point.

A refusal is exit status 2 with one line naming the problem and nothing written to `--out`; an
input that is unusual but valid (a byte-order mark, epoch time stamps, rounded quaternions) must
still give a correct answer. Nothing may exit 0 with a wrong answer, or escape as a traceback.
"""

import json
import os

import numpy as np
import pytest

from dynax.internal import cli_main, staged_directory, write_json
from tests.cli.malformed_cases import CASES, make_fixtures, run_case, run_simulate_case, simulate_cases, superuser


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    return make_fixtures(tmp_path_factory.mktemp("fixtures"))


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_malformed_input_is_refused_or_answered_correctly(case, fixtures, tmp_path):
    if case.needs_permissions and superuser():
        pytest.skip("file permissions do not bind the superuser")
    outcome = run_case(case, tmp_path / "case", fixtures, cli_main)
    assert outcome.verdict in ("refused correctly", "accepted correctly"), (
        f"{outcome.verdict}: exit {outcome.status}; expected message {case.message!r}; "
        f"stderr:\n{outcome.stderr[-3000:]}"
    )
    if case.expect == "refuse":
        # One clear line, never a traceback.
        assert "Traceback" not in outcome.stderr
        assert outcome.message.startswith("dynax ") and ": error: " in outcome.message
        assert "np." not in outcome.message  # numbers and names as the user wrote them, not numpy reprs


@pytest.mark.wrong_types
@pytest.mark.parametrize("case", simulate_cases(), ids=[c[0] for c in simulate_cases()])
def test_simulate_refuses_invalid_arguments(case):
    _, call, message = case
    assert run_simulate_case(call, message) == "refused correctly"


def test_report_folder_is_replaced_whole(tmp_path):
    out = tmp_path / "report"
    with staged_directory(out) as stage:
        (stage / "report.json").write_text("{}")
        (stage / "old_figure.png").write_bytes(b"png")
    with staged_directory(out) as stage:
        (stage / "report.json").write_text('{"new": 1}')
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]
    assert json.loads((out / "report.json").read_text()) == {"new": 1}
    mask = os.umask(0o022)
    os.umask(mask)
    assert (out.stat().st_mode & 0o777) == (0o777 & ~mask)
    # A failure inside leaves the previous report as it was, and no staging folder behind.
    with pytest.raises(RuntimeError), staged_directory(out) as stage:
        (stage / "report.json").write_text("half")
        raise RuntimeError("boom")
    assert json.loads((out / "report.json").read_text()) == {"new": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


def test_write_json_never_writes_a_non_finite_number_as_one(tmp_path, capsys):
    path = tmp_path / "m.json"
    write_json(path, {"mse": {"velocity": np.array([0.5, np.inf, np.nan])}, "gain": -np.inf})
    text = path.read_text()
    assert "1e+308" not in text and "Infinity" not in text and "NaN" not in text
    obj = json.loads(text)
    assert obj["mse"]["velocity"] == [0.5, None, None] and obj["gain"] is None
    assert obj["non_finite"] == {"/mse/velocity/1": "inf", "/mse/velocity/2": "nan", "/gain": "-inf"}
    assert "non-finite values written as null" in capsys.readouterr().err
    mask = os.umask(0o022)
    os.umask(mask)
    assert (path.stat().st_mode & 0o777) == (0o666 & ~mask)


@pytest.mark.parametrize(
    "argv",
    [
        ["diagnose", "acrobot", "{acrobot}", "--dt", "inf", "--out", "{out}"],
        ["diagnose", "acrobot", "{acrobot}", "--reference-horizon", "nan", "--out", "{out}"],
        ["identify", "acrobot", "{acrobot}", "--method", "simulation", "--segment", "inf", "--out", "{out}.json"],
    ],
    ids=["diagnose-dt-inf", "diagnose-reference-nan", "identify-segment-inf"],
)
def test_a_non_finite_number_of_seconds_is_refused_by_name(argv, fixtures, tmp_path, capsys):
    """`inf` passes a `> 0` check and `nan` fails none: each is refused naming its option, before any fit."""
    out = tmp_path / "out"
    argv = [a.format(acrobot=fixtures["acrobot"], out=out) for a in argv]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err
    assert argv[argv.index("--out") - 2] in err and "finite" in err
    assert not list(tmp_path.iterdir())
