"""`simulate` against scipy, gradients against finite differences, vmap, energy, divergence."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from tests.helpers import assert_jvp_matches_finite_differences, random_tangent
from tests.reference import DRAKE, scipy_acrobot

TS = jnp.linspace(0.0, 5.0, 501)  # 5 s at 100 Hz
US = (2.0 * jnp.sin(2.0 * TS) + jnp.where(TS > 2.5, 1.0, 0.0))[:, None]  # includes a jump
X0 = jnp.array([1.0, 0.5, 0.0, 0.0])


def scipy_reference(x0, ts, us):
    """Drake's acrobot by DOP853 at rtol 1e-11 (numpy equations), restarted at each sample (zero-order hold)."""
    return scipy_acrobot(x0, ts, us, DRAKE)


@pytest.fixture(scope="module")
def reference():
    return scipy_reference(X0, TS, US)


@pytest.mark.parametrize("method", [dynax.FixedGrid(), dynax.Adaptive()], ids=["fixed_grid", "adaptive"])
def test_matches_scipy_dop853(method, reference):
    xs = dynax.simulate(dynax.Acrobot(), X0, TS, US, method=method).xs
    assert np.max(np.abs(np.asarray(xs[:, :2]) - reference[:, :2])) < 1e-5  # the bound, rad
    assert np.max(np.abs(np.asarray(xs) - reference)) < 1e-6  # in fact far tighter


def test_default_is_two_tsit5_steps_per_sample_restarted_at_each_sample():
    """What a call without `method` computes, against a per-interval `diffeqsolve` written out here:
    Tsit5 with two constant steps on each zero-order-hold interval (the documented default)."""
    ts, us = TS[:101], US[:101]
    system = dynax.Acrobot()
    term = diffrax.ODETerm(lambda t, x, u: system.vector_field(t, x, u))

    @jax.jit
    def interval(x, t0, t1, u):
        sol = diffrax.diffeqsolve(
            term, diffrax.Tsit5(), t0, t1, (t1 - t0) / 2, x, args=u, stepsize_controller=diffrax.ConstantStepSize()
        )
        return sol.ys[-1]

    x, reference = X0, [X0]
    for k in range(len(ts) - 1):
        x = interval(x, ts[k], ts[k + 1], us[k])
        reference.append(x)
    reference = np.asarray(jnp.stack(reference))
    default = np.asarray(dynax.simulate(system, X0, ts, us).xs)
    np.testing.assert_allclose(default, reference, rtol=0, atol=1e-12)  # the same arithmetic, up to rounding
    # and it is told apart from the other choices: one step per sample, or the adaptive Dopri8 (which
    # both agree with the default only to their truncation error, ~1e-9 and more)
    for other in (dynax.FixedGrid(substeps=1), dynax.Adaptive()):
        assert np.max(np.abs(np.asarray(dynax.simulate(system, X0, ts, us, method=other).xs) - default)) > 1e-11


def test_irregular_sampling(reference):
    rng = np.random.default_rng(0)
    ts = np.cumsum(np.r_[0.0, rng.uniform(0.005, 0.015, 200)])
    us = np.sin(ts)[:, None]
    xs = dynax.simulate(dynax.Acrobot(), X0, ts, us).xs
    np.testing.assert_allclose(xs, scipy_reference(X0, ts, us), atol=1e-7)


def test_gradients_match_finite_differences(key):
    """Forward-mode derivatives of a rollout with respect to every parameter and the initial state,
    along a random direction, against central differences; reverse mode against forward mode below."""
    ts, us = TS[:101], US[:101]
    params, static = eqx.partition(dynax.Acrobot(), eqx.is_inexact_array)

    @jax.jit
    def final(params, x0):
        return dynax.simulate(eqx.combine(params, static), x0, ts, us).xs[-1]

    tangents = random_tangent(key, (params, X0))
    # central differences at h ~ 6e-6 have a truncation error ~ h^2 times the third derivative:
    # about 1e-9 relative here, far inside the tolerance
    assert_jvp_matches_finite_differences(final, (params, X0), tangents, rtol=1e-6, atol=1e-8)


