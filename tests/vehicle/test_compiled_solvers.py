"""The compiled vehicle solvers against the algorithms written out as plain Python loops.

`fit_lagged` runs the EM-free iteration (Abbeel, Ganapathi and Ng 2005) as an optimistix
minimiser inside one `while_loop`; `fit_backprop` runs optax's L-BFGS through the engine's
`fit_minimise`. Each is checked against the same algorithm stepped from Python, iteration by
iteration, and their histories, progress reports and stopping rules against what they claim.
"""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from dynax import AccelerationModel, Backprop, fit_minimise, Helicopter, Lagged, Parameters
from dynax.internal import (
    auto_stride,
    fit_backprop,
    fit_lagged,
    fit_one_step,
    horizon_steps,
    lagged_loss,
    normal_equations,
    OptaxLBFGS,
    ridge_solve,
    TEMPEST_FEATURES,
    window_starts,
    with_theta,
)
from dynax.synthetic import generate_helicopter_flight


@pytest.fixture(scope="module")
def flight():
    """Truth-simulator hover (the acceleration model is not exact: the iteration has work to do)."""
    return generate_helicopter_flight("hover", 8.0, seed=6)


@pytest.fixture(scope="module")
def start(flight):
    return fit_one_step(Helicopter(AccelerationModel.with_features(TEMPEST_FEATURES)), flight).model


def _python_em_free(system, data, criterion):
    """The paper's EM-free iteration, stepped from Python: roll out, least squares with the rollout
    states held fixed, first step size along (new - old) that lowers the lagged loss."""
    n_steps = horizon_steps(criterion.horizon, data.dt, "test")
    starts = window_starts(data, n_steps, criterion.stride)
    w = jnp.ones(6)

    def loss(s):
        return float(lagged_loss(s, data, n_steps, starts=starts, weights=w))

    current, losses = loss(system), []
    losses.append(current)
    for _ in range(criterion.max_iterations):
        ata, atb, _ = normal_equations(system, data, starts, n_steps, w, True, criterion.batch_size)
        old = system.body_model.parameter_vector()
        new = ridge_solve(ata, atb, criterion.ridge)
        accepted = None
        for step in criterion.step_sizes:
            candidate = with_theta(system, old + step * (new - old))
            value = loss(candidate)
            if np.isfinite(value) and value < current:
                accepted = candidate, value
                break
        if accepted is None:
            break
        system, value = accepted
        improvement = (current - value) / current
        current = value
        losses.append(current)
        if improvement < criterion.tolerance:
            break
    return system, np.asarray(losses)


def test_compiled_em_free_takes_the_python_iterations_steps(flight, start):
    criterion = Lagged(horizon=0.2, stride=8, max_iterations=4)
    seen = []
    fit = fit_lagged(start, flight, criterion, callback=lambda i, loss: seen.append((i, loss)))
    reference, losses = _python_em_free(start, flight, criterion)
    np.testing.assert_allclose(
        fit.model.body_model.parameter_vector(), reference.body_model.parameter_vector(), rtol=1e-9, atol=1e-12
    )
    history = np.asarray([loss for _, loss in fit.history])
    np.testing.assert_allclose(history, losses, rtol=1e-10)
    assert losses[-1] < 0.9 * losses[0]  # the iteration did real work on this flight
    # the history is an array of fixed length (max_iterations + 1), NaN past the last iteration
    assert (
        fit.loss_history.shape == (criterion.max_iterations + 1,) and fit.time_history.shape == fit.loss_history.shape
    )
    assert np.all(np.isnan(np.asarray(fit.loss_history)[len(losses) :]))
    seconds = np.asarray([t for t, _ in fit.history])
    assert seconds[0] == 0 and np.all(np.diff(seconds) > 0)
    # one report per accepted iteration, from inside the compiled loop, with its loss
    assert [i for i, _ in seen] == list(range(len(losses) - 1))
    np.testing.assert_allclose([loss for _, loss in seen], losses[1:], rtol=1e-12)
    assert fit.names == tuple(start.body_model.parameter_names)
    assert int(fit.steps) >= len(losses) - 1


