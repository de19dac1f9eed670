r"""Filter and derivative settings chosen from the data: noise level and signal band from spectra.

The least-squares models differentiate measured velocities; how hard to low-pass them is a property
of the record, not of the method. For each velocity channel the Welch power spectral density is
estimated; its **noise floor** is the median density over the upper half of the band (measurement
noise is white there, the motion of a mechanical system is not), and the **signal band** ends where
the density falls through `snr` times that floor for the last time (interpolated between Welch bins,
so that the edge does not jump a whole bin when one bin's density crosses the threshold). From these:

- cut-off $f_c$: the widest signal band over the velocity channels (no motion the data show is cut);
- order: the smallest Butterworth order $n$ (one pass; the filter runs forward and backward) at
  which the *differentiated* white noise let through above $f_c$ is under 10 % of the differentiated
  noise inside the band: $\int_1^\infty x^2 (1 + x^{2n})^{-2} dx < 0.1 \int_0^1 x^2 dx$;
- trim: one cut-off period $f_s / f_c$ of samples at each end, where the zero-phase filter's
  transient lives;
- decimation: the filtered equations carry nothing above $f_c$, so they are decimated (in parallel)
  to a Nyquist frequency of twice the cut-off, $\lfloor f_s / (4 f_c) \rfloor$, at most 13 (scipy's
  single-stage limit).

A record whose velocity noise is negligible gets no filter: when the noise the floor implies,
differenced into $\ddot q$ ($\sigma f_s/\sqrt 2$ for a central difference), is under 1 % of the
acceleration's rms, the errors-in-variables bias it causes relative to the accelerations (of the
order of its square) is under $10^{-4}$ and filtering would only distort the model (simulated data
fall here: their "floor" is the spectral tail of the motion itself). Relative to the forces the
parameters are read from it can be far larger (an arm swinging under gravity, a small torque
balancing large accelerations): `identify` checks the estimate against it and filters such a record
at its band where it does not hold (`dynax._identify._noise_bias`, `band_filter`).

??? cite

    P. D. Welch, "The use of fast Fourier transform for the estimation of power spectra", IEEE
    Trans. Audio and Electroacoustics 15(2), 1967; M. Gautier, "Dynamic identification of robots with
    power model", Proc. IEEE ICRA 1997 (cut-off a few times the motion's bandwidth, parallel
    decimation).
"""

from collections.abc import Callable
import contextlib
import contextvars
import dataclasses

import numpy as np

from .._context import set_within
from ._trajectory import Trajectory


@dataclasses.dataclass(frozen=True)
class FilterChoice:
    """The settings `choose_filter` picked for one record, and why.

    **Fields:**

    - `cutoff_hz`: Butterworth cut-off [Hz], or `None` when no noise was detected (no filter).
    - `order`: filter order of one pass.
    - `trim`: samples dropped at each end.
    - `decimate`: parallel decimation factor.
    - `sample_rate_hz`: the record's (median) sample rate.
    - `band_hz`: per velocity channel, the highest frequency with signal above the noise.
    - `noise_std`: per velocity channel, the white-noise standard deviation the floor implies.
    - `reason`: one sentence for reports.
    """

    cutoff_hz: float | None
    order: int
    trim: int
    decimate: int
    sample_rate_hz: float
    band_hz: dict[str, float]
    noise_std: dict[str, float]
    reason: str

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


MIN_SAMPLES = 128  # two Welch segments of 64 samples