def test_forward_mode_matches_reverse_mode():
    ts, us = TS[:101], US[:101]

    def final(theta3):
        return dynax.simulate(dynax.Acrobot(theta3=theta3), X0, ts, us).xs[-1]

    theta3 = jnp.asarray(1.0)
    forward = jax.jacfwd(final)(theta3)  # what Levenberg-Marquardt uses
    reverse = jax.jacrev(final)(theta3)
    np.testing.assert_allclose(forward, reverse, rtol=1e-8, atol=1e-10)


def test_vmap_equals_loop():
    x0s = jnp.stack([X0, X0 * 0.5, -X0, jnp.array([0.1, -0.1, 0.0, 0.02])])
    run = jax.jit(jax.vmap(lambda x0: dynax.simulate(dynax.Acrobot(), x0, TS[:201], US[:201]).xs))
    batched = run(x0s)
    single = jax.jit(lambda x0: dynax.simulate(dynax.Acrobot(), x0, TS[:201], US[:201]).xs)
    for i in range(4):
        np.testing.assert_allclose(batched[i], single(x0s[i]), atol=1e-12)


def test_vmap_over_parameters():
    systems = jax.vmap(lambda t5: dynax.Acrobot(theta5=t5))(jnp.array([9.0, 9.81, 11.0]))
    xs = jax.vmap(lambda s: dynax.simulate(s, X0, TS[:101], US[:101]).xs)(systems)
    assert xs.shape == (3, 101, 4)
    assert not np.allclose(xs[0], xs[2])


def test_undamped_unforced_acrobot_conserves_energy():
    system = dynax.Acrobot(theta6=jnp.asarray(0.0), theta7=jnp.asarray(0.0))
    ts = jnp.linspace(0.0, 10.0, 1001)
    x0 = jnp.array([2.0, -1.0, 0.5, 1.0])
    for method, tol in ((dynax.FixedGrid(), 1e-6), (dynax.Adaptive(), 1e-9)):
        energy = jax.vmap(system.energy)(dynax.simulate(system, x0, ts, method=method).xs)
        # Tsit5 at 2 x 100 Hz: local error O(h^5) gives ~4e-8 relative drift over 10 s of vigorous motion.
        assert float(jnp.max(jnp.abs(energy - energy[0]))) < tol * float(jnp.abs(energy[0]))


def test_divergence_is_reported_not_silent():
    unstable = dynax.LinearAxis(viscous=jnp.asarray(-5000.0), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0))
    ts = jnp.linspace(0.0, 1.0, 101)
    sim = dynax.simulate(unstable, jnp.array([0.0, 1.0]), ts, throw=False)
    assert bool(sim.diverged)
    k = int(jnp.searchsorted(ts, sim.diverged_at))
    assert 0.1 < float(sim.diverged_at) < 1.0
    assert np.all(np.isfinite(sim.xs[:k])) and np.all(np.isnan(sim.xs[k:]))
    with pytest.raises(Exception, match="rollout diverged"):
        dynax.simulate(unstable, jnp.array([0.0, 1.0]), ts).xs.block_until_ready()
    ok = dynax.simulate(dynax.LinearAxis(), jnp.array([0.0, 0.0]), ts)
    assert not bool(ok.diverged) and float(ok.diverged_at) == np.inf


def test_gradient_through_a_divergent_rollout_stays_finite():
    # The carried state is frozen at divergence and only the outputs are NaN, so the gradient of a
    # loss over the finite rows never meets an inf or NaN state (a population member that blows up
    # must not poison the population's gradient). Unfrozen, this float32 state would overflow to
    # inf after about 1.7 s.
    ts = jnp.linspace(0.0, 4.0, 401, dtype=jnp.float32)

    def loss(viscous):
        axis = dynax.LinearAxis(viscous=viscous, coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0))
        xs = dynax.simulate(axis, jnp.array([0.0, 1.0], jnp.float32), ts, throw=False).xs
        return jnp.sum(jnp.where(jnp.isnan(xs), 0.0, xs) ** 2)

    sim = dynax.simulate(
        dynax.LinearAxis(viscous=jnp.asarray(-5000.0), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)),
        jnp.array([0.0, 1.0]),
        ts,
        throw=False,
    )
    assert bool(sim.diverged) and float(sim.diverged_at) < 1.0
    gradient = jax.grad(loss)(jnp.asarray(-5000.0))
    assert np.isfinite(float(gradient)) and float(gradient) != 0.0


