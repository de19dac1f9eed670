"""The fitting engine: parameters from filters, least squares and minimisation, vmap."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import fit_least_squares, fit_minimise, Parameters, UsageError
from dynax.internal import dense_forward


def test_parameters_names_follow_tree_paths_and_masks():
    model = {"a": jnp.ones((2, 3)), "b": jnp.asarray(2.0), "c": 3}
    mask = np.array([[True, False, True], [False, False, True]])
    p = Parameters.of(model, {"a": mask, "b": True, "c": True})
    assert p.names == ("['a'][0,0]", "['a'][0,2]", "['a'][1,2]", "['b']")
    new = p.with_vector(model, jnp.array([10.0, 20.0, 30.0, 40.0]))
    np.testing.assert_array_equal(new["a"], [[10.0, 1.0, 20.0], [1.0, 1.0, 30.0]])
    assert float(new["b"]) == 40.0 and new["c"] == 3
    with pytest.raises(UsageError, match="mask of"):
        Parameters.of(model, {"a": np.ones((3, 2), bool), "b": True, "c": False})


def test_system_parameters_default_and_labels():
    heli = dynax.Helicopter()
    p = Parameters.of(heli)
    assert p.names == heli.body_model.parameter_names  # the feature labels, not the paths
    np.testing.assert_array_equal(p.vector(heli), heli.body_model.parameter_vector())
    model = dynax.Extended(dynax.Acrobot(), (dynax.CoulombFriction(joint=1, fc=0.2),))
    assert Parameters.of(model).names[-1] == "terms[0].coefficient"
    assert Parameters.of(model).names[0] == "system.theta1"


def _pendulum_data(key, noise):
    """A damped pendulum integrated with adaptive Dopri8 at tight tolerance: not the fitted integrator."""
    true = dynax.LinearAxis(
        mass=jnp.asarray(0.8), viscous=jnp.asarray(0.3), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)
    )
    ts = jnp.linspace(0.0, 4.0, 401)
    us = jnp.sin(3.0 * ts)[:, None] + 0.5 * jnp.cos(1.3 * ts)[:, None]
    sol = dynax.simulate(
        true, jnp.array([0.0, 0.0]), ts, us, method=dynax.Adaptive(solver=diffrax.Dopri8(), rtol=1e-10, atol=1e-10)
    )
    xs = sol.xs + noise * jax.random.normal(key, sol.xs.shape)
    return true, ts, xs, us


def _pendulum_problem():
    """A start far from `_pendulum_data`'s truth, the filter freeing mass and viscous friction, and the
    residuals of a fixed-grid rollout from the first measured state."""
    start = dynax.LinearAxis(
        mass=jnp.asarray(1.5), viscous=jnp.asarray(1.0), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)
    )
    spec = eqx.tree_at(lambda s: (s.mass, s.viscous), jax.tree.map(lambda _: False, start), (True, True))

    def residuals(model, data):
        ts, xs, us = data
        return (dynax.simulate(model, xs[0], ts, us, method=dynax.FixedGrid(substeps=2)).xs - xs).ravel()

    return start, spec, residuals


def test_least_squares_recovers_parameters_within_their_standard_errors():
    true, ts, xs, us = _pendulum_data(jax.random.PRNGKey(0), noise=1e-3)
    start, spec, residuals = _pendulum_problem()
    sol = eqx.filter_jit(fit_least_squares)(residuals, start, spec, (ts, xs, us))
    assert sol.succeeded and sol.names == ("mass", "viscous")
    est, std = sol.estimates(), sol.standard_errors()
    for name in ("mass", "viscous"):
        assert abs(est[name] - float(getattr(true, name))) < 5 * std[name] + 1e-3
        assert 0 < std[name] < 0.02
    assert sol.loss < 1e-3 * sol.initial_loss


def test_minimise_agrees_with_least_squares_and_vmap_matches_single_fits():
    ts = jnp.linspace(0.0, 3.0, 60)
    key = jax.random.PRNGKey(1)
    ys = jnp.stack([2.0 * jnp.exp(-0.7 * ts), 3.0 * jnp.exp(-0.2 * ts)]) + 0.01 * jax.random.normal(key, (2, 60))
    model = {"a": jnp.asarray(1.0), "b": jnp.asarray(0.3)}
    res = lambda m, y: m["a"] * jnp.exp(-m["b"] * ts) - y  # noqa: E731
    batched = jax.vmap(lambda y: fit_least_squares(res, model, None, y))(ys)
    for i in range(2):
        single = fit_least_squares(res, model, None, ys[i])
        np.testing.assert_allclose(batched.value[i], single.value, rtol=1e-8)
        # Gaussian noise of 0.01: loss/sigma^2 is the negative log-likelihood, whose Hessian inverse
        # is the same covariance as Gauss-Newton's (up to sigma estimated vs known).
        nll = lambda m, y: 0.5 * jnp.sum(res(m, y) ** 2) / 0.01**2  # noqa: E731
        minimised = fit_minimise(nll, model, None, ys[i])
        np.testing.assert_allclose(minimised.value, single.value, rtol=1e-6)
        np.testing.assert_allclose(minimised.std_errors, single.std_errors, rtol=0.2)


def test_dense_jacobian_gives_the_forward_mode_fit_and_differentiates_in_the_data():
    # The same problem through optimistix's own linearisation ("fwd") and the dense rule ("dense").
    ts = jnp.linspace(0.0, 3.0, 60)
    y = 2.0 * jnp.exp(-0.7 * ts) + 0.01 * jax.random.normal(jax.random.PRNGKey(2), (60,))
    model = {"a": jnp.asarray(1.0), "b": jnp.asarray(0.3)}
    res = lambda m, y: m["a"] * jnp.exp(-m["b"] * ts) - y  # noqa: E731
    fwd = fit_least_squares(res, model, None, y)
    dense = fit_least_squares(res, model, None, y, options=dynax.LeastSquaresOptions(jac="dense"))
    np.testing.assert_allclose(dense.value, fwd.value, rtol=1e-10)
    np.testing.assert_allclose(dense.std_errors, fwd.std_errors, rtol=1e-8)
    # the Jacobian it returns is the residuals' Jacobian in the scaled unknowns (scale |p0| = (1, 0.3))
    z = (dense.value - jnp.array([1.0, 0.3])) / jnp.array([1.0, 0.3])
    by_hand = jax.jacfwd(lambda z: res({"a": 1.0 + z[0], "b": 0.3 + 0.3 * z[1]}, y))(z)
    np.testing.assert_allclose(dense.jacobian, by_hand, rtol=1e-8, atol=1e-12)
    # ... and its residuals are those of the fitted model and of the starting one
    np.testing.assert_allclose(dense.residuals, res(dense.model, y), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(dense.initial_residuals, res(model, y), rtol=1e-12)
    # The rule itself: tangents in the unknowns and in the data give plain forward mode's directional derivatives.
    f = lambda z, d: res({"a": 1.0 + z[0], "b": 0.3 + 0.3 * z[1]}, d[0]) * d[1]  # noqa: E731
    rule = dense_forward(f)
    primals = (jnp.array([0.2, -0.1]), (y, jnp.asarray(1.5)))
    for tangents in [
        (jnp.array([1.0, -2.0]), (jnp.zeros(60), jnp.asarray(0.0))),
        (jnp.zeros(2), (jnp.sin(ts), jnp.asarray(0.3))),
        (jnp.array([0.5, 1.0]), (jnp.cos(ts), jnp.asarray(-1.0))),
    ]:
        np.testing.assert_allclose(jax.jvp(rule, primals, tangents)[1], jax.jvp(f, primals, tangents)[1], rtol=1e-12)


def test_public_engine_matches_scipy_on_a_model_of_the_users_own():
    """`dynax.fit_least_squares` on a plain dict model (no dynax system) against scipy's trust-region
    least squares: the same estimate, and standard errors equal to scipy's Jacobian-based ones."""
    import scipy.optimize

    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 5.0, 200)
    y = 2.0 * np.exp(-0.7 * t) + 0.3 + 0.02 * rng.standard_normal(t.size)

    def residuals(model, data):
        t, y = data
        return model["a"] * jnp.exp(-model["b"] * t) + model["c"] - y

    start = {"a": jnp.asarray(1.0), "b": jnp.asarray(0.2), "c": jnp.asarray(0.0)}
    sol = dynax.fit_least_squares(residuals, start, dynax.Parameters.of(start, True), (jnp.asarray(t), jnp.asarray(y)))
    assert isinstance(sol, dynax.Solution) and sol.names == ("['a']", "['b']", "['c']")

    ref = scipy.optimize.least_squares(
        lambda p: p[0] * np.exp(-p[1] * t) + p[2] - y, [1.0, 0.2, 0.0], xtol=1e-12, ftol=1e-12, gtol=1e-12
    )
    sigma2 = 2 * ref.cost / (t.size - 3)
    ref_std = np.sqrt(np.diag(sigma2 * np.linalg.inv(ref.jac.T @ ref.jac)))
    np.testing.assert_allclose(np.asarray(sol.value), ref.x, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(sol.std_errors), ref_std, rtol=1e-4)
    assert abs(ref.x[1] - 0.7) < 4 * ref_std[1]  # and both found the generating decay rate