def _python_lbfgs(loss_fn, theta, steps, tolerance):
    """optax's L-BFGS stepped from Python with the old criterion's stopping rule."""
    optimiser = optax.lbfgs()
    state = optimiser.init(theta)
    value_and_grad = optax.value_and_grad_from_state(loss_fn)

    @jax.jit
    def step(theta, state):
        value, grad = value_and_grad(theta, state=state)
        updates, state = optimiser.update(grad, state, theta, value=value, grad=grad, value_fn=loss_fn)
        return optax.apply_updates(theta, updates), state

    current, losses = float(loss_fn(theta)), []
    losses.append(current)
    for _ in range(steps):
        theta, state = step(theta, state)
        value = float(optax.tree_utils.tree_get(state, "value"))
        improvement = (current - value) / current
        current = value
        losses.append(current)
        if 0 <= improvement < tolerance:
            break
    return theta, np.asarray(losses)


@pytest.mark.slow  # about 55 s; the quick suite keeps the compiled EM-free case
def test_compiled_backprop_takes_the_python_lbfgs_steps(flight, start):
    criterion = Backprop(horizon=0.2, stride=8, max_steps=6)
    n_steps = horizon_steps(criterion.horizon, flight.dt, "test")
    starts = window_starts(flight, n_steps, criterion.stride)

    def loss_fn(theta):
        return lagged_loss(with_theta(start, theta), flight, n_steps, starts=starts)

    theta, losses = _python_lbfgs(
        loss_fn, start.body_model.parameter_vector(), criterion.max_steps, criterion.tolerance
    )
    fit = fit_backprop(start, flight, criterion)
    np.testing.assert_allclose(fit.model.body_model.parameter_vector(), theta, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose([loss for _, loss in fit.history], losses, rtol=1e-9)
    assert losses[-1] < losses[0]


def test_lbfgs_stopping_rules():
    """Relative decrease, target loss and a non-finite line search each end the solve."""

    def rosenbrock(model, args):
        x, y = model
        return (1 - x) ** 2 + 100 * (y - x**2) ** 2 + args

    start = (jnp.asarray(-1.2), jnp.asarray(1.0))
    converged = fit_minimise(
        rosenbrock,
        start,
        None,
        1.0,
        solver=OptaxLBFGS(rtol=1e-12, history=201),
        scale=1.0,
        max_steps=200,
        covariance=False,
    )
    assert converged.succeeded and float(converged.loss) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(converged.value, [1.0, 1.0], atol=1e-4)
    history = np.asarray(converged.loss_history)
    recorded = history[~np.isnan(history)]
    assert recorded.size == int(converged.steps) + 1 and recorded[-1] == pytest.approx(float(converged.loss))
    early = fit_minimise(
        rosenbrock,
        start,
        None,
        1.0,
        solver=OptaxLBFGS(rtol=1e-12, target=2.0, history=201),
        scale=1.0,
        max_steps=200,
        covariance=False,
    )
    assert 1.0 < float(early.loss) <= 2.0 and int(early.steps) < int(converged.steps)

    def cliff(model, args):  # finite only for x < 0.5: the line search walks off it
        x, y = model
        return jnp.where(x < 0.5, rosenbrock(model, args), jnp.nan)

    stopped = fit_minimise(
        cliff, start, None, 1.0, solver=OptaxLBFGS(rtol=1e-12, history=201), scale=1.0, max_steps=200, covariance=False
    )
    assert np.isfinite(float(stopped.loss)) and float(stopped.value[0]) < 0.5


def test_auto_stride_keeps_about_the_requested_number_of_windows():
    assert auto_stride(6001, 100, 600) == 10  # 60 s at 100 Hz, H = 1 s: 5901 starts, every 10th
    assert auto_stride(500, 100, 600) == 1
    for n in (701, 5000, 12345):
        stride = auto_stride(n, 100, 600)
        windows = len(range(0, n - 100, stride))
        assert windows <= 600 and len(range(0, n - 100, stride - 1)) > 600 if stride > 1 else True


def test_parameters_of_the_helicopter_follow_the_body_models_vector(start):
    parameters = Parameters.of(start)
    np.testing.assert_array_equal(parameters.vector(start), start.body_model.parameter_vector())
    assert parameters.names == tuple(start.body_model.parameter_names)
