"""`fit_vehicle`: the vehicle spelling of `identify` for the four criteria, and the model file (`MODEL.json`) format."""

import math
import warnings

import numpy as np

from ..._data._sanity import DataWarning
from ..._data._trajectory import Trajectory
from ..._errors import DataError, UsageError
from ..._fit import Solution
from ..._model._helicopter import (
    AccelerationModel,
    Helicopter,
    LinearVelocityModel,
    RICH_FEATURES,
    TEMPEST_FEATURES,
)
from .._identify import identify
from .._method import AbstractMethod, FitSettings
from .._validation import Validate
from ._body_file import body_from_json, body_to_json, model_file_fields
from ._criteria import (
    Backprop,
    Lagged,
    OneStep,
    recorded_loss,
    VehicleStatistics,
)
from ._frequency import FrequencyDomain

CRITERIA = {"one-step": OneStep, "frequency": FrequencyDomain, "lagged": Lagged, "backprop": Backprop}


def initial_helicopter(model: str, features: str = "tempest") -> Helicopter:
    """The starting `Helicopter` for `--model acceleration|linear` (`features`: `tempest` or `rich`)."""
    if model == "acceleration":
        axes = {"tempest": TEMPEST_FEATURES, "rich": RICH_FEATURES}.get(features)
        if axes is None:
            raise UsageError(f"unknown feature set '{features}'; expected 'tempest' or 'rich'")
        return Helicopter(AccelerationModel.with_features(axes))
    if model == "linear":
        return Helicopter(LinearVelocityModel())
    raise UsageError(f"unknown model '{model}'; expected 'acceleration' or 'linear'")


def fit_vehicle(
    system: Helicopter,
    trajectory: Trajectory,
    criterion: OneStep | FrequencyDomain | Lagged | Backprop = OneStep(),
    *,
    callback=None,
    progress: bool | None = None,
    breaks=None,
    warm_start: bool = False,
) -> Solution:
    r"""Learn the body model of `system` from `trajectory` with a learning `criterion`.

    The vehicle spelling of `identify`: `identify(system, trajectory, criterion,
    settings=FitSettings(breaks=..., warm_start=..., callback=..., progress=...),
    validation=Validate(holdout=0))` fits the whole record, and this is its `solution`.

    `Lagged` and `Backprop` start from the one-step fit (the paper's initialisation), so both
    descend the same lagged loss from the same point; with `warm_start` they start from
    `system`'s weights instead (e.g. `Backprop` from a `Lagged` fit: the EM-free iteration stops
    above the lagged loss's minimum, the gradient descends the rest).

    **Arguments:**

    - `system`: a `Helicopter` whose body model's mask says which weights to fit.
    - `trajectory`: uniformly sampled helicopter data (`dynax.load_trajectory(path, "helicopter")`).
    - `criterion`: `OneStep()`, `FrequencyDomain()` (linear model only), `Lagged(horizon=...)` or
      `Backprop(horizon=...)`.
    - `callback`: `callback(iteration, loss)` after each iteration of the iterative criteria.
    - `progress`: for `Lagged` and `Backprop`, a bar per iteration with the loss on stderr (an
      ETA against the iteration limit; a fit that converges early finishes early); `None` draws it
      when stderr is a terminal (see `dynax.internal.progress_mode`).
    - `breaks`: for a record joined from several (flights, or the runs of a flight between its
      ground segments and glitches), the sample indices where each new one begins: no window
      of the criteria crosses one (not for `FrequencyDomain`).
    - `warm_start`: start `Lagged` or `Backprop` from `system`'s weights, not the one-step fit.

    **Returns:** a `Solution`: the fitted system as its `model`, its free weights by name, the
    criterion's loss and its history, and a `VehicleStatistics` (the criterion, the samples, and
    for the frequency criterion each weight's Cramer-Rao bound and the weights it eliminated).
    For one-step the covariance is the least-squares one (a lower bound: the residuals are
    correlated in time); for the other criteria it is NaN.

    ??? cite "Reference"

        P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
        modeling helicopters", NIPS 18, 2005.
    """
    if not isinstance(criterion, AbstractMethod):
        raise UsageError(f"fit_vehicle: unknown criterion {type(criterion).__name__}")
    # A static field holds plain integers: an array there would be hashed by identity (and JAX warns).
    breaks = None if breaks is None else tuple(int(b) for b in np.asarray(breaks).ravel())
    settings = FitSettings(breaks=breaks, warm_start=warm_start, callback=callback, progress=progress)
    return fit_all(system, trajectory, criterion, settings)


def fit_all(system, records, criterion: AbstractMethod, settings: FitSettings, *, warn_data: bool = True) -> Solution:
    """`identify` of `system` on all of `records` (nothing held out, nothing validated) with a vehicle
    `criterion` and its `settings`: the `Solution` it carries (`fit_vehicle`, `fit_quadrotor`). Without
    `warn_data`, `identify`'s data warnings are left out: for callers that have already said what the
    records hold (the CLI's loader, `diagnose`)."""
    with warnings.catch_warnings():
        if not warn_data:
            warnings.simplefilter("ignore", DataWarning)
        return identify(
            system, records, criterion, settings=settings, consistency="off", validation=Validate(holdout=0)
        ).solution


def model_to_json(fit: Solution, *, horizon_s: float | None = None) -> dict:
    """The `MODEL.json` object of a vehicle fit (`fit_vehicle`): model kind, features, mask, weights and named
    parameters."""
    statistics = fit.statistics
    if not isinstance(statistics, VehicleStatistics):
        raise UsageError("model_to_json: not the Solution of a vehicle fit (`fit_vehicle`)")
    body = body_to_json(fit.model.body_model)
    gravity = {"gravity": body.pop("gravity")} if "gravity" in body else {}
    out = {
        "system": "helicopter",
        "model": body.pop("model"),
        "criterion": statistics.criterion,
        "horizon_s": horizon_s,
        **body,
        "loss": recorded_loss(fit),
        "n_samples": statistics.n_samples,
        **gravity,
    }
    accuracy = statistics.accuracy
    if accuracy:  # the frequency criterion's Cramer-Rao bounds and insensitivities
        out["identification"] = {
            # null where a weight is not determined at all (an infinite bound)
            "cramer_rao_percent": {name: cr if math.isfinite(cr) else None for name, _, cr, _ in accuracy},
            "insensitivity_percent": {
                name: ins if math.isfinite(ins) else None for name, _, _, ins in statistics.accuracy
            },
            "eliminated": list(statistics.eliminated),
        }
    return out


def model_from_json(obj: dict, path=None) -> Helicopter:
    """The `Helicopter` described by a `MODEL.json` object (as written by `model_to_json`)."""
    with model_file_fields(path):
        if obj.get("system") != "helicopter":
            raise DataError(f"not a helicopter model file (system = {obj.get('system')!r})", path=path)
        body = body_from_json(obj, path, gravity=9.81)
    return Helicopter(body)