def test_unknowns_the_residuals_do_not_determine_get_no_finite_error_and_frozen_ones_zero():
    # The decay model of the test above with two more unknowns: `d` enters nothing, and `e` and `f`
    # enter only as their sum. Their errors must be infinite (the pseudo-inverse put 0 on `d`, finite
    # numbers on `e` and `f`); `a`, `b`, `c` keep the errors of the fit without them (scipy's), and
    # `c2`, frozen by a zero scale, keeps 0.
    import scipy.optimize

    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 5.0, 200)
    y = 2.0 * np.exp(-0.7 * t) + 0.3 + 0.02 * rng.standard_normal(t.size)

    def residuals(model, data):
        t, y = data
        return (
            model["a"] * jnp.exp(-model["b"] * t) + model["c"] + model["c2"] + model["e"] * t**2 + model["f"] * t**2 - y
        )

    start = {k: jnp.asarray(v) for k, v in dict(a=1.0, b=0.2, c=0.0, c2=0.0, d=1.0, e=0.0, f=0.0).items()}
    params = dynax.Parameters.of(start, True)
    scale = jnp.asarray([0.0 if n == "['c2']" else 1.0 for n in params.names])
    sol = dynax.fit_least_squares(residuals, start, params, (jnp.asarray(t), jnp.asarray(y)), scale=scale)
    std = dict(zip(sol.names, np.asarray(sol.std_errors)))
    assert all(np.isinf(std[f"['{k}']"]) for k in "def"), std
    assert std["['c2']"] == 0.0
    ref = scipy.optimize.least_squares(
        lambda p: p[0] * np.exp(-p[1] * t) + p[2] + p[3] * t**2 - y,
        [1.0, 0.2, 0.0, 0.0],
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    sigma2 = 2 * ref.cost / (t.size - 4)
    ref_std = np.sqrt(np.diag(sigma2 * np.linalg.inv(ref.jac.T @ ref.jac)))
    np.testing.assert_allclose([std[f"['{k}']"] for k in "abc"], ref_std[:3], rtol=1e-3)
    covariance = np.asarray(sol.covariance)
    k = sol.names.index("['d']")
    assert np.all(np.isnan(covariance[k])) and np.isfinite(covariance[0, 0])
    # the same under vmap (the diagnosis fits its configurations so)
    batched = jax.vmap(
        lambda y_: dynax.fit_least_squares(residuals, start, params, (jnp.asarray(t), y_), scale=scale).std_errors
    )(jnp.stack([jnp.asarray(y)] * 2))
    np.testing.assert_array_equal(np.asarray(batched[0]), np.asarray(sol.std_errors))


class _Scalar(eqx.Module):
    p: jax.Array


def test_a_solver_that_ends_worse_than_it_started_is_reported_as_diverged():
    """Gauss-Newton without a trust region on arctan(p) from p = 1.5 overshoots, further each step
    (the textbook divergence of Newton's method on arctan); Levenberg-Marquardt converges."""
    import optimistix as optx

    residual = lambda m, _: jnp.atleast_1d(jnp.arctan(m.p))  # noqa: E731
    start = _Scalar(jnp.asarray(1.5))
    gauss_newton = fit_least_squares(
        residual,
        start,
        solver=optx.GaussNewton(rtol=1e-8, atol=1e-8),
        max_steps=4,
        options=dynax.LeastSquaresOptions(covariance=False),
    )
    assert float(gauss_newton.loss) > float(gauss_newton.initial_loss)
    assert gauss_newton.result == optx.RESULTS.nonlinear_divergence and not gauss_newton.succeeded
    assert abs(float(gauss_newton.value[0])) > 1.5  # the solver's last point is kept, for inspection
    damped = fit_least_squares(residual, start, options=dynax.LeastSquaresOptions(covariance=False))
    assert damped.succeeded and abs(float(damped.value[0])) < 1e-6


def test_the_strict_trust_region_refuses_a_rise_that_optimistix_would_accept():
    """optimistix accepts a step when `actual <= 0.01 * predicted`; with a predicted rise of 1.5 an actual
    rise of 0.01 passes that. The strict region refuses it and shrinks, and still takes a real decrease."""
    import lineax as lx
    import optimistix as optx

    from dynax.internal import StrictTrustRegion

    def info(residual):
        return optx.FunctionInfo.ResidualJac(jnp.array([residual]), lx.MatrixLinearOperator(jnp.array([[1.0]])))

    y, y_eval = jnp.array([0.0]), jnp.array([1.0])  # J d + r = 2: predicted change 0.5 (4 - 1) = 1.5
    rise, fall = info(1.01), info(0.5)
    plain, strict = optx.ClassicalTrustRegion(), StrictTrustRegion()
    state = strict.init(y, info(1.0))
    _, accepted, _, _ = plain.step(jnp.array(False), y, y_eval, info(1.0), rise, state)
    assert bool(accepted)  # the flaw: a rise, accepted
    size, accepted, _, new_state = strict.step(jnp.array(False), y, y_eval, info(1.0), rise, state)
    assert not bool(accepted) and float(size) == float(new_state.step_size) == 0.25
    _, accepted, _, _ = strict.step(jnp.array(False), y, jnp.array([-0.5]), info(1.0), fall, state)
    assert bool(accepted)
    assert bool(strict.step(jnp.array(True), y, y_eval, info(1.0), rise, state)[1])  # the first evaluation is no step


@pytest.mark.slow  # about 30 s
def test_a_fit_started_at_its_minimum_stops_at_once_and_the_answer_is_the_tightly_converged_one():
    """MINPACK's relative-reduction test (lmder's `ftol`): from its own solution a fit takes a step or
    two. optimistix's test alone, which waits for an accepted step that moves every residual by under
    `atol + rtol |r|`, took 15 here (23 from the far start, against 10), each a Jacobian through the
    rollout, while the strict trust region refused steps that raised the loss in its last digits."""
    import optimistix as optx

    from dynax.internal import StrictTrustRegion

    true, ts, xs, us = _pendulum_data(jax.random.PRNGKey(0), noise=1e-2)
    start, spec, residuals = _pendulum_problem()
    fit = eqx.filter_jit(fit_least_squares)
    first = fit(residuals, start, spec, (ts, xs, us))
    again = fit(residuals, first.model, spec, (ts, xs, us))
    assert first.succeeded and again.succeeded and int(again.steps) <= 3, int(again.steps)
    # optimistix's own test alone, at 1e-12: the same estimate to a tiny fraction of its standard error
    tight = optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12)
    reference = fit(
        residuals, start, spec, (ts, xs, us), solver=eqx.tree_at(lambda s: s.search, tight, StrictTrustRegion())
    )
    assert int(reference.steps) > int(first.steps)
    for sol in (first, again):
        np.testing.assert_array_less(
            np.abs(np.asarray(sol.value - reference.value)), 1e-6 * np.asarray(reference.std_errors)
        )


