"""Validation of an identified model: open-loop simulation error against horizon on held-out records.

The equation error a least-squares fit minimises says how well the model explains the measured
forces at the measured states; what a user of the model needs is how far its *simulation* drifts
from the rig. `held_out_error` runs `dynax.simulation_error` on records (or parts of records) that
did not enter the fit and pools the position RMSE over them; `split_for_validation` makes such a
part when no separate record is given.
"""

import dataclasses

import numpy as np

from .._data._derivatives import resample
from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._sim_error import simulation_error

DEFAULT_HORIZONS_S = (0.1, 0.25, 0.5)


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
    """

    horizons_s: tuple[float, ...]
    rmse: tuple[float, ...]
    per_record: dict[str, tuple[float, ...]]
    diverged_fraction: dict[str, float]
    source: str

    def to_json(self) -> dict:
        return {"horizons_s": list(self.horizons_s), "rmse": list(self.rmse),
                "per_record": {k: list(v) for k, v in self.per_record.items()},
                "diverged_fraction": self.diverged_fraction, "source": self.source}


def _name(record: Trajectory, k: int) -> str:
    return record.source.rsplit("/", 1)[-1] if record.source else f"record {k}"


def held_out_error(
    system, records: list[Trajectory], horizons_s=DEFAULT_HORIZONS_S, *, source: str = "validation records",
    max_windows: int = 200,
) -> HeldOutError:
    """Open-loop simulation error of `system` on each of `records`, pooled over their windows.

    Irregular records are resampled at their median interval first. From up to `max_windows` start
    samples per record the model is simulated from the measured state under the recorded inputs
    (`dynax.simulation_error`) and compared with the measured positions at each horizon.

    **Arguments:** `system`; `records` (held out of the fit); `horizons_s`; `source` (a label for
    reports); `max_windows` per record.

    **Returns:** a `HeldOutError`. A record shorter than the longest horizon is skipped.
    """
    if not records:
        raise UsageError("held_out_error: no records to validate on")
    horizons = tuple(float(h) for h in horizons_s)
    total, count = np.zeros(len(horizons)), 0
    per_record, diverged = {}, {}
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
    if count == 0:
        raise UsageError(f"held_out_error: every record is shorter than the {max(horizons):g} s horizon")
    return HeldOutError(horizons, tuple(float(v) for v in np.sqrt(total / count)), per_record, diverged, source)


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
