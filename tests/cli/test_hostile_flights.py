"""Hostile flight logs (`tests/cli/hostile_flights.py`) through the console script's entry point.

Every case ends in a right answer, a located refusal (exit 2, one line naming the column and the row or
time, and the fix; nothing written) or a located note with a right answer: never a traceback, never exit
0 with a wrong answer, never advice that would make the data worse. The cases that read the NanoBench
flights are skipped where those files are absent; the two that fit a real flight are `heavy`.
"""

import pytest

from dynax.internal import cli_main as main
from tests.cli.hostile_cases import GOOD, run_case
from tests.cli.hostile_flights import CASES, make_fixtures, NEEDS_NANOBENCH, STAR


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    return make_fixtures(tmp_path_factory.mktemp("hostile_flights"), main)


def _params(cases):
    out = []
    for c in cases:
        marks = [pytest.mark.heavy] if c.heavy else []
        if c.id in NEEDS_NANOBENCH:
            marks.append(pytest.mark.skipif(not STAR.exists(), reason="the NanoBench flights are not here"))
        out.append(pytest.param(c, id=c.id, marks=marks))
    return out


@pytest.mark.parametrize("case", _params(CASES))
def test_hostile_flight_gets_a_right_answer_or_a_located_refusal(case, fixtures, tmp_path):
    outcome = run_case(case, tmp_path / "case", fixtures, main)
    assert outcome.verdict in GOOD, (
        f"{outcome.verdict}: exit {outcome.status}; expected {case.expect} with {case.needles}; stdout:\n"
        f"{outcome.stdout[-2000:]}\nstderr:\n{outcome.stderr[-3000:]}"
    )


def test_the_flight_corpus_covers_every_class_of_fault():
    kinds = {c.kind for c in CASES}
    assert {
        "glitch",
        "dropout",
        "time",
        "time_units",
        "quaternion",
        "frame",
        "units",
        "velocity",
        "motors",
        "ground",
        "duplicate",
        "file",
        "model",
        "args",
        "clean",
    } <= kinds
    assert len(CASES) >= 30 and len({c.id for c in CASES}) == len(CASES)
    assert {c.expect for c in CASES} == {"refuse", "warn", "accept"}