def _exponential_and_sine():
    """Residuals of a sum of an exponential and a sine (scaled by 100) against data made with
    y = (2, -1.3, 0.5, 3): a small fit whose trust region refuses steps from some starts."""
    ts = jnp.linspace(0.0, 4.0, 40)
    data = 2.0 * jnp.exp(-1.3 * ts) + 0.5 * jnp.sin(3.0 * ts)

    def residuals(y):
        return 100.0 * (y[0] * jnp.exp(y[1] * ts) + y[2] * jnp.sin(y[3] * ts) - data)

    return residuals


def test_the_jacobian_formed_only_where_a_step_is_taken_gives_the_same_iterates_for_fewer_jacobians():
    """MINPACK's order (residuals at the trial point, the Jacobian only once the step is taken) against
    optimistix's (the Jacobian at every trial point): a sum of an exponential and a sine fitted from a
    start where the trust region refuses steps. Each Jacobian is counted where it is formed (the JVP
    rule's callback, which depends on the point only); the iterates must be the same."""
    import optimistix as optx

    from dynax.internal import levenberg_marquardt

    model = _exponential_and_sine()
    formed = []

    @jax.custom_jvp
    def residuals(y):
        return model(y)

    @residuals.defjvp
    def residuals_jvp(primals, tangents):
        jax.debug.callback(lambda _: formed.append(1), primals[0][0])
        return jax.jvp(model, primals, tangents)

    start = jnp.array([3.0, -3.0, 0.1, 2.8])
    solutions = {}
    for jacobian in ("every_step", "accepted"):
        formed.clear()
        solver = levenberg_marquardt(1e-10, 1e-10, jacobian=jacobian)
        solution = optx.least_squares(lambda y, _: residuals(y), solver, start, max_steps=100, throw=False)
        jax.effects_barrier()
        solutions[jacobian] = (solution, len(formed))
    (lazy, n_lazy), (eager, n_eager) = solutions["accepted"], solutions["every_step"]
    assert lazy.result == optx.RESULTS.successful and eager.result == optx.RESULTS.successful
    np.testing.assert_allclose(np.asarray(lazy.value), [2.0, -1.3, 0.5, 3.0], rtol=1e-8)
    np.testing.assert_allclose(np.asarray(lazy.value), np.asarray(eager.value), rtol=1e-12)
    steps, accepted = int(lazy.stats["num_steps"]), int(lazy.state.num_accepted_steps)
    assert steps == int(eager.stats["num_steps"]) and accepted < steps  # the start makes it refuse steps
    assert n_eager == steps and n_lazy == accepted, (n_eager, n_lazy, steps, accepted)
    # batched (the branch becomes a select): the same answers as one by one
    starts = jnp.stack([start, jnp.array([1.0, -0.5, 0.2, 2.5])])
    solver = levenberg_marquardt(1e-10, 1e-10, jacobian="accepted")
    batched = jax.vmap(
        lambda y0: optx.least_squares(lambda y, _: model(y), solver, y0, max_steps=100, throw=False).value
    )(starts)
    np.testing.assert_allclose(np.asarray(batched), np.asarray(jnp.stack([lazy.value, lazy.value])), rtol=1e-8)
    with pytest.raises(ValueError, match="jacobian"):
        levenberg_marquardt(1e-8, 1e-8, jacobian="sometimes")


