"""`simulation_error` (and the output-error fit) start a model's internal states along the record before each window.

The record is made outside dynax: a unit mass with viscous damping driven through a first-order lag
$\\tau \\dot a = u - a$, integrated exactly over the zero-order-hold input (the matrix exponential of the
augmented linear system). Scored by the true lagged model, a window whose lag starts at rest under the input in
force starts with the wrong applied force; started along the half second before it, with the right one.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.linalg import expm

import dynax

DT, TAU, MASS, VISCOUS = 0.01, 0.1, 1.0, 2.0


def lagged_axis_record(n=600, seed=0) -> dynax.Trajectory:
    """`q, dq` of $m \\ddot q = a - F_v \\dot q$, $\\tau \\dot a = u - a$ under a random-phase multisine `u` (held
    over each sample interval), exact to rounding; the lag starts at rest under the first input."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    f, phase = rng.uniform(0.5, 4.0, 12), rng.uniform(0, 2 * np.pi, 12)
    u = np.sin(2 * np.pi * f[None, :] * t[:, None] + phase).sum(axis=1)
    u = 2.0 * u / u.std()
    # state (q, dq, a), input u: d/dt = A s + B u
    a_mat = np.array([[0.0, 1.0, 0.0], [0.0, -VISCOUS / MASS, 1.0 / MASS], [0.0, 0.0, -1.0 / TAU]])
    b_vec = np.array([0.0, 0.0, 1.0 / TAU])
    big = np.zeros((4, 4))
    big[:3, :3], big[:3, 3] = a_mat, b_vec
    step = expm(big * DT)
    phi, gamma = step[:3, :3], step[:3, 3]
    s = np.array([0.0, 0.0, u[0]])
    out = [s]
    for k in range(n - 1):
        s = phi @ s + gamma * u[k]
        out.append(s)
    xs = np.asarray(out)[:, :2]
    return dynax.Trajectory(jnp.asarray(t), jnp.asarray(xs), jnp.asarray(u[:, None]), ("q", "dq"), ("force",))


def test_a_lagged_model_starts_each_window_with_the_lag_the_record_implies():
    record = lagged_axis_record()
    axis = dynax.LinearAxis(mass=MASS, viscous=VISCOUS, coulomb=0.0, offset=0.0)
    lagged = dynax.Extended(axis, (dynax.InputLag(0, TAU),))  # pyright: ignore[reportCallIssue]
    result = dynax.simulation_error(lagged, record, horizons_s=(0.1, 0.5), stride=10)
    errors = np.asarray(result.errors)  # (window, step, state)
    starts = np.asarray(result.starts)
    # The lag at rest under the input in force (no history) misses the applied force by |u - a| at the start:
    # the speed error a tenth of a second in is ~ 0.05 * |u - a| (tens of mm/s here).
    early = errors[:, 1:11, 1]
    rest = np.sqrt(np.mean(early**2))
    # Started at rest under the input half a second before the window and integrated along the recorded inputs, the
    # lag keeps exp(-0.5 / tau) = 0.7 % of that start's error (0.45 mm/s RMS here; 67 mm/s started at rest at the
    # window's first sample).
    assert rest < 1e-3, f"speed error over the first 0.1 s of each window: {rest:.3g} m/s RMS"
    # Every window, also those of the first half second (history padded with the record's first sample, where the
    # lag rests under the first input as the record's does).
    assert np.all(np.abs(early) < 3e-3), f"worst window starting at {starts[np.argmax(np.abs(early).max(1))]}"
    # Still the same windows as a model without internal states (the nominal scored as before).
    plain = dynax.simulation_error(axis, record, horizons_s=(0.1, 0.5), stride=10)
    assert np.array_equal(np.asarray(plain.starts), starts)
    # The nominal (no lag) is far off at the start: the measure above can fail.
    assert np.sqrt(np.mean(np.asarray(plain.errors)[:, 1:11, 1] ** 2)) > 10 * rest


