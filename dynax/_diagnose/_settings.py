"""The settings of a diagnosis, grouped as diffrax groups what to save in `SaveAt`: `Horizons` (how far it
simulates) and `Selection` (how causes are tested and chosen). Each checks its fields when made."""

from collections.abc import Sequence
import math

import equinox as eqx

from .._errors import UsageError
from .._validate import DEFAULT_FRACTION
from ._records import HOLDOUT_FRACTION

#: The horizons [s] a diagnosis reports its held-out simulation error at, unless `Horizons.horizons_s` says otherwise.
DEFAULT_HORIZONS_S = (0.1, 0.25, 0.5, 1.0, 2.0)


def _seconds(values) -> tuple[float, ...] | None:
    return None if values is None else tuple(float(v) for v in values)


def _positive(owner: str, name: str, value) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise UsageError(f"{owner}: `{name}` must be a positive number of seconds, got {value}")


class Horizons(eqx.Module):
    """How far a diagnosis simulates: where the held-out error is reported and judged, and the fit windows.

    **Fields:**

    - `horizons_s`: where the held-out simulation error is reported [s]; default `None`: 0.1, 0.25, 0.5, 1
      and 2 s (0.1, 0.25 and 0.5 s for a `Quadrotor`, where flight models are scored).
    - `reference_s`: where the gain is judged [s]; default `None`: the *predictability horizon*, the longest
      horizon at which the nominal model's open-loop position error on the training runs is at most
      `fraction` of the positions' spread (see `dynax.internal.predictability_horizon`).
    - `fraction`: that share of the positions' spread, in (0, 1).
    - `fit_window_s`: window length of the simulation-error fits [s]; default `None`: 2.5 times the
      starting model's predictability horizon on the training runs, between 0.25 s and 1 s (a fit over
      windows longer than the model can predict fits chaos, not physics).
    """

    horizons_s: tuple[float, ...] | None = eqx.field(default=None, converter=_seconds, static=True)
    reference_s: float | None = eqx.field(default=None, static=True)
    fraction: float = eqx.field(default=DEFAULT_FRACTION, static=True)
    fit_window_s: float | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.horizons_s is not None:
            if not self.horizons_s:
                raise UsageError("Horizons: `horizons_s` is empty")
            for h in self.horizons_s:
                _positive("Horizons", "horizons_s", h)
        _positive("Horizons", "reference_s", self.reference_s)
        _positive("Horizons", "fit_window_s", self.fit_window_s)
        if not 0 < self.fraction < 1:
            raise UsageError(f"Horizons: `fraction` must be in (0, 1), got {self.fraction}")

    def reported(self, default: Sequence[float] = DEFAULT_HORIZONS_S) -> tuple[float, ...]:
        """The horizons the error is reported at: `horizons_s`, or `default` where it is not given."""
        return self.horizons_s if self.horizons_s is not None else tuple(default)


class Selection(eqx.Module):
    """How a diagnosis tests and chooses causes: the held-out data, the test, the search.

    **Fields:**

    - `max_terms`: at most this many causes are selected (at least 1).
    - `alpha`: the held-out test's significance level, in (0, 1).
    - `min_gain`: the smallest held-out gain that counts, in [0, 1).
    - `shortlist`: candidates refitted jointly per round (at least 1).
    - `cross_fit`: with three or more training runs (default on), each training run is also held out
      in turn (with two, each fold would fit one run alone, a pessimistic judge of every added term;
      the report's notes say so): the screening's regression and every refit of a round are repeated on the
      other training runs, the left-out run is simulated over the reference horizon, and the paired test and
      the run agreement pool those windows with the held-out runs' (leave-one-run-out cross-validation). A
      short held-out run (a few seconds of a chaotic swing) then no longer decides alone; each round costs one
      more batch of fits per training run. The reported gains and error curves stay those of the held-out
      runs; `report.runs` lists the cross-fitted runs too. `False` tests on the held-out runs alone.
    - `discovery`: search for a term beyond the vocabulary when structure is left (default on).
    - `holdout_fraction`: without validation records, the last this share of each training record is held
      out, in (0, 1).
    - `velocities`: `"auto"` (default): for a system whose states are joint positions and velocities,
      each measured velocity that carries white noise larger than the bias of a local cubic fit of
      its positions (Savitzky-Golay over half a period of the signal band's edge; see
      `dynax._data._spectra.with_velocities_from_positions`) is replaced by that fit's
      derivative before anything is fitted or compared: the windows then start from better
      velocities and are compared with them, so the held-out errors measure the model, not the
      velocity sensor. `"measured"` keeps the records as they are. The report's
      `data.velocities` says which was used.
    """

    max_terms: int = eqx.field(default=3, static=True)
    alpha: float = eqx.field(default=0.01, static=True)
    min_gain: float = eqx.field(default=0.05, static=True)
    shortlist: int = eqx.field(default=4, static=True)
    cross_fit: bool = eqx.field(default=True, static=True)
    discovery: bool = eqx.field(default=True, static=True)
    holdout_fraction: float = eqx.field(default=HOLDOUT_FRACTION, static=True)
    velocities: str = eqx.field(default="auto", static=True)

    def __check_init__(self):
        if self.max_terms < 1:
            raise UsageError(f"Selection: `max_terms` must be at least 1, got {self.max_terms}")
        if not 0 < self.alpha < 1:
            raise UsageError(f"Selection: `alpha` must be in (0, 1), got {self.alpha}")
        if not 0 <= self.min_gain < 1:
            raise UsageError(f"Selection: `min_gain` must be in [0, 1), got {self.min_gain}")
        if self.shortlist < 1:
            raise UsageError(f"Selection: `shortlist` must be at least 1, got {self.shortlist}")
        if not 0 < self.holdout_fraction < 1:
            raise UsageError(f"Selection: `holdout_fraction` must be in (0, 1), got {self.holdout_fraction}")
        if self.velocities not in ("auto", "measured"):
            raise UsageError(f"Selection: `velocities` must be 'auto' or 'measured', got {self.velocities!r}")