def test_nielsens_damping_update_reaches_the_same_minimum_in_no_more_steps():
    """Nielsen's rule (the damping set from the gain ratio after every accepted step) against the
    trust region's keep-unless-99 %-of-the-prediction: from five starts of the exponential-plus-sine
    fit, one of them to a local minimum, the same minimum each time, never more steps, and fewer where
    the path is long (29 against 37 when this was written)."""
    import optimistix as optx

    from dynax.internal import levenberg_marquardt

    model = _exponential_and_sine()

    def residuals(y, _):
        return model(y)

    starts = (
        [3.0, -3.0, 0.1, 2.8],
        [1.0, -0.5, 0.2, 2.5],
        [1.0, -0.2, 1.0, 2.0],
        [2.5, -1.0, 0.3, 3.2],
        [1.5, -2.0, 0.8, 2.9],
    )
    saved = 0
    for start in starts:
        fits = {
            d: optx.least_squares(
                residuals,
                levenberg_marquardt(1e-10, 1e-10, jacobian="accepted", damping=d),
                jnp.array(start),
                max_steps=200,
                throw=False,
            )
            for d in ("classical", "nielsen")
        }
        classical, nielsen = fits["classical"], fits["nielsen"]
        assert nielsen.result == optx.RESULTS.successful and classical.result == optx.RESULTS.successful
        loss = [float(jnp.sum(residuals(f.value, None) ** 2)) for f in (classical, nielsen)]
        assert abs(loss[1] - loss[0]) <= 1e-9 * max(loss[0], 1.0), (start, loss)
        np.testing.assert_allclose(np.asarray(nielsen.value), np.asarray(classical.value), rtol=1e-5, atol=1e-8)
        steps = int(classical.stats["num_steps"]), int(nielsen.stats["num_steps"])
        assert steps[1] <= steps[0], (start, steps)
        saved += steps[0] - steps[1]
    assert saved >= 5, saved
    with pytest.raises(ValueError, match="damping"):
        levenberg_marquardt(1e-8, 1e-8, damping="geodesic")
