"""Validation of an identified model: open-loop simulation error against horizon on held-out records.

The equation error a least-squares fit minimises says how well the model explains the measured
forces at the measured states; what a user of the model needs is how far its *simulation* drifts
from the rig. `held_out_error` runs `dynax.simulation_error` on records (or parts of records) that
did not enter the fit and pools the position RMSE over them; `split_for_validation` makes such a
part when no separate record is given.

An RMSE pools squared errors, so a few windows can carry it: on a record that ends with a pendulum
at rest upright, every open-loop rollout started there falls off the unstable equilibrium, and those windows' errors of
a radian or more outweigh the rest of the record. So the result also gives the median window error per horizon, and
names, per record and horizon, the windows that carry the RMSE where it is more than `CONCENTRATED` times the median
window's error (`SimulationError.concentrated`, `note()`): half of its squared error comes from the fewest windows
that hold it, and where they start.
"""

from collections.abc import Sequence
from typing import Literal

import equinox as eqx
import numpy as np

from .._data._derivatives import resample
from .._data._rest import speeds_zeroed_at_rest
from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._simulate import simulation_error, SimulationError

DEFAULT_HORIZONS_S = (0.1, 0.25, 0.5)


class Validate(eqx.Module):
    """How `identify` validates what it fits: on which records, or which part of each, at what horizons.

    **Arguments:**

    - `records`: held-out records (a `Trajectory` or a sequence of them); when given, all of the
      data is fitted and these are simulated.
    - `holdout`: without `records`, the fraction of each record held out at its end (`"auto"`:
      0.2, or 0 when row `weights` are given); 0 fits everything and reports no validation.
    - `horizons_s`: the horizons [s] of the open-loop position RMSE (default 0.1, 0.25, 0.5).

    `identify(..., validation=records)` is `Validate(records)`.
    """

    records: Trajectory | Sequence[Trajectory] | None = None
    holdout: float | Literal["auto"] = "auto"
    horizons_s: tuple[float, ...] = eqx.field(default=DEFAULT_HORIZONS_S, converter=lambda h: tuple(map(float, h)))


# RMSE over the median window's root-mean-square error above which a record's RMSE is said to be
# carried by a few windows. Windows whose errors differ only by chance give about 1.2 (for a
# Gaussian error in two positions, sqrt(2 / 1.386)) to 1.7 (the true model on a noisy synthetic rig
# record, `tests/identify/test_validation.py`); real records give about as much, except one whose end rests
# at an unstable equilibrium. A ratio of 3 is a mean square 9 times the median's.
CONCENTRATED = 3.0


def _concentrated(window_mse: np.ndarray, start_times: np.ndarray, horizons, rmse) -> list[dict]:
    """`SimulationError.concentrated`'s entries for one record (`window_mse (window, horizon)`)."""
    entries = []
    for k, horizon in enumerate(horizons):
        squared = window_mse[:, k]
        finite = np.isfinite(squared)
        if not np.isfinite(rmse[k]) or finite.sum() < 2:
            continue  # a diverged rollout is reported as such (`diverged_fraction`)
        median = float(np.sqrt(np.median(squared[finite])))
        if not rmse[k] > CONCENTRATED * median:
            continue
        order = np.argsort(squared[finite])[::-1]
        cumulative = np.cumsum(squared[finite][order])
        count = int(np.searchsorted(cumulative, 0.5 * cumulative[-1]) + 1)
        starts = start_times[finite][order[:count]]
        entries.append(
            {
                "horizon_s": float(horizon),
                "rmse": float(rmse[k]),
                "median": median,
                "windows": count,
                "of": int(finite.sum()),
                "from_s": float(starts.min()),
                "to_s": float(starts.max()),
            }
        )
    return entries


def _name(record: Trajectory, k: int) -> str:
    return record.source.rsplit("/", 1)[-1] if record.source else f"record {k}"


