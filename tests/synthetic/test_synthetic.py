"""`dynax.synthetic`: the truth simulators and data generators, checked against independent references."""

import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate

import dynax
from dynax import Acrobot, CoulombFriction, Extended
from dynax.internal import hover_state
import dynax.synthetic as synthetic

PUBLIC = (
    "demo_data",
    "FlightController",
    "generate_helicopter_flight",
    "helicopter_flight",
    "HelicopterTruth",
    "multisine",
    "synthetic_trajectory",
)


@pytest.mark.parametrize("name", PUBLIC)
def test_synthetic_data_is_spelled_once(name):
    # Synthetic data has one public spelling, `dynax.synthetic.NAME` (defined in dynax/_synthetic/): the
    # top level holds the pipeline's verbs and types, not the data generators a second time.
    obj = getattr(synthetic, name)
    assert obj.__module__.startswith("dynax._synthetic.")
    assert not hasattr(dynax, name)


def test_the_model_layer_does_not_import_the_synthetic_package():
    # The models are what is fitted; synthetic data sits above them: dynax/_synthetic/ imports the
    # model layer, never the other way round (tests/test_layers.py checks every layer's imports).
    model = pathlib.Path(dynax.__file__).parent / "_model"
    importers = [str(path.relative_to(model)) for path in model.rglob("*.py") if "_synthetic" in path.read_text()]
    assert importers == []


def test_multisine_rms_and_band():
    dt = 0.01
    ts = jnp.arange(6000) * dt
    u = np.asarray(synthetic.multisine(ts, 2, seed=3, amplitude=1.5, band_hz=(0.2, 2.0)))
    assert u.shape == (6000, 2)
    np.testing.assert_allclose(np.sqrt(np.mean(u**2, axis=0)), 1.5, rtol=1e-12)
    power = np.abs(np.fft.rfft(u, axis=0)) ** 2
    f = np.fft.rfftfreq(6000, dt)
    inside = (f >= 0.15) & (f <= 2.1)
    # Leakage aside, the power lies in the band (the tones are not on the FFT grid).
    assert power[inside].sum() / power.sum() > 0.97


def test_filtered_noise_is_stationary_with_the_given_spread_and_correlation():
    rng = np.random.default_rng(0)
    dt, cutoff, sigma = 0.01, 3.0, [0.5, 2.0]
    e = synthetic.filtered_noise(rng, 200_000, dt, sigma, cutoff)
    np.testing.assert_allclose(e.std(axis=0), sigma, rtol=0.03)
    a = np.exp(-2 * np.pi * cutoff * dt)
    lag1 = [np.corrcoef(e[1:, k], e[:-1, k])[0, 1] for k in range(2)]
    np.testing.assert_allclose(lag1, a, atol=0.01)
    # Stationary from the first sample: the early samples already have the full spread.
    many = np.stack(
        [synthetic.filtered_noise(np.random.default_rng(s), 3, dt, [1.0], cutoff)[0, 0] for s in range(4000)]
    )
    assert 0.93 < many.std() < 1.07


def test_synthetic_trajectory_noise_level_and_hidden_states():
    truth = Extended(Acrobot(), (CoulombFriction(1, 0.2), dynax.InputLag(0, 0.05)))
    clean = synthetic.synthetic_trajectory(truth, duration=5.0, seed=4, noise=(0.0, 0.0, 0.0, 0.0))
    noisy = synthetic.synthetic_trajectory(truth, duration=5.0, seed=4)
    assert clean.state_names == ("q1", "q2", "dq1", "dq2")  # the lag's internal state is not recorded
    e = np.asarray(noisy.xs - clean.xs)
    np.testing.assert_allclose(e.std(axis=0), [1e-3, 1e-3, 1e-2, 1e-2], rtol=0.1)
    np.testing.assert_array_equal(noisy.us, clean.us)


