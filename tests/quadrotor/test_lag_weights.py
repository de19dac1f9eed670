"""`Lagged(lag_weights=...)`: the relative weights move the lagged fit toward the short horizons on a
synthetic flight made by scipy (`synthetic_flight`), and the default is the paper's uniform loss."""

import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax.internal import lagged_loss, lagged_loss_of
from tests.typecheck import standing_aside

from .synthetic_flight import quadrotor_flight

HORIZON = 0.3


@pytest.fixture(scope="module")
def delayed():
    """A noise-free flight whose rotors act on the commands 40 ms late, a lag the acceleration model
    cannot express: its lagged fit has to trade the short horizons against the long ones."""
    flight = quadrotor_flight(8.0, seed=3, noise=False, delay=0.04)
    start = dynax.Quadrotor.from_flights("acceleration", [flight])
    fits = {
        weights: dynax.fit_quadrotor(
            start,
            [flight],
            dynax.Lagged(horizon=HORIZON, stride=5, max_iterations=5, lag_weights=weights),
            progress=False,
        ).model
        for weights in ("uniform", "relative")
    }
    return flight, fits


def test_relative_lag_weights_favour_the_short_horizons(delayed):
    flight, fits = delayed
    rmse = {w: dynax.flight_error(model, flight, (1, 30)).table("rmse") for w, model in fits.items()}
    for group in ("velocity", "body_rate"):  # one step ahead: the relative fit no worse
        assert rmse["relative"][group][0] <= rmse["uniform"][group][0]
    # and it pays on the uniform loss, which the uniform fit minimises (its 0.3 s errors weigh most)
    uniform_loss = {
        w: lagged_loss_of(m.as_helicopter(), m.body_frame(flight), HORIZON, stride=5) for w, m in fits.items()
    }
    assert uniform_loss["uniform"] < uniform_loss["relative"]


def test_the_default_is_the_uniform_loss(delayed):
    flight, fits = delayed
    assert dynax.Lagged().lag_weights == "uniform"
    model = fits["uniform"]
    helicopter, record = model.as_helicopter(), model.body_frame(flight)
    n_steps = round(HORIZON / 0.01)
    per_state = lagged_loss(helicopter, record, n_steps, weights=jnp.ones(6))
    per_lag = lagged_loss(helicopter, record, n_steps, weights=jnp.ones((n_steps, 6)))
    np.testing.assert_allclose(float(per_lag), float(per_state), rtol=1e-12)
    for refused in ("equal", 1.5, -0.5):
        with standing_aside(), pytest.raises(dynax.UsageError, match="lag_weights"):  # "equal" is no Literal
            dynax.Lagged(lag_weights=refused)
