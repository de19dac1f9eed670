"""Property-based (hypothesis): `simulate` fed random, often malformed, arguments raises `UsageError`
with a message, or returns the exact solution; never another exception, never silent NaN rows."""

from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import dynax

# The linear axis without Coulomb friction or offset is linear: m q'' = F - b q'. Its zero-order-hold
# solution is the matrix exponential of the augmented system, an oracle independent of diffrax.
AXIS = dynax.LinearAxis(coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0))


def exact(x0, ts, us):
    m, b = float(AXIS.mass), float(AXIS.viscous)
    a = np.array([[0.0, 1.0, 0.0], [0.0, -b / m, 1.0 / m], [0.0, 0.0, 0.0]])
    xs = [np.asarray(x0, float)]
    for k in range(len(ts) - 1):
        z = scipy.linalg.expm(a * (ts[k + 1] - ts[k])) @ np.r_[xs[-1], us[k]]
        xs.append(z[:2])
    return np.array(xs)


values = st.one_of(st.floats(-1e3, 1e3), st.sampled_from([np.nan, np.inf, -np.inf]), st.floats(-1e3, 1e3))


@st.composite
def arguments(draw):
    n = draw(st.sampled_from([2, 6]))
    x0 = draw(st.lists(values, min_size=draw(st.sampled_from([2, 2, 2, 1, 3])), max_size=3))[:3]
    steps = draw(st.lists(st.floats(1e-3, 0.1), min_size=n - 1, max_size=n - 1))
    ts = np.concatenate([[draw(st.floats(-10, 10))], np.asarray(steps)]).cumsum()
    if draw(st.integers(0, 3)) == 0:  # corrupt the clock: a repeat, a reversal, a NaN
        k = draw(st.integers(0, n - 1))
        ts[k] = draw(st.sampled_from([ts[0], ts[-1], np.nan, -np.inf]))
    rows = draw(st.sampled_from([n, n, n - 1, n + 1]))
    us = np.asarray(draw(st.lists(values, min_size=rows, max_size=rows)))
    if draw(st.booleans()):
        us = us[:, None]
    return np.asarray(x0, float), ts, us


@pytest.mark.wrong_types
@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(arguments())
def test_simulate_refuses_or_returns_the_exact_solution(args):
    x0, ts, us = args
    try:
        sim = dynax.simulate(AXIS, x0, ts, us)
    except dynax.UsageError as e:
        assert str(e).startswith("simulate: ")
        return
    xs = np.asarray(sim.xs)
    assert np.all(np.isfinite(xs)) and not bool(sim.diverged)
    scale = 1 + np.max(np.abs(exact(x0, ts, us.reshape(len(us), -1)[:, 0])))
    np.testing.assert_allclose(xs, exact(x0, ts, us.reshape(len(us), -1)[:, 0]), rtol=1e-6, atol=1e-9 * scale)