def test_the_output_error_fit_starts_each_segment_with_the_lag_the_record_implies():
    record = lagged_axis_record()
    start = dynax.Extended(  # pyright: ignore[reportCallIssue]
        dynax.LinearAxis(mass=1.5, viscous=1.0, coulomb=0.0, offset=0.0), (dynax.InputLag(0, TAU),)
    )
    spec = jax.tree.map(lambda _: False, start)
    spec = eqx.tree_at(lambda s: (s.system.mass, s.system.viscous), spec, (True, True))
    method = dynax.SimulationFit(segment_s=0.3, fit_initial_states=False)
    solution = dynax.fit_simulation_error(start, record, method, filter_spec=spec, progress=False)
    # Each 0.3 s segment's lag started at rest under its first input took the fit to a mass of 1.9 and a damping of
    # 2.1 (truth 1 and 2); started along the half second before the segment, 0.9994 and 2.012.
    np.testing.assert_allclose(np.asarray(solution.value), [MASS, VISCOUS], rtol=0.02)


def noisy(record: dynax.Trajectory, std, seed=1) -> dynax.Trajectory:
    xs = np.asarray(record.xs) + np.asarray(std) * np.random.default_rng(seed).normal(size=record.xs.shape)
    return dynax.Trajectory(record.ts, jnp.asarray(xs), record.us, record.state_names, record.input_names)


def test_the_residual_scale_at_the_true_lagged_model_is_the_noise_level():
    from dynax.internal import record_residual_scale

    clean = lagged_axis_record()
    noise = np.array([5e-4, 5e-3])  # m, m/s
    record = noisy(clean, noise)
    lagged = dynax.Extended(  # pyright: ignore[reportCallIssue]
        dynax.LinearAxis(mass=MASS, viscous=VISCOUS, coulomb=0.0, offset=0.0), (dynax.InputLag(0, TAU),)
    )
    method = dynax.SimulationFit(segment_s=0.3, fit_initial_states=False)
    starts = np.asarray(clean.xs)[0 : len(clean) - 30 : 30]  # the true state at each 0.3 s segment's start
    sigma = record_residual_scale(lagged, jnp.asarray(starts), [record], noise, method)
    # Each segment's lag started along the half second before it, as the fit starts it: the residuals are the noise
    # (1.002 here; 22.9 with the lag at rest under each segment's first input, the lag's start error).
    np.testing.assert_allclose(sigma, [1.0], rtol=0.1)


def test_the_refinements_timed_inputs_start_the_lag_along_the_record():
    # `refine_by_simulation` fits its model behind `TimedInputs` (the input read `alpha` steps later); the wrapper
    # exposes what `complete_state` reads, so the segments' lag starts along the record as the bare model's does.
    from dynax.internal import TimedInputs, with_neighbour_inputs

    record = lagged_axis_record()
    start = dynax.Extended(  # pyright: ignore[reportCallIssue]
        dynax.LinearAxis(mass=1.5, viscous=1.0, coulomb=0.0, offset=0.0), (dynax.InputLag(0, TAU),)
    )
    timed = TimedInputs(start, jnp.zeros(()))  # pyright: ignore[reportCallIssue]
    spec = jax.tree.map(lambda _: False, timed)
    spec = eqx.tree_at(lambda s: (s.system.system.mass, s.system.system.viscous, s.alpha), spec, (True, True, True))
    method = dynax.SimulationFit(segment_s=0.3, fit_initial_states=False)
    solution = dynax.fit_simulation_error(
        timed, [with_neighbour_inputs(record)], method, filter_spec=spec, progress=False
    )
    mass, viscous, alpha = np.asarray(solution.value)
    # 0.9988, 2.017 and alpha -0.017 (the record's hold is exact: 0); with the lag at rest under each segment's first
    # input, 1.50, 0.94 and alpha 4.6 (at the wrapper's reach of 3 steps).
    np.testing.assert_allclose([mass, viscous], [MASS, VISCOUS], rtol=0.02)
    assert abs(alpha) < 0.1


def test_horizon_errors_are_window_simulation_errors_for_a_lagged_model():
    from dynax.internal import horizon_errors, window_simulation_errors

    record = noisy(lagged_axis_record(), [5e-4, 5e-3])
    lagged = dynax.Extended(  # pyright: ignore[reportCallIssue]
        dynax.LinearAxis(mass=MASS, viscous=VISCOUS, coulomb=0.0, offset=0.0), (dynax.InputLag(0, TAU),)
    )
    candidates = np.round(np.arange(0.1, 1.0 + 1e-9, 0.05), 6)
    expected = np.asarray(window_simulation_errors(lagged, record, candidates, stride=5))
    # Both start the lag along the half second before each window (without it, up to 0.29 m/s apart).
    np.testing.assert_array_equal(horizon_errors(lagged, record, candidates, 5, DT), expected)
