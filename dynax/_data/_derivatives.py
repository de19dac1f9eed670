"""Derivative estimation and filtering of measured signals.

Central and backward differences work on irregular grids. Savitzky-Golay and Butterworth filters assume a uniform
grid: resample irregular records first with `resample` (they raise otherwise).
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float
import numpy as np

from .._errors import UsageError
from .._precision import host_times
from ._trajectory import Trajectory


def central_difference(ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."]) -> Float[Array, "time ..."]:
    r"""Second-order central differences $dy/dt$ on a possibly irregular grid (one-sided at the ends).

    `jnp.gradient(ys, ts, axis=0)`: on an irregular grid, the exact derivative of the quadratic
    through each three neighbouring samples (as `numpy.gradient`), first-order one-sided at the two
    ends. Jittable, vmappable and differentiable. Concrete times are taken relative to the first
    sample in float64 on the host before they reach the device, so long records lose less in
    float32 (see the float64 policy in the docs).

    **Arguments:**

    - `ts`: sample times, shape `(time,)`, strictly increasing.
    - `ys`: samples, shape `(time, ...)`.

    **Returns:** $dy/dt$ at `ts`, same shape as `ys`.
    """
    ts, ys = _times_and_samples(ts, ys, "central_difference", 3)
    return jnp.gradient(ys, ts, axis=0)


def _times_and_samples(ts, ys, function: str, min_samples: int):
    """`(ts, ys)` as arrays, concrete times relative to the first sample (float64 on the host first)
    and in the samples' float type; `ValueError` naming `function` for mismatched or too few samples."""
    ts = host_times(ts)
    if not isinstance(ts, jax.core.Tracer):
        ts = ts - ts[0] if ts.ndim == 1 and ts.size else ts
    ts = jnp.asarray(ts)
    ys = jnp.asarray(ys)
    if ts.ndim != 1 or ys.shape[:1] != ts.shape or ts.shape[0] < min_samples:
        raise ValueError(
            f"{function}: need `ts` (time,) with time >= {min_samples} and `ys` (time, ...); got {ts.shape}, {ys.shape}"
        )
    return ts.astype(jnp.result_type(ys, float)), ys


