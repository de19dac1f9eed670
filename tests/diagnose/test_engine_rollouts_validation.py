"""diagnose on the shared machinery: the one windowed rollout, the engine's batched refits, the validation
block (fit %, residual tests), the progress reporting, and the system protocol instead of class checks."""

import ast
import pathlib
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import (
    Adaptive,
    CoulombFriction,
    default_candidates,
    Extended,
    InputLag,
    InputOffset,
    LinearAxis,
    Trajectory,
)
from dynax.internal import (
    complete_state,
    Family,
    fit_configurations,
    fit_percent,
    make_windows,
    movable_parameters,
    progress_mode,
    residual_tests,
    rollouts_from_starts,
    stage_reporter,
    window_errors,
    window_rollouts,
)


def _axis_record(truth, *, seconds=12.0, dt=0.01, noise=1e-4, seed=0, name="run.csv"):
    """A linear axis under a multisine force, simulated with an adaptive solver (not the fixed grid the fits use)."""
    rng = np.random.default_rng(seed)
    ts = np.arange(0.0, seconds, dt)
    freqs = rng.uniform(0.2, 1.5, 6)
    us = (60.0 * np.sum(np.sin(2 * np.pi * freqs[None] * ts[:, None] + rng.uniform(0, 6.28, 6)), axis=1))[:, None]
    x0 = truth.initial_state(jnp.zeros(2), jnp.asarray(us[0])) if isinstance(truth, Extended) else jnp.zeros(2)
    sim = dynax.simulate(truth, x0, jnp.asarray(ts), jnp.asarray(us), method=Adaptive(rtol=1e-9, atol=1e-11))
    xs = np.asarray(sim.xs)[:, :2] + noise * rng.standard_normal((len(ts), 2))
    return Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), ("q", "dq"), ("force",), "linear_axis", name)


NOMINAL = LinearAxis(coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0))


def test_window_rollouts_agree_with_an_independent_integrator():
    record = _axis_record(NOMINAL, noise=0.0)
    errors, diverged = rollouts_from_starts(
        NOMINAL, record.ts, record.xs, record.us, jnp.asarray([0, 300, 700]), 100, dynax.FixedGrid()
    )
    assert not np.any(np.asarray(diverged))
    # the record itself was made by an adaptive solver at tight tolerances: the fixed grid reproduces it
    assert np.max(np.abs(np.asarray(errors))) < 1e-5
    assert np.max(np.abs(np.asarray(errors))) > 0  # and it is a different integrator, not the record echoed


def test_input_history_drives_a_lag_to_its_exact_state():
    """The lag's state at a window's start, integrated along the input history with `simulate`, against the
    exact solution of tau a' = u - a under the held input."""
    tau, dt = 0.07, 0.01
    model = Extended(NOMINAL, (InputLag(0, tau),))
    rng = np.random.default_rng(1)
    us = rng.normal(0.0, 30.0, (61, 1))
    ts = np.arange(61) * dt
    a = us[0, 0]
    for k in range(60):
        a = us[k, 0] + (a - us[k, 0]) * np.exp(-dt / tau)
    window_ts = ts[-1] + dt * np.arange(3)
    window_xs = np.zeros((3, 2))
    errors, _ = window_rollouts(
        model,
        jnp.asarray(window_ts)[None],
        jnp.asarray(window_xs)[None],
        jnp.asarray(np.repeat(us[-1:], 3, axis=0))[None],
        jnp.asarray(ts)[None],
        jnp.asarray(us)[None],
    )
    x0 = complete_state(model, jnp.zeros(2), jnp.asarray(us[-1]), jnp.asarray(ts), jnp.asarray(us))
    assert abs(float(x0[2]) - a) < 1e-6 * max(1.0, abs(a))
    # without history the lag would start at rest under the last input, a different state
    assert abs(float(model.initial_state(jnp.zeros(2), jnp.asarray(us[-1]))[2]) - a) > 1e-3
    assert np.all(np.isfinite(np.asarray(errors)))


def test_batched_engine_refits_recover_a_hidden_friction_and_converge():
    """One vmapped `fit_least_squares` over configurations: the configuration with the right candidate recovers
    its coefficient, the nominal-only configuration cannot, and the solver stops on its convergence test."""
    truth = Extended(NOMINAL, (CoulombFriction(0, 25.0, velocity_scale=0.01),))
    record = _axis_record(truth, noise=1e-5)
    candidates = (CoulombFriction(0, velocity_scale=0.01), InputOffset(0))
    system = NOMINAL
    windows = make_windows([record], 50, 50)
    family = Family(
        model=Extended(system, candidates),
        names=("mass", "viscous", "coulomb", "offset"),
        refit=jnp.asarray([1.0, 1.0, 0.0, 0.0]),
        nominal_scale=jnp.asarray([95.0, 200.0, 1.0, 1.0]),
        candidate_scale=jnp.asarray([10.0, 10.0]),
        candidate_init=jnp.asarray([0.0, 0.0]),
        neutral=jnp.asarray([0.0, 0.0]),
        state_scale=jnp.asarray(np.asarray(record.xs).std(axis=0)),
    )
    p0 = np.concatenate([[95.1089, 203.5034, 0.0, 0.0], [0.0, 0.0]])  # four nominal, one slot, the new term
    slots = -np.ones((3, 1), int)
    new = np.asarray([-1, 0, 1])
    p_init = np.tile(p0, (3, 1))
    p_init[1:, -1] = 1.0
    p, cost, std, steps = fit_configurations(
        family, windows, jnp.asarray(slots), jnp.asarray(new), jnp.asarray(p_init), jnp.ones(6)
    )
    p, cost, steps = np.asarray(p), np.asarray(cost), np.asarray(steps)
    assert abs(p[1, -1] - 25.0) < 1.0  # Coulomb friction found (truth 25 N)
    assert cost[1] < 0.05 * cost[0]  # and it explains what the nominal model cannot
    assert cost[1] < cost[2]  # better than the wrong candidate (an offset)
    assert np.all(steps < 32)  # converged, not stopped by the step budget
    assert np.all(np.asarray(std)[1, :2] > 0) and np.asarray(std)[1, 2] == 0  # frozen parameters have no error
    # The Jacobian is formed over what can move (the refitted mass and viscous friction, the slot, the new term):
    # differentiating every entry as well (the frozen ones give zero columns) fits the same, in the same steps.
    assert movable_parameters(family, 6) == (0, 1, 4, 5)
    every = fit_configurations(
        family, windows, jnp.asarray(slots), jnp.asarray(new), jnp.asarray(p_init), jnp.ones(6), movable=range(6)
    )
    np.testing.assert_allclose(np.asarray(every[0]), p, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(every[2]), np.asarray(std), rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(every[3]), steps)
    assert np.all(np.asarray(std)[:, 2:4] == 0)


