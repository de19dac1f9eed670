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
window's error (`HeldOutError.concentrated`, `note()`): half of its squared error comes from the fewest windows
that hold it, and where they start.
"""

import dataclasses

import numpy as np

from .._data._derivatives import resample
from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._sim_error import simulation_error

DEFAULT_HORIZONS_S = (0.1, 0.25, 0.5)
# RMSE over the median window's root-mean-square error above which a record's RMSE is said to be
# carried by a few windows. Windows whose errors differ only by chance give about 1.2 (for a
# Gaussian error in two positions, sqrt(2 / 1.386)) to 1.7 (the true model on a noisy synthetic rig
# record, `tests/identify/test_validation.py`); real records give about as much, except one whose end rests
# at an unstable equilibrium. A ratio of 3 is a mean square 9 times the median's.
CONCENTRATED = 3.0


@dataclasses.dataclass(frozen=True)
class HeldOutError:
    """Open-loop position RMSE on held-out data (the result of `held_out_error`).

    **Fields:**

    - `horizons_s`: the horizons [s].
    - `rmse`: pooled over every window of every record, per horizon [rad or m]; `inf` where a
      rollout diverged.
    - `per_record`: record name -> RMSE per horizon.
    - `diverged_fraction`: record name -> fraction of windows whose rollout diverged.
    - `source`: `"validation records"` or `"held-out end of each record (last X %)"`.
    - `median`: per horizon, the median over every window of every record of the window's
      root-mean-square position error (a typical window, where `rmse` weighs the worst), over the
      windows that did not diverge.
    - `concentrated`: record name -> one entry per horizon at which the record's RMSE is more than
      `CONCENTRATED` times its median window error: `horizon_s`, `rmse`, `median`, `windows` (the
      fewest windows holding half of the squared error), `of` (the record's windows), `from_s`,
      `to_s` (the first and last of those windows' start times, in the record's time). Records
      whose RMSE no few windows carry are absent.
    """

    horizons_s: tuple[float, ...]
    rmse: tuple[float, ...]
    per_record: dict[str, tuple[float, ...]]
    diverged_fraction: dict[str, float]
    source: str
    median: tuple[float, ...] = ()
    concentrated: dict[str, list[dict]] = dataclasses.field(default_factory=dict)

    def note(self) -> str | None:
        """One sentence per record whose RMSE a few windows carry (`concentrated`); `None` if none."""
        if not self.concentrated:
            return None
        parts = []
        for name, entries in self.concentrated.items():
            cells = "; ".join(
                f"at {e['horizon_s']:g} s half of its squared error comes from {e['windows']} of "
                f"{e['of']} windows, starting {e['from_s']:.2f} to {e['to_s']:.2f} s (RMSE "
                f"{e['rmse']:.3g} against a median window error of {e['median']:.3g})"
                for e in entries
            )
            parts.append(f"{name}: {cells}")
        return (
            "the open-loop RMSE is carried by a few windows, which say more about those stretches "
            "(rest at an unstable equilibrium, a glitch in the data) than about the "
            "record: " + ". ".join(parts)
        )

    def to_json(self) -> dict:
        return {
            "horizons_s": list(self.horizons_s),
            "rmse": list(self.rmse),
            "per_record": {k: list(v) for k, v in self.per_record.items()},
            "diverged_fraction": self.diverged_fraction,
            "source": self.source,
            "median": list(self.median),
            "concentrated": self.concentrated,
        }


def _concentrated(window_mse: np.ndarray, start_times: np.ndarray, horizons, rmse) -> list[dict]:
    """`HeldOutError.concentrated`'s entries for one record (`window_mse (window, horizon)`)."""
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
) -> HeldOutError:
    """Open-loop simulation error of `system` on each of `records`, pooled over their windows.

    Irregular records are resampled at their median interval first. From up to `max_windows` start
    samples per record the model is simulated from the measured state under the recorded inputs
    (`dynax.simulation_error`) and compared with the measured positions at each horizon.

    **Arguments:** `system`; `records` (held out of the fit); `horizons_s`; `source` (a label for
    reports); `max_windows` per record.

    **Returns:** a `HeldOutError`, with the median window error and the records whose RMSE a few
    windows carry (`concentrated`). A record shorter than the longest horizon is skipped.
    """
    if not records:
        raise UsageError("held_out_error: no records to validate on")
    horizons = tuple(float(h) for h in horizons_s)
    total, count = np.zeros(len(horizons)), 0
    per_record, diverged, concentrated, windows = {}, {}, {}, []
    for k, record in enumerate(records):
        uniform = record if record.is_uniform else resample(record, record.dt)
        if uniform.duration <= max(horizons) + uniform.dt:
            continue
        error = simulation_error(system, uniform, horizons, max_windows=max_windows)
        rmse = np.asarray(error.rmse, dtype=float)
        name = _name(record, k)
        per_record[name] = tuple(float(r) for r in rmse)
        diverged[name] = float(error.diverged_fraction)
        total += error.n_windows * rmse**2
        count += error.n_windows
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
    return HeldOutError(
        horizons, tuple(float(v) for v in np.sqrt(total / count)), per_record, diverged, source, median, concentrated
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