def noise_floor_and_band(ys: np.ndarray, sample_rate_hz: float, *, snr: float = 100.0) -> tuple[float, float]:
    r"""The white-noise floor of a signal's spectrum and the edge of its signal band.

    **Arguments:** `ys` samples on a uniform grid, shape `(time,)`; `sample_rate_hz`; `snr`, the
    factor by which the density must exceed the floor to count as signal (default 100, 20 dB: far
    above the scatter of a Welch estimate averaged over many segments).

    **Returns:** `(floor, band_hz)`: the one-sided density of the floor [unit^2/Hz] and the
    frequency at which the density falls through `snr * floor` for the last time (the Nyquist
    frequency when there is no floor above round-off).

    The crossing lies between the last Welch bin above the threshold and the next one; it is placed
    where the log-density, interpolated linearly between those two bins, meets the threshold. The
    bins are $f_s / n_{seg}$ apart (1.6 Hz on a 6 s record at 5 ms), as wide as the band edge is
    high; taking the last bin above instead would make the edge jump by a whole bin when one bin's
    density moves from just above to just below the threshold (from 101 to 99 times the floor), and
    with it the cut-off and the velocity fit's window. On a steep spectrum the Hann window's leakage
    lifts the bins just above the edge, so the crossing comes out high by a fraction of a bin (0.54
    of a bin on a synthetic 4th-order spectrum, 6 s at 5 ms).
    """
    ys = np.asarray(ys, dtype=float)
    nperseg = int(min(len(ys), max(64, 2 ** int(np.floor(np.log2(len(ys) / 8))))))
    import scipy.signal  # lazily: keeps `import dynax` light

    f, p = scipy.signal.welch(ys - ys.mean(), fs=sample_rate_hz, nperseg=nperseg)
    nyquist = 0.5 * sample_rate_hz
    floor = float(np.median(p[f > 0.5 * nyquist]))
    peak = float(np.max(p[1:])) if len(p) > 1 else 0.0
    # No floor: the upper half of the band is round-off (relative 1e-20 in power, well below any sensor).
    if not floor > 1e-20 * peak:
        return floor, nyquist
    threshold = snr * floor
    above = np.flatnonzero((p > threshold) & (f > 0))
    if not above.size:
        return floor, float(f[1])
    k = int(above.max())
    if k + 1 >= len(f):
        return floor, float(f[k])
    # p[k] > threshold >= p[k + 1] >= 0: the log-linear crossing lies in [f[k], f[k + 1]).
    if p[k + 1] <= 0:
        return floor, float(f[k])
    step = np.log(p[k] / threshold) / np.log(p[k] / p[k + 1])
    return floor, float(f[k] + step * (f[k + 1] - f[k]))


def measurement_noise_std(trajectory: Trajectory) -> np.ndarray:
    """Per state column, the standard deviation of the white measurement noise its spectrum's floor implies.

    A column without a floor above round-off gets `1e-6` of its own standard deviation (a floor for
    weights built from it).
    """
    fs = 1.0 / trajectory.dt
    out = []
    names = tuple(trajectory.state_names)
    for k in range(trajectory.xs.shape[1]):
        column = np.asarray(trajectory.xs[:, k], dtype=float)
        position = names[k][1:] if names[k].startswith("d") else None
        reading = (
            column
            if position not in names or _reads_itself(trajectory)
            else _noise_reading(trajectory.xs[:, names.index(position)], column, fs)
        )
        floor, _ = noise_floor_and_band(reading, fs)
        out.append(max(np.sqrt(max(floor, 0.0) * 0.5 * fs), 1e-6 * float(np.std(column)), 1e-12))
    return np.asarray(out)


def _tail_ratio(order: int) -> float:
    import scipy.integrate

    tail = scipy.integrate.quad(lambda x: x**2 / (1 + x ** (2 * order)) ** 2, 1, np.inf)[0]
    return tail / (1.0 / 3.0)


