"""`synthetic_trajectory`: measured data from a truth system, with a hidden effect and noise."""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._data._trajectory import Trajectory
from .._model._extensions import Extended
from .._model._system import AbstractSystem
from .._simulate import FixedGrid, simulate
from ._excitation import Multisine


def synthetic_trajectory(
    truth: AbstractSystem,
    *,
    duration: float,
    dt: float = 0.01,
    seed: int = 0,
    excitation: Multisine = Multisine(),
    noise: tuple[float, ...] | None = None,
    x0: Float[Array, " n_states"] | None = None,
    system_name: str = "",
) -> Trajectory:
    """Simulate `truth` under a random multisine and record it as measured data with noise.

    The rollout uses 4 Runge-Kutta substeps per sample (the truth is integrated finer than any
    model the diagnosis fits). Internal states of an `Extended` truth (lags, delays) are not
    recorded, just as on a real rig.

    **Arguments:**

    - `truth`: the system that generates the data (e.g. `Extended(Acrobot(), (CoulombFriction(1, 0.2),))`).
    - `duration` [s], `dt` sample interval [s], `seed` for excitation and noise.
    - `excitation`: the input, a `Multisine` (default: RMS 1.5 per input over 0.1 to 2 Hz).
    - `noise`: standard deviation per measured state (default 1e-3 for positions, 1e-2 for
      velocities).
    - `x0`: initial measured state (default at rest hanging down).
    - `system_name`: recorded in the `Trajectory` (its `source` is `""`; `dataclasses.replace` sets
      one).

    **Returns:** a `Trajectory` of the measured states and the recorded inputs.
    """
    nominal = truth.system if isinstance(truth, Extended) else truth
    names = tuple(nominal.state_names)
    n = len(names)
    ts = jnp.arange(int(round(duration / dt)) + 1) * dt
    us = excitation(ts, truth.n_inputs, seed)
    if x0 is None:
        x0 = jnp.zeros(n)
    x0 = jnp.asarray(x0, ts.dtype)
    full_x0 = truth.initial_state(x0, us[0]) if isinstance(truth, Extended) else x0
    xs = simulate(truth, full_x0, ts, us, method=FixedGrid(substeps=4)).xs[:, :n]
    if noise is None:
        noise = tuple(1e-2 if s.startswith("d") else 1e-3 for s in names)
    noise = jnp.asarray(noise, xs.dtype)
    xs = xs + noise[None, :] * jax.random.normal(jax.random.PRNGKey(seed + 7919), xs.shape, xs.dtype)
    return Trajectory(ts, xs, us, names, tuple(nominal.input_names), system_name)
