"""Model extensions compose with a nominal system, are neutral at rest values and act as documented."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import (
    Acrobot,
    CoulombFriction,
    DoublePendulum,
    Extended,
    InputDelay,
    InputGain,
    InputLag,
    InputOffset,
    JointSpring,
    QuadraticDrag,
    RotorInertia,
    simulate,
    ViscousFriction,
)

TS = jnp.arange(0.0, 2.0, 0.01)
US = (0.8 * jnp.sin(2.0 * TS) + 0.3 * jnp.sin(7.0 * TS))[:, None]
X0 = jnp.array([0.3, -0.2, 0.1, 0.0])


def _rollout(system, x0=X0, us=US):
    if isinstance(system, Extended):
        x0 = system.initial_state(x0, us[0])
    return simulate(system, x0, TS, us).xs[:, :4]


def test_neutral_terms_give_the_nominal_model():
    terms = (
        CoulombFriction(1),
        ViscousFriction(0),
        QuadraticDrag(1),
        RotorInertia(1),
        JointSpring(0),
        InputGain(0),
        InputOffset(0),
        InputLag(0),
        InputDelay(0),
    )
    extended = Extended(Acrobot(), terms)
    assert extended.state_names == ("q1", "q2", "dq1", "dq2", "tau2_lag", "tau2_delay1", "tau2_delay2")
    np.testing.assert_allclose(_rollout(extended), _rollout(Acrobot()), atol=1e-12)


@pytest.mark.parametrize(
    "term, force",
    [
        (CoulombFriction(1, 0.3), lambda q, dq: -0.3 * np.tanh(dq / 0.01)),
        (ViscousFriction(1, 0.2), lambda q, dq: -0.2 * dq),
        (QuadraticDrag(1, 0.1), lambda q, dq: -0.1 * abs(dq) * dq),
        (JointSpring(1, 2.0), lambda q, dq: -2.0 * q),
    ],
)
def test_joint_forces_enter_the_equations_of_motion(term, force):
    nominal = Acrobot()
    x = jnp.array([0.4, -0.7, 0.5, -1.3])
    u = jnp.array([0.6])
    ddq = Extended(nominal, (term,)).vector_field(0.0, x, u)[2:]
    M = nominal.mass_matrix(x[:2])
    rhs = nominal.input_matrix() @ u - nominal.bias_force(x[:2], x[2:]) + jnp.array([0.0, force(x[1], x[3])])
    np.testing.assert_allclose(ddq, jnp.linalg.solve(M, rhs), rtol=1e-10)


def test_rotor_inertia_adds_to_the_diagonal_of_the_mass_matrix():
    nominal = DoublePendulum()
    x = jnp.array([0.4, -0.7, 0.5, -1.3])
    u = jnp.array([0.2, 0.6])
    ddq = Extended(nominal, (RotorInertia(0, 0.05), RotorInertia(1, 0.02))).vector_field(0.0, x, u)[2:]
    M = nominal.mass_matrix(x[:2]) + jnp.diag(jnp.array([0.05, 0.02]))
    rhs = u - nominal.bias_force(x[:2], x[2:])
    np.testing.assert_allclose(ddq, jnp.linalg.solve(M, rhs), rtol=1e-10)


def test_rotor_inertia_is_the_calibration_generators_mass_matrix_law():
    # The calibration battery's truth writes its rotor out in numpy from the base parameters (`tests.hidden_cases`:
    # the inertia on M_jj alone, the coupling into M_12 of a motor carried on link 1 neglected, as `RotorInertia`
    # neglects it). Both must be one law, or a missed rotor would be a mismatch of laws, not of the data.
    from tests.hidden_cases import arm_rhs, Case, THETA

    rng = np.random.default_rng(5)
    theta = np.asarray(THETA) * (1 + rng.uniform(-0.03, 0.03, 7))
    base = {f"theta{i + 1}": v for i, v in enumerate(theta)}
    for arm, driven, where in ((Acrobot, (1,), "q2"), (DoublePendulum, (0, 1), "q2"), (DoublePendulum, (0, 1), "q1")):
        case = Case("rotor", "x", "rotor_inertia", where, 0.04, "mass matrix", "known", 0)
        truth, _ = arm_rhs(theta, case, driven)
        free, _ = arm_rhs(theta, Case("free", "x", None, None, 0.0, "none", "known", 0), driven)
        model = Extended(arm.from_base_parameters(base), (RotorInertia(int(where[1]) - 1, 0.04),))
        for _ in range(20):
            x, u = rng.uniform(-3, 3, 4), rng.uniform(-2, 2, len(driven))
            ours = np.asarray(model.vector_field(0.0, jnp.asarray(x), jnp.asarray(u)))
            np.testing.assert_allclose(ours, truth(x, u), rtol=1e-9, atol=1e-9)
            assert np.max(np.abs(truth(x, u) - free(x, u))) > 1e-4  # the rotor does act at this state


def test_input_gain_on_the_acrobot_equals_rescaled_base_parameters():
    # The reason an input gain is not identifiable when the base parameters are refitted.
    gain = 1.25
    scaled = Acrobot.from_base_parameters({k: v / gain for k, v in Acrobot().base_parameters.items()})
    np.testing.assert_allclose(_rollout(Extended(Acrobot(), (InputGain(0, gain),))), _rollout(scaled), atol=1e-10)


def test_input_offset_equals_shifted_recorded_input():
    np.testing.assert_allclose(
        _rollout(Extended(Acrobot(), (InputOffset(0, 0.2),))), _rollout(Acrobot(), us=US + 0.2), atol=1e-12
    )


def test_input_lag_step_response_is_first_order():
    tau = 0.05
    extended = Extended(Acrobot(), (InputLag(0, tau),))
    us = jnp.ones((TS.shape[0], 1))
    x0 = jnp.concatenate([X0, jnp.zeros(1)])  # lag output at rest at zero, then a unit step
    applied = simulate(extended, x0, TS, us).xs[:, 4]
    np.testing.assert_allclose(applied, 1 - np.exp(-np.asarray(TS) / tau), atol=1e-5)


def test_input_delay_delays_a_slow_sinusoid():
    delay, w = 0.04, 3.0
    extended = Extended(Acrobot(), (InputDelay(0, delay),))
    ts = jnp.arange(0.0, 4.0, 0.002)
    us = jnp.sin(w * ts)[:, None]
    xs = simulate(extended, extended.initial_state(X0, us[0]), ts, us).xs
    applied = jax.vmap(lambda x, u: extended.applied_input(u, x[4:])[0])(xs, us)[:, 0]
    late = ts > 1.0  # past the start transient
    np.testing.assert_allclose(applied[late], np.sin(w * (ts[late] - delay)), atol=2e-3)


def test_extensions_are_differentiable_in_their_coefficients():
    def final_angle(fc):
        extended = Extended(Acrobot(), (CoulombFriction(1, fc), InputLag(0, 0.03)))
        return _rollout(extended)[-1, 1]

    grad = jax.grad(final_angle)(0.2)
    fd = (final_angle(0.2 + 1e-6) - final_angle(0.2 - 1e-6)) / 2e-6
    np.testing.assert_allclose(grad, fd, rtol=1e-4)
    assert abs(grad) > 0


def test_report_names_and_labels():
    extended = Extended(Acrobot(), (CoulombFriction(1, 0.21), InputDelay(0, 0.03)))
    assert extended.labels == ("coulomb_friction@q2", "input_delay@tau2")
    assert set(extended.parameters) == {"fc2", "delay_tau2"}


def test_bad_compositions_are_refused_naming_the_problem():
    with pytest.raises(ValueError, match="joint=2"):
        Extended(Acrobot(), (CoulombFriction(2, 0.1),))
    with pytest.raises(ValueError, match="input=1"):
        Extended(Acrobot(), (InputGain(1, 2.0),))
    with pytest.raises(ValueError, match="twice"):
        Extended(Acrobot(), (CoulombFriction(1), CoulombFriction(1, 0.3)))
    with pytest.raises(ValueError, match="non-negative int"):
        CoulombFriction(-1)


def test_coulomb_friction_on_a_linear_axis_equals_its_own_coulomb_term():
    from dynax import LinearAxis

    axis = LinearAxis(coulomb=jnp.asarray(0.0), coulomb_velocity=0.01)
    reference = LinearAxis(coulomb=jnp.asarray(20.0), coulomb_velocity=0.01)
    extended = Extended(axis, (CoulombFriction(0, 20.0),))
    assert extended.labels == ("coulomb_friction@q",) and set(extended.parameters) == {"fc"}
    for x in (jnp.array([0.1, 0.05]), jnp.array([0.0, -0.003])):
        np.testing.assert_allclose(
            extended.vector_field(0.0, x, jnp.array([30.0])),
            reference.vector_field(0.0, x, jnp.array([30.0])),
            rtol=1e-12,
        )


def test_windowed_rollouts_shift_the_input_by_a_dead_time_of_any_size():
    # A linear axis under a 150 N multisine at 100 Hz, its input applied a dead time late, integrated by scipy's DOP853
    # restarted at every switch of the delayed input (`tests.hidden_cases.integrate`, not dynax). The windowed rollout
    # (one Tsit5 step per sample, with the input history) shifts the recorded input: whole samples exactly, a fraction
    # of one as the interval's mean, so a dead time shorter than a sample is followed as a dead time, closer than a
    # lag of the same size, where the Padé filter at this step is far off.
    from dynax import InputLag, LinearAxis
    from dynax.internal import window_rollout
    from tests.hidden_cases import axis_rhs, Case, integrate, multisine

    dt, n_before, n = 0.01, 50, 201
    ts = np.arange(n_before + n) * dt
    us = multisine(n_before + n, 1, 3, 150.0)
    free, _ = axis_rhs(Case("free", "linear_axis", None, None, 0.0, "none", "refit", 0))
    axis = LinearAxis(
        mass=jnp.asarray(95.1), viscous=jnp.asarray(200.0), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)
    )

    def rmse(term, xs, history=True):
        args = (jnp.asarray(ts[n_before:]), jnp.asarray(xs), jnp.asarray(us[n_before:]))
        if history:
            args += (jnp.asarray(ts[: n_before + 1]), jnp.asarray(us[: n_before + 1]))
        errors, _ = window_rollout(Extended(axis, (term,)), *args)
        return np.sqrt(np.mean(np.asarray(errors) ** 2, axis=0))  # (position, velocity)

    for delay in (0.005, 0.008, 0.01, 0.02):
        xs = integrate(free, np.zeros(2), ts, us, delay=delay, delayed=0)[n_before:]
        shifted, lag, none = rmse(InputDelay(0, delay), xs), rmse(InputLag(0, delay), xs), rmse(InputDelay(0), xs)
        assert np.all(shifted < 0.02 * none), (delay, shifted, none)
        assert shifted[1] < 0.6 * lag[1], (delay, shifted, lag)
        if delay in (0.01, 0.02):
            assert np.all(shifted < 1e-6), (delay, shifted)  # whole samples: the held input moved exactly
    xs = integrate(free, np.zeros(2), ts, us, delay=0.005, delayed=0)[n_before:]
    pade = np.nan_to_num(rmse(InputDelay(0, 0.005), xs, history=False), nan=np.inf)  # the ODE form: its Padé filter
    assert pade[1] > 10 * rmse(InputDelay(0, 0.005), xs)[1]


def test_the_dead_time_shift_agrees_with_the_residual_probes_interval_means():
    # Two implementations of one mean, written apart: the traced shift of the windowed rollouts
    # (`Extended.with_shifted_inputs`) and the host-side one of the one-step residuals (`exact_delays(interval=True)`),
    # on a record's inputs, a fraction of a sample and a sample and a half late.
    from dynax import Trajectory
    from dynax.internal import exact_delays

    ts = jnp.arange(300) * 0.01
    us = jnp.asarray(np.random.default_rng(4).normal(size=(300, 1)))
    run = Trajectory(ts, jnp.zeros((300, 4)), us, ("q1", "q2", "dq1", "dq2"), ("tau2",))
    for delay in (0.0037, 0.015):
        model = Extended(Acrobot(), (InputDelay(0, delay),))
        _, probe, _ = exact_delays(model, run, interval=True)
        _, shifted = model.with_shifted_inputs(us, 0.01)
        np.testing.assert_allclose(np.asarray(shifted)[5:], np.asarray(probe)[5:], atol=1e-12)
    # Two dead times on one input (a per-input one and the drives' shared one) act one after the other, as in the
    # rollouts; a lag before them changes nothing of the shifts.
    from dynax import DoublePendulum, MotorDelay

    us2 = jnp.asarray(np.random.default_rng(5).normal(size=(300, 2)))
    run2 = Trajectory(ts, jnp.zeros((300, 4)), us2, ("q1", "q2", "dq1", "dq2"), ("tau1", "tau2"))
    model = Extended(DoublePendulum(), (InputLag(0, 0.05), InputDelay(0, 0.0137), MotorDelay((0, 1), 0.021)))
    _, probe, _ = exact_delays(model, run2, interval=True)
    _, shifted = model.with_shifted_inputs(us2, 0.01)
    np.testing.assert_allclose(np.asarray(shifted)[6:], np.asarray(probe)[6:], atol=1e-12)
    # Whole samples compose exactly: 1 + 2 samples on tau1, 2 on tau2.
    model = Extended(DoublePendulum(), (InputDelay(0, 0.01), MotorDelay((0, 1), 0.02)))
    _, probe, _ = exact_delays(model, run2, interval=True)
    np.testing.assert_allclose(np.asarray(probe)[6:], np.stack([us2[3:-3, 0], us2[4:-2, 1]], axis=1), atol=1e-12)