def test_invalid_member_of_a_population_is_flagged_not_simulated():
    # Under vmap the values cannot be refused up front: an invalid member comes back all NaN with
    # diverged_at = -inf (told apart from a divergence), and the others are untouched.
    axis = dynax.LinearAxis(coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0))
    ts = jnp.linspace(0.0, 0.5, 51)
    x0s = jnp.array([[0.0, 1.0], [jnp.nan, 0.0], [0.0, 2.0]])
    sims = jax.jit(jax.vmap(lambda x0: dynax.simulate(axis, x0, ts, throw=False)))(x0s)
    assert float(sims.diverged_at[1]) == -np.inf and bool(sims.diverged[1]) and np.all(np.isnan(sims.xs[1]))
    alone = dynax.simulate(axis, x0s[2], ts)
    np.testing.assert_allclose(sims.xs[2], alone.xs, rtol=1e-12, atol=1e-15)  # jit vs eager rounding
    assert not bool(sims.diverged[0]) and not bool(sims.diverged[2])
    with pytest.raises(Exception, match="non-finite input"):
        jax.jit(jax.vmap(lambda x0: dynax.simulate(axis, x0, ts).xs))(x0s).block_until_ready()


def test_float32_is_respected():
    xs = dynax.simulate(dynax.Acrobot(), X0.astype(jnp.float32), TS.astype(jnp.float32), US.astype(jnp.float32)).xs
    assert xs.dtype == jnp.float32


@pytest.mark.wrong_types
def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="`us` must have shape \\(time, 1\\)"):
        dynax.simulate(dynax.Acrobot(), X0, TS, jnp.zeros((501, 2)))
    with pytest.raises(ValueError, match="`x0` has 2 entries"):
        dynax.simulate(dynax.Acrobot(), X0[:2], TS, US)
    with pytest.raises(ValueError, match="`ts` must be a 1-d array"):
        dynax.simulate(dynax.Acrobot(), X0, TS[:1], US[:1])
    with pytest.raises(ValueError, match="`method`"):
        dynax.simulate(dynax.Acrobot(), X0, TS, US, method=diffrax.Tsit5())


