"""A quadrotor diagnosed on a part of its vocabulary: a user's choice of candidates runs whatever it holds."""

import pytest

import dynax
from dynax.internal import body_frame_system, quadrotor_candidates

from .synthetic_flight import quadrotor_flight


@pytest.mark.slow  # two minutes of CPU: a crash of a path the default vocabulary never takes
def test_a_vocabulary_without_input_dynamics_is_diagnosed():
    # The held motor map is refitted through a lag or dead time when one is a candidate; with none (drag only)
    # that step has nothing to try (it divided its level by zero tries).
    train, test = [quadrotor_flight(4.0, seed=5)], [quadrotor_flight(4.0, seed=105)]
    quad = dynax.Quadrotor.from_flights("nominal", train)
    body = body_frame_system(quad, train[0].input_names)
    drag = tuple(t for t in quadrotor_candidates(body) if t.cause == "rotor_drag")
    report = dynax.diagnose(quad, train, test, candidates=drag, selection=dynax.Selection(max_terms=1, discovery=False))
    assert all(f.cause == "rotor_drag" for f in report.findings)