def test_fit_percent_is_matlab_compare_and_residual_tests_tell_a_wrong_model():
    truth = Extended(NOMINAL, (CoulombFriction(0, 25.0, velocity_scale=0.01),))
    record = _axis_record(truth, seconds=30.0, noise=1e-4, seed=2)
    windows = make_windows([record], 40, 10)
    measured = np.asarray(windows.xs)[:, 40]
    fits = {}
    for name, model in (("nominal", NOMINAL), ("truth", truth)):
        errors = np.asarray(window_errors(model, windows))[:, 40]
        fits[name] = fit_percent(errors, measured, ("q", "dq"))
        reference = 100 * (1 - np.linalg.norm(errors[:, 1]) / np.linalg.norm(measured[:, 1] - measured[:, 1].mean()))
        assert np.isclose(fits[name]["dq"], reference)
    assert fits["truth"]["dq"] > 99.0 and fits["nominal"]["dq"] < fits["truth"]["dq"] - 2.0
    wrong, right = residual_tests(NOMINAL, record), residual_tests(truth, record)
    assert wrong.channels == ("dq",) and wrong.inputs == ("force",)
    assert not all(wrong.white) or not all(all(r) for r in wrong.independent)  # the missing friction shows
    assert all(right.white) and all(
        all(r) for r in right.independent
    )  # noise through the filter is white at its spacing
    assert 0 < right.autocorrelation_bound < 1 and right.lag_s == pytest.approx(0.11)


def test_stage_reporter_follows_progress_mode(capsys):
    lines = []
    with stage_reporter(lines.append) as say:
        say("a")
    assert lines == ["a"]
    with progress_mode("always"), stage_reporter(None) as say:
        say("stage one")
        say("stage two")
    err = capsys.readouterr().err
    assert "stage one" in err and "diagnose" in err and "2stage" in err.replace(" ", "")
    for mode in (
        "never",
        "auto",
    ):  # auto: stderr is not a terminal under pytest: no bar, and the library prints nothing
        with progress_mode(mode), stage_reporter(None) as say:
            say("hidden")
        assert capsys.readouterr().err == ""


def test_the_cli_stage_log_prints_lines_without_a_terminal_and_nothing_when_quiet(capsys):
    from dynax.internal import stage_log

    with stage_log() as say:
        say("screening")
    err = capsys.readouterr().err
    assert "screening" in err and "\r" not in err  # a log line, no bar
    with progress_mode("never"), stage_log() as say:
        say("screening")
    assert capsys.readouterr().err == ""


def test_candidates_come_from_the_system_protocol_not_its_class():
    """A manipulator dynax has never seen gets the joint vocabulary through `joints`; a system without joints or
    body axes gets only the input terms."""
    from dynax import DoublePendulum

    labels = [t.label(DoublePendulum()) for t in default_candidates(DoublePendulum())]
    assert "coulomb_friction@q1" in labels and "rotor_inertia@q2" in labels and "input_lag@tau1" in labels

    class Integrator(dynax.AbstractSystem):
        gain: jnp.ndarray
        state_names: ClassVar[tuple[str, ...]] = ("x",)
        input_names: ClassVar[tuple[str, ...]] = ("u",)

        def vector_field(self, t, x, u):
            return self.gain * u

    causes = {t.cause for t in default_candidates(Integrator(jnp.asarray(1.0)))}
    assert causes == {"input_delay", "input_lag", "input_gain", "input_offset"}


def test_no_class_checks_on_concrete_systems_outside_their_modules():
    """What differs per system is a method of the system: no generic layer (diagnosis, identification,
    the consistency check, the vehicle fits) tests for a concrete system or body-model class."""
    # where each class may be checked: its own module (and, for the body models' abstract base, the
    # vehicles that hold a body model and validate the field in their `__check_init__`)
    own = {
        "Helicopter": {"_helicopter.py"},
        "AccelerationModel": {"_helicopter.py"},
        "LinearVelocityModel": {"_helicopter.py"},
        "AbstractBodyModel": {"_helicopter.py", "_quadrotor.py"},
        "LinearAxis": {"_linear_axis.py"},
        "Acrobot": {"_two_link.py"},
        "DoublePendulum": {"_two_link.py"},
        "AbstractTwoLink": {"_two_link.py"},
        "AbstractManipulator": {"_system.py"},
    }
    package = pathlib.Path(dynax.__file__).parent
    found = []
    for path in package.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("isinstance", "issubclass"):
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                found += [
                    f"{path.relative_to(package)}:{node.lineno} {n}"
                    for n in names
                    if n in own and path.name not in own[n]
                ]
    assert found == []
