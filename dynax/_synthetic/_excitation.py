"""Excitation signals for synthetic experiments: random-phase multisines and low-pass filtered noise."""

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np


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


class Multisine(eqx.Module):
    """The settings of a random-phase multisine excitation (see `multisine`): RMS `amplitude` per
    input (default 1.5), `band_hz` (default 0.1 to 2 Hz) and `n_tones` (default 12)."""

    amplitude: float = 1.5
    band_hz: tuple[float, float] = (0.1, 2.0)
    n_tones: int = 12

    def __call__(self, ts: Float[Array, " time"], n_inputs: int, seed: int) -> Float[Array, "time n_inputs"]:
        """The excitation at `ts` for `n_inputs` inputs, drawn with `seed`."""
        return multisine(ts, n_inputs, seed=seed, amplitude=self.amplitude, band_hz=self.band_hz, n_tones=self.n_tones)


def filtered_noise(rng: np.random.Generator, n: int, dt: float, sigma: Sequence[float], cutoff_hz: float) -> np.ndarray:
    r"""First-order low-pass filtered Gaussian noise with stationary standard deviation `sigma`.

    $e_{k+1} = a e_k + \sqrt{1 - a^2}\,\sigma w_k$ with $a = e^{-2\pi f_c \Delta t}$, started from
    the stationary distribution (a discretised Ornstein-Uhlenbeck process).

    **Arguments:** `rng` a NumPy generator (consumed in a fixed order, so a seed gives one signal);
    `n` samples; `dt` [s]; `sigma` one standard deviation per channel; `cutoff_hz` $f_c$.

    **Returns:** a NumPy array of shape `(n, len(sigma))`.
    """
    a = np.exp(-2 * np.pi * cutoff_hz * dt)
    white = rng.standard_normal((n, len(sigma))) * np.sqrt(1 - a**2) * np.asarray(sigma)
    out = np.zeros_like(white)
    state = rng.standard_normal(len(sigma)) * np.asarray(sigma)
    for k in range(n):
        state = a * state + white[k]
        out[k] = state
    return out
