"""Closed-loop helicopter flights recorded as measured data: the learning sets and the diagnosis flights.

`fly` closes the loop around a truth system with `FlightController` (plus low-pass filtered
excitation on every input and gusts on the truth's wind inputs); `generate_helicopter_flight`
produces the two data sets of Abbeel, Ganapathi and Ng (2005), `"hover"` and `"aerobatic"`;
`helicopter_flight` flies waypoints with a heading sweep, for telling world-fixed from body-fixed
effects in a diagnosis.

??? cite "References"

    P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to modeling
    helicopters", NIPS 18, 2005.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._control._closed_loop import simulate_closed_loop
from .._data._trajectory import Trajectory
from .._model._helicopter import (
    HELICOPTER_INPUT_NAMES,
    HELICOPTER_STATE_NAMES,
    hover_state,
    quaternion_from_euler,
    quaternion_multiply,
)
from .._model._system import AbstractSystem
from .._simulate import FixedGrid, RK4
from ._excitation import filtered_noise
from ._flight_controller import FlightController
from ._helicopter_truth import HelicopterTruth


@eqx.filter_jit
def fly(
    truth: AbstractSystem,
    controller: FlightController,
    x0: Float[Array, " n_states"],
    dt: float,
    references: Float[Array, "time 13"],
    excitation: Float[Array, "time 4"],
    wind: Float[Array, "time 3"],
    substeps: int = 4,
) -> tuple[Float[Array, "time n_states"], Float[Array, "time 4"]]:
    """Fly `truth` in closed loop with `controller` plus additive `excitation`, with
    `dynax.control.simulate_closed_loop`.

    `truth` is a `HelicopterTruth` or any system whose first 13 states and 4 inputs are the
    helicopter's (a `Helicopter` flies the same references in still air).

    At each sample the controller reads the state, the excitation is added and the inputs are
    clipped to $[-1, 1]$ and held over the interval, integrated by `substeps` steps of the classical Runge-Kutta
    method (`dynax.RK4`). Reference
    rows are `(x, y, z, yaw, qw, qx, qy, qz, p, q, r, collective, manoeuvre)`: position and heading
    for position hold, or (when `manoeuvre > 0.5`) the attitude, body-rate and collective references.

    **Returns:** the states `(time, n_states)` and the applied inputs `(time, 4)`.
    """

    n = references.shape[0]
    dtype = jnp.result_type(x0, float)
    ts = jnp.arange(n + 1, dtype=dtype) * dt

    def feedback(t, x):
        k = jnp.minimum(jnp.round(t / dt).astype(int), n - 1)
        u = jnp.clip(controller(x[:13], references[k]) + excitation[k], -1.0, 1.0)
        # A system without wind inputs (e.g. a `Helicopter`) flies in still air.
        return jnp.concatenate([u, wind[k]])[: truth.n_inputs]

    run = simulate_closed_loop(truth, feedback, x0, ts, method=FixedGrid(RK4(), substeps=substeps))
    return run.xs[:n], run.us[:n, :4]


def _integrate_body_rates(quat0, omegas, dt):
    """Integrate a body-rate reference into an attitude reference (numpy, exact per step)."""
    quats = np.zeros((len(omegas), 4))
    q = np.asarray(quat0, float)
    for k, w in enumerate(omegas):
        quats[k] = q
        angle = np.linalg.norm(w) * dt
        axis = w / (np.linalg.norm(w) + 1e-15)
        dq = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
        q = _np_qmul(q, dq)
        q = q / np.linalg.norm(q)
    return quats


def _references(kind, n, dt, rng, hover_collective):
    """Reference rows for `fly`: waypoints in hover; rolls, flips and funnels in the aerobatic set."""
    refs = np.zeros((n, 13))
    refs[:, 4] = 1.0
    k = 0
    waypoint = np.zeros(3)
    yaw = 0.0
    manoeuvres = ("roll", "flip", "funnel", "roll_left", "flip_back")
    m = 0
    while k < n:
        if kind == "hover" or m % 2 == 0:
            # Position hold at a new waypoint (a few metres away) and heading.
            length = int(rng.uniform(3.0, 6.0) / dt) if kind == "hover" else int(rng.uniform(4.0, 5.0) / dt)
            waypoint = waypoint + rng.uniform(-1.5, 1.5, 3) * np.array([1, 1, 0.5])
            yaw = yaw + rng.uniform(-0.5, 0.5)
            seg = slice(k, min(n, k + length))
            refs[seg, 0:3] = waypoint
            refs[seg, 3] = yaw
            refs[seg, 12] = 0.0
            k += length
            m += 1
            continue
        name = manoeuvres[(m // 2) % len(manoeuvres)]
        m += 1
        quat0 = np.asarray(quaternion_from_euler(0.0, 0.0, yaw))
        if name in ("roll", "roll_left", "flip", "flip_back"):
            duration = rng.uniform(2.2, 2.8)
            length = int(duration / dt)
            axis = 0 if name.startswith("roll") else 1
            # Trapezoidal rate profile (0.4 s ramps) whose integral is one full turn.
            t = (np.arange(length) + 0.5) * dt
            shape = np.clip(np.minimum(t, duration - t) / 0.4, 0.0, 1.0)
            profile = shape * 2 * np.pi / (shape.sum() * dt) * (-1 if name in ("roll_left", "flip_back") else 1)
            omegas = np.zeros((length, 3))
            omegas[:, axis] = profile
            quats = _integrate_body_rates(quat0, omegas, dt)
            angle = np.cumsum(profile) * dt
            collective = hover_collective * np.cos(angle)
        else:  # funnel: tilted, yawing steadily, so the thrust vector sweeps a cone
            duration = rng.uniform(4.0, 6.0)
            length = int(duration / dt)
            tilt = rng.uniform(0.4, 0.6)
            yaw_rate = 2 * np.pi / 3.0
            t = np.arange(length) * dt
            ramp = np.clip(t / 0.5, 0, 1) * np.clip((duration - t) / 0.5, 0, 1)
            quats = np.asarray(
                jax.vmap(quaternion_from_euler)(
                    jnp.asarray(tilt * ramp), jnp.zeros(length), jnp.asarray(yaw + yaw_rate * t)
                )
            )
            qdot = np.gradient(quats, dt, axis=0)
            conj = quats * np.array([1, -1, -1, -1])
            omegas = 2 * _batch_qmul(conj, qdot)[:, 1:]
            collective = hover_collective + (9.81 / np.cos(tilt * ramp) - 9.81) / 42.15
            yaw = yaw + yaw_rate * duration
        seg = slice(k, min(n, k + length))
        size = seg.stop - seg.start
        refs[seg, 0:3] = waypoint
        refs[seg, 3] = yaw
        refs[seg, 4:8] = quats[:size]
        refs[seg, 8:11] = omegas[:size]
        refs[seg, 11] = collective[:size]
        refs[seg, 12] = 1.0
        k += length
    return refs


def generate_helicopter_flight(
    kind: str,
    duration: float,
    *,
    seed: int = 0,
    dt: float = 0.01,
    truth: AbstractSystem | None = None,
    controller: FlightController | None = None,
    measurement_noise: bool = True,
) -> Trajectory:
    r"""Fly the truth simulator and record a data set like the paper's.

    - `"hover"`: position hold around waypoints a few metres apart, excitation (low-pass filtered
      at 3 Hz) of standard deviation 0.06 on the cyclic and tail and 0.05 on the collective, gusts of
      0.3 m/s.
    - `"aerobatic"`: alternating position-hold recoveries and manoeuvres (full rolls and flips in
      both directions, funnels tilted 25 to 35 degrees), excitation 0.08, gusts of 0.5 m/s.

    The recorded states carry small measurement noise (`measurement_noise=True`): 5 mm in position,
    2 mrad in attitude, 0.02 m/s in velocity and 0.01 rad/s in rate, about what a state estimator
    on a model helicopter delivers.

    **Arguments:**

    - `kind`: `"hover"` or `"aerobatic"`.
    - `duration`: seconds of flight (the first 2 s settle from the start state and are kept).
    - `seed`: random seed of the excitation, gusts, manoeuvre schedule and noise.
    - `dt`: sample interval [s] (default 0.01, 100 Hz).
    - `truth`, `controller`: override the simulator (e.g. a `Helicopter` to fly a learned or the
      Tempest model itself) or the controller.
    - `measurement_noise`: whether to add the measurement noise above.

    **Returns:** a `dynax.Trajectory` with the contract's helicopter columns (float64 if enabled).
    """
    if kind not in ("hover", "aerobatic"):
        raise ValueError(f"generate_helicopter_flight: `kind` must be 'hover' or 'aerobatic', got {kind!r}")
    if duration <= 10 * dt:
        raise ValueError(f"generate_helicopter_flight: `duration` must exceed 10 samples, got {duration}")
    truth = HelicopterTruth() if truth is None else truth
    controller = FlightController() if controller is None else controller
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt))
    dtype = jnp.result_type(float)
    aerobatic = kind == "aerobatic"
    sigma = [0.08] * 4 if aerobatic else [0.06, 0.06, 0.06, 0.05]
    excitation = filtered_noise(rng, n, dt, sigma, cutoff_hz=3.0)
    gust_sigma = 0.5 if aerobatic else 0.3
    wind = filtered_noise(rng, n, dt, [gust_sigma] * 3, cutoff_hz=1 / (2 * np.pi * 2.0))
    references = _references(kind, n, dt, rng, controller.hover_collective)
    x0 = jnp.concatenate([hover_state(dtype=dtype), jnp.zeros(truth.n_states - 13, dtype)])
    xs, us = fly(
        truth,
        controller,
        x0,
        dt,
        jnp.asarray(references, dtype),
        jnp.asarray(excitation, dtype),
        jnp.asarray(wind, dtype),
    )
    return _recorded(
        xs, us, dt, rng, measurement_noise, "generate_helicopter_flight", f"dynax truth simulator ({kind}, seed {seed})"
    )


class FlightPlan(eqx.Module):
    """What `helicopter_flight` flies: the heading sweep's `yaw_amplitude` [rad] (default 2.5), the
    standard deviation of the inputs' `excitation` (default 0.08) and the waypoints' `spread` [m]
    (default 1.0)."""

    yaw_amplitude: float = 2.5
    excitation: float = 0.08
    spread: float = 1.0


def helicopter_flight(
    truth: AbstractSystem,
    *,
    duration: float,
    dt: float = 0.02,
    seed: int = 0,
    plan: FlightPlan = FlightPlan(),
    controller: FlightController | None = None,
    noise: bool = True,
    source: str = "",
) -> Trajectory:
    r"""Fly a helicopter `truth` in closed loop and record it as measured data, with heading changes.

    The truth simulator's cascaded controller (`FlightController`) holds position near waypoints
    (uniform within `spread` north and east and 0.3 `spread` down, a new one every 3 s; a wide
    spread makes faster flight) while the heading sweeps sinusoidally over $\pm$`yaw_amplitude`
    (one period per `duration`), with low-pass filtered excitation (3 Hz, standard deviation
    `excitation`) on all inputs. The heading sweep is what tells a world-fixed effect (wind) from a
    body-fixed one (a body bias); it stays inside $(-\pi, \pi)$ so the recorded quaternion needs no
    sign flips.

    **Arguments:**

    - `truth`: a `Helicopter` or an `Extended` helicopter (e.g. with a hidden `Wind`).
    - `duration` [s], `dt` [s], `seed`.
    - `plan`: a `FlightPlan`: `yaw_amplitude` [rad], `excitation`, `spread` [m].
    - `controller`: default `FlightController()`; a larger `max_position_error` flies faster
      between waypoints.
    - `noise`: add measurement noise (5 mm, 2 mrad, 0.02 m/s, 0.01 rad/s, as
      `generate_helicopter_flight`).
    - `source`: recorded in the `Trajectory`.

    **Returns:** a `Trajectory` with the contract's helicopter columns.
    """
    yaw_amplitude, excitation, spread = plan.yaw_amplitude, plan.excitation, plan.spread
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt))
    dtype = jnp.result_type(float)
    t = np.arange(n) * dt
    refs = np.zeros((n, 13))
    refs[:, 4] = 1.0
    segment = max(1, int(round(3.0 / dt)))
    for k in range(0, n, segment):
        refs[k : k + segment, 0:3] = spread * rng.uniform(-1.0, 1.0, 3) * np.array([1.0, 1.0, 0.3])
    refs[:, 3] = yaw_amplitude * np.sin(2 * np.pi * t / duration + rng.uniform(-0.3, 0.3))
    kick = filtered_noise(rng, n, dt, [excitation] * 4, cutoff_hz=3.0)
    x0 = jnp.concatenate([hover_state(yaw=float(refs[0, 3]), dtype=dtype), jnp.zeros(truth.n_states - 13, dtype)])
    xs, us = fly(
        truth,
        FlightController() if controller is None else controller,
        x0,
        dt,
        jnp.asarray(refs, dtype),
        jnp.asarray(kick, dtype),
        jnp.zeros((n, 3), dtype),
    )
    return _recorded(xs, us, dt, rng, noise, "helicopter_flight", source)


def _recorded(xs, us, dt, rng, noise, caller, source) -> Trajectory:
    """The recorded data set of a flight: the 13 contract states on the hemisphere $q_w \\ge 0$ (q and
    -q are one attitude), with measurement noise of 5 mm, 2 mrad, 0.02 m/s and 0.01 rad/s if `noise`."""
    xs = np.array(xs[:, :13], float)
    n = xs.shape[0]
    if not np.all(np.isfinite(xs)) or np.abs(xs).max() > 1e4:
        raise RuntimeError(f"{caller}: the closed-loop flight diverged")
    xs[:, 3:7] *= np.sign(xs[:, 3:4] + 1e-12)
    if noise:
        e = rng.standard_normal((n, 13))
        xs[:, 0:3] += 0.005 * e[:, 0:3]
        small = np.concatenate([np.ones((n, 1)), 0.5 * 0.002 * e[:, 4:7]], axis=1)
        xs[:, 3:7] = _batch_qmul(xs[:, 3:7], small)
        xs[:, 3:7] /= np.linalg.norm(xs[:, 3:7], axis=1, keepdims=True)
        xs[:, 7:10] += 0.02 * e[:, 7:10]
        xs[:, 10:13] += 0.01 * e[:, 10:13]
    dtype = jnp.result_type(float)
    ts = np.arange(n) * dt
    return Trajectory(
        jnp.asarray(ts, dtype),
        jnp.asarray(xs, dtype),
        jnp.asarray(np.asarray(us), dtype),
        HELICOPTER_STATE_NAMES,
        HELICOPTER_INPUT_NAMES,
        "helicopter",
        source,
    )


def _np_qmul(a, b):
    aw, av, bw, bv = a[0], a[1:], b[0], b[1:]
    return np.concatenate([[aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)])


def _batch_qmul(a, b):
    return np.asarray(jax.vmap(quaternion_multiply)(jnp.asarray(a), jnp.asarray(b)))