def _scipy_closed_loop(truth, controller, x0, dt, references, excitation, wind):
    """The closed loop integrated by scipy's DOP853 interval by interval: a reference independent of
    dynax's integrators (the input held over each sample interval, as on a real controller)."""
    f = jax.jit(truth.vector_field)
    feedback = jax.jit(controller)
    x = np.asarray(x0)
    xs, us = [], []
    for k in range(references.shape[0]):
        u = np.clip(np.asarray(feedback(jnp.asarray(x[:13]), references[k])) + np.asarray(excitation[k]), -1.0, 1.0)
        ua = jnp.asarray(np.concatenate([u, np.asarray(wind[k])])[: truth.n_inputs])
        xs.append(x)
        us.append(u)
        sol = scipy.integrate.solve_ivp(
            lambda t, y: np.asarray(f(t, jnp.asarray(y), ua)), (0.0, dt), x, method="DOP853", rtol=1e-11, atol=1e-12
        )
        x = sol.y[:, -1]
    return np.stack(xs), np.stack(us)


def test_fly_matches_an_independent_integrator():
    truth = synthetic.HelicopterTruth()
    controller = synthetic.FlightController()
    dt, n = 0.01, 150
    rng = np.random.default_rng(1)
    references = np.zeros((n, 13))
    references[:, 4] = 1.0
    references[:, 0:3] = [0.8, -0.5, 0.2]  # a waypoint away from the start: the loop has work to do
    references[:, 3] = 0.4
    excitation = synthetic.filtered_noise(rng, n, dt, [0.05] * 4, 3.0)
    wind = synthetic.filtered_noise(rng, n, dt, [0.5] * 3, 0.1)
    x0 = jnp.concatenate([hover_state(dtype=jnp.float64), jnp.zeros(2)])
    xs, us = synthetic.fly(
        truth, controller, x0, dt, jnp.asarray(references), jnp.asarray(excitation), jnp.asarray(wind)
    )
    ref_xs, ref_us = _scipy_closed_loop(truth, controller, x0, dt, jnp.asarray(references), excitation, wind)
    assert np.abs(ref_xs[-1, 0:3] - ref_xs[0, 0:3]).max() > 0.05  # it moved
    # RK4 with 4 substeps of 2.5 ms against DOP853 at 1e-11: agreement to integration error.
    np.testing.assert_allclose(np.asarray(xs), ref_xs, atol=1e-6)
    np.testing.assert_allclose(np.asarray(us), ref_us, atol=1e-6)


def test_flight_recording_noise_and_hemisphere():
    clean = synthetic.generate_helicopter_flight("hover", 1.5, seed=7, measurement_noise=False)
    noisy = synthetic.generate_helicopter_flight("hover", 1.5, seed=7)
    assert clean.state_names == dynax.Helicopter.state_names and clean.xs.shape == (150, 13)
    assert np.all(np.asarray(noisy.xs[:, 3]) >= 0.0)  # qw >= 0: q and -q are one attitude
    np.testing.assert_allclose(np.linalg.norm(np.asarray(noisy.xs[:, 3:7]), axis=1), 1.0, atol=1e-12)
    e = np.asarray(noisy.xs - clean.xs)
    np.testing.assert_allclose(e[:, 0:3].std(), 0.005, rtol=0.1)
    np.testing.assert_allclose(e[:, 7:10].std(), 0.02, rtol=0.1)
    np.testing.assert_allclose(e[:, 10:13].std(), 0.01, rtol=0.1)
    np.testing.assert_array_equal(noisy.us, clean.us)  # noise is measurement noise only


def test_demo_data_hides_the_term_in_the_truth():
    truth, train, validation = synthetic.demo_data(CoulombFriction(1, 0.3), seed=0, train_s=2.0, validation_s=1.0)
    assert truth.labels == ("coulomb_friction@q2",)
    assert train.ts.shape == (201,) and validation.ts.shape == (100,)
    assert float(train.ts[-1]) < float(validation.ts[0])
    assert float(truth.system.theta1) != float(Acrobot().theta1)  # the rig differs from the datasheet model
