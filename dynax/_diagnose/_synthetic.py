"""Synthetic measured data with an effect hidden in it: dynax's own truth simulator for demos and tests."""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._data._trajectory import Trajectory
from .._model._extensions import Extended
from .._model._system import AbstractSystem
from .._simulate import FixedGrid, simulate


def multisine(
    ts: Float[Array, " time"],
    n_inputs: int,
    *,
    seed: int,
    amplitude: float,
    band_hz: tuple[float, float] = (0.1, 2.0),
    n_tones: int = 12,
) -> Float[Array, "time n_inputs"]:
    r"""A random-phase multisine excitation, $u(t) = \sum_k a \sin(2\pi f_k t + \phi_k)$ per input.

    Frequencies are spread log-uniformly over `band_hz`, phases are random (Schroeder-like crest
    factor on average); the signal is scaled to RMS `amplitude`.

    **Arguments:** `ts` sample times; `n_inputs`; `seed`; `amplitude` RMS per input; `band_hz`;
    `n_tones`.

    **Returns:** inputs of shape `(time, n_inputs)`.

    ??? cite

        R. Pintelon and J. Schoukens, *System Identification: A Frequency Domain Approach*,
        2nd ed., Wiley 2012, ch. 5 (multisine excitation).
    """
    rng = np.random.default_rng(seed)
    ts = np.asarray(ts)
    us = []
    for _ in range(n_inputs):
        freqs = np.exp(rng.uniform(np.log(band_hz[0]), np.log(band_hz[1]), n_tones))
        phases = rng.uniform(0, 2 * np.pi, n_tones)
        u = np.sin(2 * np.pi * freqs[None, :] * ts[:, None] + phases[None, :]).sum(axis=1)
        us.append(amplitude * u / np.sqrt(np.mean(u**2)))
    return jnp.asarray(np.stack(us, axis=1))


def synthetic_trajectory(
    truth: AbstractSystem,
    *,
    duration: float,
    dt: float = 0.01,
    seed: int = 0,
    amplitude: float = 1.5,
    band_hz: tuple[float, float] = (0.1, 2.0),
    noise: tuple[float, ...] | None = None,
    x0: Float[Array, " n_states"] | None = None,
    system_name: str = "",
    source: str = "",
) -> Trajectory:
    """Simulate `truth` under a random multisine and record it as measured data with noise.

    The rollout uses 4 Runge-Kutta substeps per sample (the truth is integrated finer than any
    model the diagnosis fits). Internal states of an `Extended` truth (lags, delays) are not
    recorded, just as on a real rig.

    **Arguments:**

    - `truth`: the system that generates the data (e.g. `Extended(Acrobot(), (CoulombFriction(1, 0.2),))`).
    - `duration` [s], `dt` sample interval [s], `seed` for excitation and noise.
    - `amplitude`: RMS of each input; `band_hz`: excitation band.
    - `noise`: standard deviation per measured state (default 1e-3 for positions, 1e-2 for
      velocities).
    - `x0`: initial measured state (default at rest hanging down).
    - `system_name`, `source`: recorded in the `Trajectory`.

    **Returns:** a `Trajectory` of the measured states and the recorded inputs.
    """
    nominal = truth.system if isinstance(truth, Extended) else truth
    names = tuple(nominal.state_names)
    n = len(names)
    ts = jnp.arange(int(round(duration / dt)) + 1) * dt
    us = multisine(ts, truth.n_inputs, seed=seed, amplitude=amplitude, band_hz=band_hz)
    if x0 is None:
        x0 = jnp.zeros(n)
    x0 = jnp.asarray(x0, ts.dtype)
    full_x0 = truth.initial_state(x0, us[0]) if isinstance(truth, Extended) else x0
    xs = simulate(truth, full_x0, ts, us, method=FixedGrid(substeps=4)).xs[:, :n]
    if noise is None:
        noise = tuple(1e-2 if s.startswith("d") else 1e-3 for s in names)
    noise = jnp.asarray(noise, xs.dtype)
    xs = xs + noise[None, :] * jax.random.normal(jax.random.PRNGKey(seed + 7919), xs.shape, xs.dtype)
    return Trajectory(ts, xs, us, names, tuple(nominal.input_names), system_name, source)


def helicopter_flight(
    truth: AbstractSystem,
    *,
    duration: float,
    dt: float = 0.02,
    seed: int = 0,
    yaw_amplitude: float = 2.5,
    excitation: float = 0.08,
    spread: float = 1.0,
    controller=None,
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
    - `yaw_amplitude` [rad], `excitation`, `spread` [m].
    - `controller`: default `FlightController()`; a larger `max_position_error` flies faster
      between waypoints.
    - `noise`: add measurement noise (5 mm, 2 mrad, 0.02 m/s, 0.01 rad/s, as
      `generate_helicopter_flight`).
    - `source`: recorded in the `Trajectory`.

    **Returns:** a `Trajectory` with the contract's helicopter columns.
    """
    from .._model._helicopter import hover_state, HELICOPTER_INPUT_NAMES, HELICOPTER_STATE_NAMES
    from .._model._helicopter_truth import _batch_qmul, _filtered_noise, FlightController, fly

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
    kick = _filtered_noise(rng, n, dt, [excitation] * 4, cutoff_hz=3.0)
    x0 = jnp.concatenate([hover_state(yaw=float(refs[0, 3]), dtype=dtype), jnp.zeros(truth.n_states - 13, dtype)])
    xs, us = fly(truth, FlightController() if controller is None else controller, x0, dt, jnp.asarray(refs, dtype), jnp.asarray(kick, dtype),
                 jnp.zeros((n, 3), dtype))
    xs = np.array(xs[:, :13], float)
    if not np.all(np.isfinite(xs)) or np.abs(xs).max() > 1e4:
        raise RuntimeError("helicopter_flight: the closed-loop flight diverged")
    xs[:, 3:7] *= np.sign(xs[:, 3:4] + 1e-12)
    if noise:
        e = rng.standard_normal((n, 13))
        xs[:, 0:3] += 0.005 * e[:, 0:3]
        small = np.concatenate([np.ones((n, 1)), 0.5 * 0.002 * e[:, 4:7]], axis=1)
        xs[:, 3:7] = _batch_qmul(xs[:, 3:7], small)
        xs[:, 3:7] /= np.linalg.norm(xs[:, 3:7], axis=1, keepdims=True)
        xs[:, 7:10] += 0.02 * e[:, 7:10]
        xs[:, 10:13] += 0.01 * e[:, 10:13]
    return Trajectory(jnp.asarray(t, dtype), jnp.asarray(xs, dtype), jnp.asarray(np.asarray(us), dtype),
                      HELICOPTER_STATE_NAMES, HELICOPTER_INPUT_NAMES, "helicopter", source)
