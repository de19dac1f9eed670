"""The float64 policy: dynax never switches JAX to float64 itself, but says so where it matters.

JAX computes in float32 unless `jax.config.update("jax_enable_x64", True)` is called before any
array is made (STYLE: the library never changes global config; the CLI and the experiments do).
Identification and diagnosis solve least-squares problems and compare small differences of
simulated states, which float32's 7 digits do not resolve reliably, so their entry points warn,
once per process and kind of work, with a `PrecisionWarning` naming the switch. Measured times are
kept in float64 on the host (`load_trajectory`, `resample`) whatever JAX's mode, and a record whose
times float32 cannot resolve (a 20-minute record at 1 kHz: float32 resolves 1200 s only to 0.12 ms)
is warned about by name when it is loaded in float32 mode.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np

ENABLE_X64 = 'jax.config.update("jax_enable_x64", True)'
_WARNED: set[str] = set()


class PrecisionWarning(UserWarning):
    """dynax is running, or about to run, work that needs float64 in float32."""


def x64_enabled() -> bool:
    """Whether JAX makes float64 arrays (`jax_enable_x64`)."""
    return jnp.zeros((), dtype=float).dtype == jnp.float64


def warn_if_float32(work: str, *, stacklevel: int = 3) -> None:
    """Warn once per process and `work` (e.g. `"identification"`) when JAX is in float32 mode."""
    if x64_enabled() or work in _WARNED:
        return
    _WARNED.add(work)
    warnings.warn(
        f"dynax: {work} is running in float32 because JAX's float64 mode is off; least squares and "
        f"simulation-error comparisons lose digits (condition numbers above ~1e3 are unreliable). "
        f"Call {ENABLE_X64} at the start of your program, before any JAX array is made. "
        f"(The command line does this itself.)",
        PrecisionWarning,
        stacklevel=stacklevel,
    )


def float32_time_resolution(ts: np.ndarray) -> tuple[float, float]:
    """(resolution of the largest |t| in float32 [s], shortest sample interval [s]) of host times `ts`."""
    ts = np.asarray(ts, dtype=np.float64)
    t_max = float(np.max(np.abs(ts))) if ts.size else 0.0
    shortest = float(np.min(np.diff(ts))) if ts.size > 1 else np.inf
    return float(np.spacing(np.float32(t_max))), shortest


def check_times_for_float32(ts: np.ndarray, source: str) -> None:
    """Warn (naming `source`) when JAX is in float32 and float32 resolves the times to worse than 1 % of a step."""
    if x64_enabled():
        return
    resolution, shortest = float32_time_resolution(ts)
    if resolution > 0.01 * shortest:
        warnings.warn(
            f"dynax: {source}: in float32 the times (up to {float(np.max(np.abs(ts))):.6g} s) are resolved only to "
            f"{resolution:.2g} s, {resolution / shortest:.0%} of the shortest sample interval {shortest:.3g} s; "
            f"the trajectory keeps its times in float64 on the host, but computations on the device will see a "
            f"jittered grid. Call {ENABLE_X64} first.",
            PrecisionWarning,
            stacklevel=3,
        )


def host_times(ts) -> np.ndarray | jax.Array:
    """Times as a float64 numpy array when concrete (a traced array is returned as it is)."""
    if isinstance(ts, jax.core.Tracer):
        return ts
    return np.asarray(ts, dtype=np.float64)