def test_simulation_error_starts_internal_states_at_rest():
    """An input-lag model predicting its own data has no error: its lag state starts at rest, not at zero."""
    ts = jnp.arange(0.0, 4.0, 0.01)
    us = (1.0 + 0.5 * jnp.sin(3.0 * ts))[:, None]
    model = dynax.Extended(dynax.Acrobot(), (dynax.InputLag(0, 0.1),))
    x0 = model.initial_state(jnp.array([0.2, 0.0, 0.0, 0.0]), us[0])
    xs = dynax.simulate(model, x0, ts, us).xs
    data = dynax.Trajectory(ts, xs[:, :4], us, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot")
    error = dynax.simulation_error(model, data, (0.5, 1.0), stride=37)
    # At rest: 0.004 rad (the lag state is not exactly at rest at each window start); started at
    # zero it would be 0.047 rad, worse than the nominal model without any lag (0.027 rad).
    assert float(jnp.max(error.rmse)) < 5e-3
    zero_start = dynax.simulation_error(dynax.Acrobot(), data, (0.5, 1.0), stride=37)
    assert float(jnp.max(error.rmse)) < 0.2 * float(jnp.max(zero_start.rmse))


def test_window_simulation_errors_are_simulation_errors_errors():
    """`window_simulation_errors` (what `diagnose` reads its horizons from) is `simulation_error(...).errors` bit for
    bit: the same windows, the same compiled rollouts, the summaries left out."""
    from dynax.internal import window_simulation_errors

    ts = jnp.arange(0.0, 3.0, 0.01)
    us = (0.8 * jnp.sin(2.0 * ts) + 0.3 * jnp.sin(7.0 * ts))[:, None]
    xs = dynax.simulate(dynax.Acrobot(), jnp.array([0.3, -0.2, 0.0, 0.5]), ts, us).xs
    noisy = xs + 1e-3 * jax.random.normal(jax.random.PRNGKey(0), xs.shape)
    data = dynax.Trajectory(ts, noisy, us, ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot")
    model = dynax.Acrobot.from_physical(m1=1.1)  # another model than the data's: errors that grow with the horizon
    for horizons, stride in (((0.2, 0.5), 7), ((0.1, 0.3, 0.45), None)):
        errors = np.asarray(window_simulation_errors(model, data, horizons, stride=stride))
        np.testing.assert_array_equal(
            errors, np.asarray(dynax.simulation_error(model, data, horizons, stride=stride).errors)
        )
        assert errors.shape[1] == round(max(horizons) / 0.01) + 1 and np.all(np.isfinite(errors))
        assert float(np.abs(errors[:, -1]).max()) > 1e-2


def test_fixed_grid_explicit_step_equals_diffrax_step():
    """The fixed-grid rollout writes explicit Runge-Kutta stages out from the tableau; each method's
    step must equal diffrax's own `solver.step` (to rounding), including FSAL methods whose last
    stage is skipped, and solvers that are not explicit RK must still go through diffrax. The rolled
    stages (one vector field in a loop) too, and their forward-mode derivative (the diagnosis's fits)."""
    from dynax.internal import explicit_step, zoh_term

    system = dynax.Acrobot()
    x = jnp.array([0.3, -0.2, 0.5, 1.0])
    u = jnp.array([0.7])
    term = zoh_term(system)
    for solver in (dynax.RK4(), diffrax.Tsit5(), diffrax.Dopri5(), diffrax.Dopri8(), diffrax.Heun(), diffrax.Bosh3()):
        ref = solver.step(term, 0.1, 0.15, x, u, solver.init(term, 0.1, 0.15, x, u), made_jump=True)[0]
        for rolled in (False, True):
            ours = explicit_step(system, solver, rolled)(jnp.asarray(0.1), x, u, jnp.asarray(0.05))
            np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-12, err_msg=f"{type(solver).__name__} {rolled}")
            # times and step as Python floats, as a caller outside a rollout may pass them
            plain = explicit_step(system, solver, rolled)(0.1, x, u, 0.05)
            np.testing.assert_allclose(plain, ref, rtol=1e-12, atol=1e-12, err_msg=f"{type(solver).__name__} {rolled}")
    assert explicit_step(system, diffrax.Euler()) is None
    assert explicit_step(system, diffrax.Euler(), rolled=True) is None

    # Forward mode through the rolled loop against the written-out stages (each checked against diffrax above).
    def end(x0, rolled):
        grid = dynax.FixedGrid(diffrax.Tsit5(scan_kind="lax"), substeps=3, roll_stages=rolled)
        return dynax.simulate(system, x0, jnp.linspace(0, 0.2, 5), jnp.full((5, 1), 0.7), method=grid).xs[-1]

    jac_rolled = jax.jacfwd(lambda x0: end(x0, True))(x)
    np.testing.assert_allclose(jac_rolled, jax.jacfwd(lambda x0: end(x0, False))(x), rtol=1e-10, atol=1e-12)
    assert float(np.abs(jac_rolled - np.eye(4)).max()) > 1e-2
    # Through simulate: a rollout with Euler (diffrax's step) still integrates.
    xs = dynax.simulate(
        system, x, jnp.linspace(0, 0.1, 11), jnp.zeros((11, 1)), method=dynax.FixedGrid(diffrax.Euler())
    ).xs
    assert np.all(np.isfinite(xs))


def test_a_measured_state_of_a_model_with_internal_states_is_refused_with_how_to_complete_it():
    # A `Stiction` with a dwell time carries a memory of rest: a measured state (positions and velocities)
    # is short of it, and the refusal says how to complete it; so completed, the joint at rest holds.
    model = dynax.Extended(dynax.DoublePendulum(), (dynax.Stiction(1, 0.3, dwell_time=0.1),))
    ts, us = jnp.linspace(0.0, 1.0, 101), jnp.zeros((101, 2))
    measured = jnp.array([0.1, 0.0, 0.0, 0.0])
    with pytest.raises(dynax.UsageError, match=r"4 entries but Extended has 5 states.*initial_state\(x0, u0\)"):
        dynax.simulate(model, measured, ts, us)
    x0 = model.initial_state(measured, us[0])
    assert x0.shape == (5,) and float(x0[4]) == 1.0  # measured at rest: rested long
    xs = dynax.simulate(model, x0, ts, us).xs
    assert float(jnp.max(jnp.abs(xs[:, 1]))) < 1e-6  # the elbow, held by its static level under the swing
    # a state short of the measured ones is refused without that advice
    with pytest.raises(
        dynax.UsageError, match=r"has 2 entries but Extended has 5 states \('q1', 'q2', 'dq1', 'dq2', 'fs2_rest'\)$"
    ):
        dynax.simulate(model, measured[:2], ts, us)