def trim_and_decimation(sample_rate_hz: float, cutoff_hz: float, n_samples: int) -> tuple[int, int]:
    """Samples to trim (one cut-off period) and the parallel decimation factor (Nyquist at twice the
    cut-off, at most 13) for a filter at `cutoff_hz`; both reduced on short records so that at least
    half of the record and 28 rows per decimation step remain."""
    trim = int(min(np.ceil(sample_rate_hz / cutoff_hz), n_samples // 4))
    decimate = int(max(1, min(13, np.floor(sample_rate_hz / (4 * cutoff_hz)), (n_samples - 2 * trim) // 28)))
    return trim, decimate


CENTRAL_MATCH = 0.25  # see `_noise_reading`
# A velocity read as its position's central difference whose own floor is above the backward difference's by more
# than this (in density) carries noise of its own: a central difference's floor lies below the backward
# difference's (their responses' ratio, cos^2 of pi f dt, is at most 1 and falls to 0 at the Nyquist frequency).
OWN_NOISE = 4.0


def _noise_reading(q, v, fs: float) -> np.ndarray:
    r"""The signal whose spectrum gives a velocity channel's noise floor: the velocity itself, or, for
    a velocity that is the central difference of its position (an encoder-only record, as
    `load_trajectory` estimates it), the backward difference of that position.

    A zero-phase derivative's noise vanishes at the Nyquist frequency (its response is odd and
    periodic), where the floor is read: a central difference's, $\sin^2(2\pi f\Delta t)/\Delta t^2$
    times the encoder's, reads a floor about 7 times lower than a backward difference's
    ($4\sin^2(\pi f\Delta t)/\Delta t^2$), and motion-free bands then count as signal. Both carry the
    same signal and the same noise in the band; the backward difference reads the floor as a logged
    velocity's. A velocity counts as a central difference when it lies closer to the central than
    to the backward difference of its position, and within `CENTRAL_MATCH` (0.25) of their distance
    from each other, distances read as medians of absolute differences: a resampled record's few
    samples interpolated across a logging gap differ by the gap's whole motion and would rule an
    rms, while its other samples match to round-off (the DFKI records read from their angles alone
    and resampled to their own median interval lie at 0 to 0.14, the 1.6 kHz irregular one highest).
    A logged backward difference lies closer to the backward difference; a velocity measured apart
    from its position differs from the central difference by at least that difference's own noise,
    about 0.58 of the distance for white encoder noise ($\sigma f_s/\sqrt 2$ against
    $\sigma f_s\sqrt{3/2}$, and medians of Gaussian magnitudes scale as their rms), more with its
    own; the DFKI logged velocities interpolated to 10 ms, whose noise is the 2 ms backward
    difference's, lie at 0.30 and above. A velocity whose noise does not vanish at the Nyquist
    frequency reads its floor correctly from itself, so a doubtful case costs little either way: the
    positions-only records interpolated to 5 or 10 ms (0.17 to 1.9) read floors within a factor of
    about 2 in noise power either way."""
    q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
    if len(q) < 3:
        return v
    backward = np.diff(q) * fs
    central = 0.5 * (q[2:] - q[:-2]) * fs
    size = lambda a: float(np.median(np.abs(a)))  # noqa: E731
    to_central, to_backward = size(v[1:-1] - central), size(v[1:-1] - backward[:-1])
    if to_central < to_backward and to_central < CENTRAL_MATCH * size(central - backward[:-1]):
        return np.concatenate([backward[:1], backward])
    return v


def _reads_itself(trajectory: Trajectory) -> bool:
    """A linear axis's velocity reads its own floor, whatever it is: its central-difference estimate is the
    one its defaults were set with (the EMPS reproduction), and only the arms' estimate changed."""
    return trajectory.system == "linear_axis" or tuple(trajectory.state_names) == ("q", "dq")


# `filter_rule`'s rule, or None
FILTER_RULE: contextvars.ContextVar[Callable | None] = contextvars.ContextVar("dynax_filter_rule", default=None)


@contextlib.contextmanager
def filter_rule(rule):
    """Within the block, every filter dynax chooses from the data (`choose_filter`: the dynamic model's
    `"auto"` settings, the refinement's segments and filtered positions) is `rule(trajectory, choice, snr=snr)`:
    the `FilterChoice` read from the velocities' spectra handed to `rule`, which returns the one to use. For
    trying another band rule through the whole pipeline."""
    with set_within(FILTER_RULE, rule):
        yield


def choose_filter(trajectory: Trajectory, *, snr: float = 100.0) -> FilterChoice:
    """Pick the low-pass cut-off, order, trim and decimation for the dynamic model from one record.

    **Arguments:** `trajectory` (resampled to its median interval first if irregular), `snr` as in
    `noise_floor_and_band`.

    **Returns:** a `FilterChoice` (see the module notes for the rules; inside `filter_rule`, that rule's).
    """
    choice = _spectral_choice(trajectory, snr)
    rule = FILTER_RULE.get()
    return choice if rule is None else rule(trajectory, choice, snr=snr)


def _spectral_choice(trajectory: Trajectory, snr: float) -> FilterChoice:
    """`choose_filter`'s choice from the velocities' spectra."""
    fs = 1.0 / trajectory.dt
    nyquist = 0.5 * fs
    names = trajectory.state_names
    order = next(o for o in range(1, 9) if _tail_ratio(o) < 0.1)

    def no_filter(bands, noise, why):  # the velocities pass as measured
        return FilterChoice(None, order, 1, 1, fs, bands, noise, f"{why}: no filter")

    if len(trajectory) < MIN_SAMPLES:
        return no_filter({}, {}, f"{len(trajectory)} samples are too few for a spectrum (at least {MIN_SAMPLES})")
    n = len(names) // 2
    velocities = names[n:]
    bands, noise = {}, {}
    xs = np.asarray(trajectory.xs)  # columns cut on the host: a slice of a JAX array compiles a program per shape
    for k, name in enumerate(velocities):
        reading = xs[:, n + k] if _reads_itself(trajectory) else _noise_reading(xs[:, k], xs[:, n + k], fs)
        floor, band = noise_floor_and_band(reading, fs, snr=snr)
        if reading is not xs[:, n + k]:
            # Read as its position's central difference, a velocity may still carry noise of its own that its
            # clean position does not (a velocity measured apart, at a rate where the difference's truncation
            # outweighs that noise): where its own floor is above the difference's by more than a central
            # difference's can be, it is the velocity's noise, and it is read from the velocity.
            own_floor, own_band = noise_floor_and_band(xs[:, n + k], fs, snr=snr)
            if own_floor > OWN_NOISE * floor:
                floor, band = own_floor, own_band
        bands[name] = band
        noise[name] = float(np.sqrt(max(floor, 0.0) * nyquist))
    band = max(bands.values())
    if all(ratio < 0.01 for ratio in differenced_noise_ratios(trajectory, noise, fs).values()):
        return no_filter(
            bands, noise, "velocity noise negligible (differenced into accelerations it is under 1 % of their rms)"
        )
    if band >= 0.5 * nyquist:
        return no_filter(bands, noise, f"no noise floor below {0.5 * nyquist:.3g} Hz in the velocities")
    return _band_choice(bands, noise, fs, len(trajectory), snr, order)


def differenced_noise_ratios(trajectory: Trajectory, noise: dict, fs: float) -> dict[str, float]:
    r"""Per velocity of `trajectory`, its white-noise level `noise[name]` differenced into accelerations (a central
    difference at `fs`: $\sigma f_s/\sqrt 2$) over the accelerations' rms without it (`inf` where nothing is left)."""
    n = len(trajectory.state_names) // 2
    xs = np.asarray(trajectory.xs, dtype=float)
    ratios = {}
    for k, name in enumerate(trajectory.state_names[n:]):
        dq = xs[:, n + k]
        accel_rms = np.sqrt(np.mean(((dq[2:] - dq[:-2]) * 0.5 * fs) ** 2))
        noise_accel = noise.get(name, 0.0) * fs / np.sqrt(2.0)
        signal = np.sqrt(max(accel_rms**2 - noise_accel**2, 0.0))
        ratios[name] = float(noise_accel / signal) if signal > 0 else float("inf")
    return ratios


def _band_choice(bands, noise, fs, n_samples, snr, order, why="") -> FilterChoice:
    """The filter at the widest signal band `bands` (the velocities' floors `noise`), `why` before its reason."""
    band = max(bands.values())
    trim, decimate = trim_and_decimation(fs, band, n_samples)
    worst = max(noise, key=noise.get)
    reason = (
        f"{why}velocity signal band ends at {band:.3g} Hz (density {snr:g} x above the noise floor; "
        f"noisiest channel {worst}, {noise[worst]:.3g} rms): order-{order} zero-phase Butterworth at "
        f"{band:.3g} Hz, {trim} samples trimmed (one cut-off period), parallel decimation by {decimate}"
    )
    return FilterChoice(band, order, trim, decimate, fs, bands, noise, reason)


def band_filter(trajectory: Trajectory, choice: FilterChoice, *, snr: float = 100.0, why: str = "") -> FilterChoice:
    """The filter at the signal band for a record whose `choice` (from `choose_filter`) is no filter because its
    velocity noise was read as negligible; `choice` itself for any other (already filtered, or no noise floor below
    half the Nyquist frequency: nothing to cut). `why` opens the reason."""
    if choice.cutoff_hz is not None or not choice.band_hz or not choice.noise_std:
        return choice
    if max(choice.band_hz.values()) >= 0.25 * choice.sample_rate_hz:
        return choice
    return _band_choice(
        choice.band_hz, choice.noise_std, choice.sample_rate_hz, len(trajectory), snr, choice.order, why
    )


def position_fit_window(band_hz: float, dt: float) -> int:
    """Samples (odd, at least 5) of the local cubic fit in `velocities_from_positions`: half a period of the band's
    edge."""
    return max(5, int(round(0.5 / (band_hz * dt))) | 1)


def velocities_from_positions(xs: np.ndarray, dt: float, band_hz: float) -> np.ndarray:
    r"""The states (positions then velocities) with measured positions and velocities from a local cubic fit of the
    positions.

    Encoder positions are three orders of magnitude less noisy (relative to the motion) than a
    velocity differenced from them over one sample (a driver's estimate; the DFKI rig logs that);
    the derivative of a cubic Savitzky-Golay fit over a window of half a period of the band's edge
    passes the band (its -3 dB point lies near $4 f_s / (3.2 (2m + 1))$, about 3 times the band
    edge) and differentiates the position noise
    into a velocity noise $\sim \sigma_q / (m^{3/2} dt)$ (Schafer, "What is a Savitzky-Golay
    filter?", IEEE Signal Processing Magazine 28(4), 2011).
    """
    import scipy.signal

    n = xs.shape[1] // 2
    window = position_fit_window(band_hz, dt)
    window = min(window, (len(xs) - 1) | 1 if len(xs) % 2 == 0 else len(xs))
    out = np.array(xs, dtype=float, copy=True)
    out[:, n:] = scipy.signal.savgol_filter(out[:, :n], window, 3, deriv=1, delta=dt, axis=0, mode="interp")
    return out


def with_velocities_from_positions(trajectory: Trajectory) -> tuple[Trajectory, FilterChoice, tuple[str, ...]]:
    r"""`trajectory` (uniformly sampled; states `q..., dq...`) with each velocity replaced by
    `velocities_from_positions` where that estimate is better than the measured one.

    The measured velocity is $v + n$ with white noise $n$ of standard deviation $\sigma$ (from its
    spectrum's floor, `choose_filter`); the local cubic fit is $v + b$ with a bias $b$ (it cannot
    follow what changes faster than its window: a friction's kink, a delayed torque step) and far
    less noise. Their mean squared difference is about $\sigma^2 + \overline{b^2}$, so the fit is
    taken where that difference is at most $2\sigma^2$: where its bias is at most the noise it
    removes. On a one-sample difference of the encoder (the DFKI rig's logged velocity) the
    difference is the noise itself; on nearly clean data (simulated records with a little noise) it
    is many times the noise and the measured velocities are kept. A record without a noise floor is returned as it is.

    **Returns:** `(trajectory, choice, replaced)`, `replaced` the names of the velocities taken from positions.
    """
    import jax.numpy as jnp

    choice = choose_filter(trajectory)
    if choice.cutoff_hz is None:
        return trajectory, choice, ()
    xs = np.array(trajectory.xs, dtype=float)
    fitted = velocities_from_positions(xs, trajectory.dt, choice.cutoff_hz)
    n = xs.shape[1] // 2
    replaced = []
    for k in range(n, 2 * n):
        name = trajectory.state_names[k]
        sigma = choice.noise_std.get(name, 0.0)
        if np.mean((xs[:, k] - fitted[:, k]) ** 2) <= 2.0 * sigma**2:
            xs[:, k] = fitted[:, k]
            replaced.append(name)
    if not replaced:
        return trajectory, choice, ()
    t = trajectory
    return (
        Trajectory(t.ts, jnp.asarray(xs, dtype=t.xs.dtype), t.us, t.state_names, t.input_names, t.system, t.source),
        choice,
        tuple(replaced),
    )