def backward_difference(ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."]) -> Float[Array, "time ..."]:
    r"""Backward differences $(y_i - y_{i-1}) / (t_i - t_{i-1})$ on a possibly irregular grid.

    The velocity a motor driver or logger computes from an encoder, one sample at a time: the DFKI
    rig's logged `vel_meas` is exactly this difference of `pos_meas` on the logged time stamps (to
    round-off, all six runs in `shared/datasets`). It is the exact derivative at the midpoint
    $(t_{i-1} + t_i)/2$ of anything quadratic, so at $t_i$ it lags by half an interval. Its noise
    density from white encoder noise, $4 \sin^2(\pi f \Delta t) / \Delta t^2$ times the encoder's,
    rises to the Nyquist frequency, where a central difference's vanishes: the noise floor that
    `choose_filter` reads from the upper half of the band is then the noise the derivative carries
    at its largest. The first sample takes the second's value. Jittable, vmappable, differentiable;
    concrete times are taken relative to the first sample in float64 on the host (as
    `central_difference`).

    **Arguments:**

    - `ts`: sample times, shape `(time,)`, strictly increasing.
    - `ys`: samples, shape `(time, ...)`.

    **Returns:** $dy/dt$ at `ts`, same shape as `ys`.
    """
    ts, ys = _times_and_samples(ts, ys, "backward_difference", 2)
    dt = jnp.diff(ts)
    slopes = jnp.diff(ys, axis=0) / dt.reshape(dt.shape + (1,) * (ys.ndim - 1))
    return jnp.concatenate([slopes[:1], slopes], axis=0)


def _uniform_dt(ts, function):
    ts = np.asarray(ts)
    d = np.diff(ts)
    dt = float(np.median(d))
    if np.any(np.abs(d - dt) > 0.01 * dt):
        raise UsageError(
            f"{function}: the sampling is irregular (intervals {d.min():.3g} to {d.max():.3g} s); "
            "resample it first with dynax.resample(trajectory, dt)"
        )
    return dt


def savitzky_golay(
    ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."], *, window: int, order: int = 3, deriv: int = 0
) -> Float[Array, "time ..."]:
    """Savitzky-Golay smoothing or differentiation along time (uniform sampling).

    **Arguments:**

    - `ts`: uniform sample times, shape `(time,)`.
    - `ys`: samples, shape `(time, ...)`.
    - `window`: window length in samples (odd, > `order`).
    - `order`: polynomial order.
    - `deriv`: derivative order (0 smooths).

    **Returns:** the filtered signal or its `deriv`-th derivative, same shape as `ys`.

    ??? cite

        A. Savitzky and M. J. E. Golay, "Smoothing and differentiation of data by simplified least
        squares procedures", Analytical Chemistry 36(8), 1964.
    """
    if window % 2 == 0 or window <= order:
        raise UsageError(f"savitzky_golay: `window` must be odd and larger than `order`, got {window} (order {order})")
    dt = _uniform_dt(ts, "savitzky_golay")
    import scipy.signal  # lazily: keeps `import dynax` light

    out = scipy.signal.savgol_filter(np.asarray(ys), window, order, deriv=deriv, delta=dt, axis=0, mode="interp")
    return jax.device_put(out)  # not `jnp.asarray`: that compiles a copy for every new shape


def butterworth_filtfilt(
    ts: Float[ArrayLike, " time"], ys: Float[ArrayLike, "time ..."], *, cutoff_hz: float, order: int = 4
) -> Float[Array, "time ..."]:
    """Zero-phase low-pass Butterworth filter (forward-backward, `scipy.signal.sosfiltfilt`).

    The forward-backward pass doubles the effective order and cancels the phase, so filtered
    positions can be differentiated without a time shift (the usual recipe before inverse-dynamics
    identification).

    **Arguments:**

    - `ts`: uniform sample times, shape `(time,)`.
    - `ys`: samples, shape `(time, ...)`.
    - `cutoff_hz`: the -3 dB frequency of one pass [Hz], below the Nyquist frequency.
    - `order`: the filter order of one pass.

    **Returns:** the filtered signal, same shape as `ys`.
    """
    dt = _uniform_dt(ts, "butterworth_filtfilt")
    nyquist = 0.5 / dt
    if not 0 < cutoff_hz < nyquist:
        raise UsageError(f"butterworth_filtfilt: `cutoff_hz` must be in (0, {nyquist:g}) Hz, got {cutoff_hz}")
    import scipy.signal

    sos = scipy.signal.butter(order, cutoff_hz / nyquist, output="sos")
    return jnp.asarray(scipy.signal.sosfiltfilt(sos, np.asarray(ys), axis=0))


def resample(trajectory: Trajectory, dt: float) -> Trajectory:
    """Resample a trajectory onto a uniform grid of step `dt` from its first sample.

    States are interpolated linearly; inputs are resampled as the zero-order hold they are
    (the value in force at each new sample time).

    **Arguments:** `trajectory`; `dt` [s].

    **Returns:** a new `Trajectory` on the uniform grid.
    """
    if not dt > 0:
        raise UsageError(f"resample: `dt` must be positive, got {dt}")
    ts = np.asarray(trajectory.ts)
    grid = ts[0] + dt * np.arange(int(np.floor((ts[-1] - ts[0]) / dt + 1e-9)) + 1)
    xs = np.stack([np.interp(grid, ts, col) for col in np.asarray(trajectory.xs).T], axis=1)
    held = np.clip(np.searchsorted(ts, grid, side="right") - 1, 0, len(ts) - 1)
    us = np.asarray(trajectory.us)[held]
    return Trajectory(
        grid,
        jnp.asarray(xs),
        jnp.asarray(us),  # times stay float64 on the host
        trajectory.state_names,
        trajectory.input_names,
        trajectory.system,
        trajectory.source,
    )