def held_out_error(
    system,
    records: list[Trajectory],
    horizons_s=DEFAULT_HORIZONS_S,
    *,
    source: str = "validation records",
    max_windows: int = 200,
    start_at_rest: bool = False,
) -> SimulationError:
    """Open-loop simulation error of `system` on each of `records`, pooled over their windows.

    Irregular records are resampled at their median interval first. From up to `max_windows` start
    samples per record the model is simulated from the measured state under the recorded inputs
    (`dynax.simulation_error`) and compared with the measured positions at each horizon.

    **Arguments:** `system`; `records` (held out of the fit); `horizons_s`; `source` (a label for
    reports); `max_windows` per record; `start_at_rest`: start a joint that rests at zero speed where
    its measured speed is within the noise at rest (`dynax.internal.speeds_zeroed_at_rest`: the record's
    own noise; `identify` validates so where its model has `Stiction`).

    **Returns:** a `SimulationError` with `source`, the RMSE per record, the median window error
    and the records whose RMSE a few windows carry (`concentrated`). A record shorter than the
    longest horizon is skipped.
    """
    if not records:
        raise UsageError("held_out_error: no records to validate on")
    horizons = tuple(float(h) for h in horizons_s)
    total, count, n_diverged = np.zeros(len(horizons)), 0, 0.0
    per_record, diverged, concentrated, windows, states = {}, {}, {}, [], ()
    for k, record in enumerate(records):
        uniform = record if record.is_uniform else resample(record, record.dt)
        if uniform.duration <= max(horizons) + uniform.dt:
            continue
        if start_at_rest:
            (uniform,) = speeds_zeroed_at_rest([uniform])
        error = simulation_error(system, uniform, horizons, max_windows=max_windows)
        rmse = np.asarray(error.rmse, dtype=float)
        name = _name(record, k)
        per_record[name] = tuple(float(r) for r in rmse)
        diverged[name] = float(error.diverged_fraction)
        total += error.n_windows * rmse**2
        count += error.n_windows
        n_diverged += error.n_windows * error.diverged_fraction
        states = error.states
        window_mse = np.asarray(error.window_mse, dtype=float)
        windows.append(window_mse)
        entries = _concentrated(window_mse, np.asarray(uniform.ts)[np.asarray(error.starts)], horizons, rmse)
        if entries:
            concentrated[name] = entries
    if count == 0:
        raise UsageError(f"held_out_error: every record is shorter than the {max(horizons):g} s horizon")
    pooled = np.concatenate(windows)
    median = tuple(
        float(np.sqrt(np.nanmedian(pooled[:, k]))) if np.isfinite(pooled[:, k]).any() else float("nan")
        for k in range(len(horizons))
    )
    return SimulationError(
        horizons_s=horizons,
        n_windows=count,
        diverged_fraction=n_diverged / count,
        rmse=np.sqrt(total / count),
        states=states,
        source=source,
        rmse_per_record=per_record,
        diverged_per_record=diverged,
        median=np.asarray(median),
        concentrated=concentrated,
    )


def split_for_validation(records: list[Trajectory], fraction: float, min_duration_s: float) -> tuple[list, list]:
    """Split each record into a fitted head and a held-out tail of `fraction` of its samples.

    A record whose tail would be shorter than `min_duration_s` stays whole in the fit.

    **Returns:** `(fit_records, held_out_records)`.
    """
    if not 0 < fraction < 1:
        raise UsageError(f"`holdout` must be in (0, 1), got {fraction}")
    fit, held = [], []
    for record in records:
        head, tail = record.split(1 - fraction)
        if len(tail) > 1 and tail.duration > min_duration_s and len(head) > 2:
            fit.append(head)
            held.append(tail)
        else:
            fit.append(record)
    return fit, held


class HeldOut(eqx.Module):
    """The records `identify` validates every stage of a fit on, and how (what `Validate` became once
    the records to fit were split off).

    **Fields:** `records` (the held-out records; empty: nothing is validated), `horizons_s`, `source`
    (what they are, as the validation reports it), `tails_of` (for held-out tails, the index of the
    fitted record each was cut from; `None` for records of their own), `start_at_rest` (windows whose
    joint rests start at zero speed where the measured one is within the noise: `held_out_error`).
    """

    records: list[Trajectory]
    horizons_s: tuple[float, ...]
    source: str
    tails_of: tuple[int, ...] | None = None
    start_at_rest: bool = eqx.field(default=False, static=True)

    def validate(self, model) -> SimulationError | None:
        """`held_out_error` of `model` on the held-out records, or `None` where there are none."""
        if not self.records:
            return None
        return held_out_error(
            model, self.records, self.horizons_s, source=self.source, start_at_rest=self.start_at_rest
        )
