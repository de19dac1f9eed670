"""The output-error fit on the engine: names from the system's tree, one `Solution` behind the
result, and recovery from data made by another integrator with measurement noise."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import (
    Adaptive,
    CoulombFriction,
    Extended,
    fit_simulation_error,
    identify,
    Parameters,
    SimulationFit,
    Solution,
    Trajectory,
)


def _noisy_record(system, ts, us, x0, names, noise, seed):
    """Data from the adaptive Dopri8 integrator (the fit simulates with fixed Tsit5 steps), with
    white measurement noise on every state."""
    sim = dynax.simulate(system, jnp.asarray(x0), jnp.asarray(ts), jnp.asarray(us), method=Adaptive())
    rng = np.random.default_rng(seed)
    xs = np.asarray(sim.xs[:, : len(names)]) + noise * rng.standard_normal((len(ts), len(names)))
    return Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), names, system.input_names)


def _axis_problem(seed):
    """A linear axis (EMPS-sized) under a multisine force, measured with 1e-4 noise, and a start 15 to
    25 % off: `(record, start)`."""
    truth = dynax.LinearAxis(
        mass=jnp.asarray(95.0), viscous=jnp.asarray(200.0), coulomb=jnp.asarray(20.0), offset=jnp.asarray(-3.0)
    )
    ts = np.arange(0.0, 4.0, 0.002)
    us = (60 * np.sin(3 * ts) + 40 * np.sin(7.1 * ts) + 25 * np.sin(13.3 * ts))[:, None]
    data = _noisy_record(truth, ts, us, [0.0, 0.0], truth.state_names, noise=1e-4, seed=seed)
    start = dynax.LinearAxis(
        mass=jnp.asarray(80.0), viscous=jnp.asarray(240.0), coulomb=jnp.asarray(15.0), offset=jnp.asarray(0.0)
    )
    return data, start


@pytest.mark.slow  # one Levenberg-Marquardt compilation (about 30 s on 2 cores)
def test_linear_axis_named_by_tree_path_recovers_parameters_within_their_errors():
    data, start = _axis_problem(seed=0)
    result = fit_simulation_error(start, data, SimulationFit(segment_s=1.0, max_steps=40))
    assert result.names == ("mass", "viscous", "coulomb", "offset")  # the tree paths of the default filter
    assert isinstance(result, Solution)
    assert set(result.standard_errors()) == set(result.names)
    estimate, std = np.asarray(result.value), np.asarray(result.std_errors)
    expected = np.array([95.0, 200.0, 20.0, -3.0])
    np.testing.assert_allclose(estimate, expected, rtol=0.02, atol=0.1)
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    # The covariance ignores the smoothing of the Coulomb term and the integrator's own error, so
    # allow a generous multiple; a wrong estimate (or wrong errors) is typically far outside.
    assert np.all(np.abs(estimate - expected) < 10 * std + 1e-3 * np.abs(expected)), (estimate, std)


@pytest.mark.slow  # one Levenberg-Marquardt compilation (the tolerances travel in the solver)
def test_a_solver_given_replaces_the_engines():
    # The engine's Levenberg-Marquardt with tolerances a million times looser stops sooner, near the same minimum.
    from dynax.internal import levenberg_marquardt

    data, start = _axis_problem(seed=0)
    method = SimulationFit(segment_s=1.0, max_steps=40)
    default = fit_simulation_error(start, data, method)
    loose = levenberg_marquardt(rtol=1e-2, atol=1e-2, jacobian="accepted", damping="nielsen")
    stopped = fit_simulation_error(start, data, method, solver=loose)
    assert int(stopped.steps) < int(default.steps), (int(stopped.steps), int(default.steps))
    np.testing.assert_allclose(np.asarray(stopped.value), np.asarray(default.value), rtol=0.05)


class _WithSpare(dynax.AbstractSystem):
    """A linear axis with one more parameter that its dynamics never read."""

    axis: dynax.LinearAxis
    spare: jax.Array

    @property
    def state_names(self):
        return self.axis.state_names

    @property
    def input_names(self):
        return self.axis.input_names

    def vector_field(self, t, x, u):
        return self.axis.vector_field(t, x, u)


@pytest.mark.slow  # one Levenberg-Marquardt compilation
def test_a_parameter_the_rollouts_do_not_depend_on_gets_no_finite_error():
    # Its Jacobian column is zero: the data say nothing of it, and its error must say so (infinite),
    # not zero, which the clustered sandwich's pseudo-inverse put there; the axis' own parameters
    # keep the errors of the fit without it.
    data, start = _axis_problem(seed=0)
    spared = _WithSpare(start, jnp.asarray(1.0))
    # 0.25 s segments: 16 blocks of time, enough for the clustered covariance
    result = fit_simulation_error(spared, data, SimulationFit(segment_s=0.25, fit_initial_states=False, max_steps=40))
    alone = fit_simulation_error(start, data, SimulationFit(segment_s=0.25, fit_initial_states=False, max_steps=40))
    std = dict(zip(result.names, np.asarray(result.std_errors)))
    assert np.isinf(std["spare"]), std
    np.testing.assert_allclose(
        [std[f"axis.{n}"] for n in ("mass", "viscous", "coulomb", "offset")], np.asarray(alone.std_errors), rtol=1e-3
    )
    covariance = np.asarray(result.covariance)
    k = result.names.index("spare")
    assert np.all(np.isnan(covariance[k])) and np.all(np.isnan(covariance[:, k]))
    assert result.statistics.diverged_segments == result.statistics.initial_diverged_segments == 0


@pytest.mark.slow  # one Levenberg-Marquardt compilation
def test_identify_by_simulation_is_built_from_one_solution_with_the_contract_names():
    truth = Extended(dynax.Acrobot(), (CoulombFriction(0, jnp.asarray(0.05)), CoulombFriction(1, jnp.asarray(0.03))))
    ts = np.arange(0.0, 1.0 + 1e-9, 0.005)
    us = (2.0 * np.sin(0.7 * ts) + 1.5 * np.sin(1.9 * ts + 1) + np.sin(3.3 * ts + 2))[:, None]
    data = _noisy_record(truth, ts, us, [0.2, 0.0, 0.0, 0.0], ("q1", "q2", "dq1", "dq2"), noise=1e-5, seed=1)
    start = dynax.Acrobot.from_base_parameters({k: 1.05 * float(v) for k, v in dynax.Acrobot().base_parameters.items()})
    result = identify(
        start,
        data,
        SimulationFit(segment_s=0.25, max_steps=30),
        friction="coulomb",
        validation=dynax.Validate(holdout=0),
    )
    names = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7", "fc1", "fc2")
    assert result.names == names and result.solution.names == names
    out = result.to_json()
    assert tuple(out["parameters"]) == names and tuple(out["std_errors"]) == names
    assert out["parameters"] == result.solution.estimates() and out["std_errors"] == result.solution.standard_errors()
    np.testing.assert_array_equal(result.value, result.estimate)
    np.testing.assert_allclose(np.sqrt(np.diag(result.covariance)), result.std_errors, rtol=1e-10)
    theta = np.array([float(v) for v in dynax.Acrobot().base_parameters.values()] + [0.05, 0.03])
    np.testing.assert_allclose(np.asarray(result.estimate)[:7], theta[:7], rtol=1e-2)
    np.testing.assert_allclose(np.asarray(result.estimate)[7:], theta[7:], atol=0.01)


def test_named_parameters_pick_the_named_coefficients_of_nominal_system_and_terms():
    from dynax.internal import named_parameters

    system = Extended(dynax.Acrobot(), (CoulombFriction(1, jnp.asarray(0.3)), CoulombFriction(0, jnp.asarray(0.2))))
    names = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7", "fc2", "fc1")
    parameters = named_parameters(system, names)
    assert parameters.names == names  # tree order: the nominal fields, then the terms in their order
    values = dict(zip(parameters.names, np.asarray(parameters.vector(system))))
    assert values["fc2"] == pytest.approx(0.3) and values["fc1"] == pytest.approx(0.2)
    assert values["theta1"] == pytest.approx(float(system.system.theta1))
    moved = parameters.with_vector(system, jnp.arange(1.0, 10.0))
    assert float(moved.terms[0].coefficient) == 8.0 and float(moved.system.theta7) == 7.0
    axis = Parameters.of(dynax.LinearAxis())
    assert axis.names == ("mass", "viscous", "coulomb", "offset")
    fixed = named_parameters(dynax.LinearAxis(), ("mass", "viscous", "offset"))
    assert fixed.names == ("mass", "viscous", "offset")  # the Coulomb term is not fitted


def test_staggered_cuts_start_every_fraction_of_a_segment_and_link_only_the_first_cut():
    from dynax.internal import simulation_segments

    ts = np.arange(0.0, 1.0 + 1e-9, 0.01)  # 101 samples
    record = Trajectory(jnp.asarray(ts), jnp.asarray(ts[:, None]), jnp.zeros((len(ts), 1)), ("q",), ("u",))
    one = simulation_segments([record], 0.2)
    four = simulation_segments([record], 0.2, stagger=4)
    starts = lambda cut: sorted(np.round(cut[0][:, 0] / 0.01).astype(int))  # noqa: E731
    assert starts(one) == [0, 20, 40, 60, 80]
    # Segments of 21 samples starting every 5 samples, as long as they fit in the record.
    assert starts(four) == list(range(0, 81, 5))
    assert four[1].shape[1:] == (21, 1) and np.all(four[1][:, :, 0] == four[0])  # states follow their times
    assert one[5] == four[5] == 101 and np.all(four[4] == 0)  # the samples covered, counted once; one record
    # Only the first cut's segments continue one another (the continuity links of fitted states).
    assert list(four[3][:5]) == [False, True, True, True, True] and not np.any(four[3][5:])
    with pytest.raises(dynax.UsageError, match="stagger"):
        fit_simulation_error(dynax.LinearAxis(), record, SimulationFit(stagger=2))  # fitted initial states: refused
    with pytest.raises(dynax.UsageError, match="stagger"):
        fit_simulation_error(dynax.LinearAxis(), record, SimulationFit(stagger=0, fit_initial_states=False))


@pytest.mark.slow  # two Levenberg-Marquardt compilations
def test_staggered_cuts_keep_the_standard_errors_of_one_cut():
    """Four staggered cuts repeat each sample four times; their residuals are not independent, so the
    standard errors must stay near one cut's, not halve (as counting them as independent would)."""
    data, start = _axis_problem(seed=2)
    fits = [
        fit_simulation_error(
            start, data, SimulationFit(segment_s=0.5, fit_initial_states=False, max_steps=40, stagger=k)
        )
        for k in (1, 4)
    ]
    expected = np.array([95.0, 200.0, 20.0, -3.0])
    for fit in fits:
        np.testing.assert_allclose(np.asarray(fit.value), expected, rtol=0.02, atol=0.1)
    ratio = np.asarray(fits[1].std_errors) / np.asarray(fits[0].std_errors)
    # Counted as independent, four cuts would halve them (0.33 to 0.41 here); the cuts do add some
    # information (each sample is also fitted from other start states), 0.66 to 0.83 measured.
    assert np.all((ratio > 0.55) & (ratio < 1.2)), ratio
    # The residual's RMS is per sample, as with one cut.
    assert float(fits[1].statistics.residual_rms) == pytest.approx(float(fits[0].statistics.residual_rms), rel=0.3)
