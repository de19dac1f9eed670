r"""`fit_quadrotor`: learn a `Quadrotor`'s body model from flights with the vehicle criteria.

The quadrotor's dynamics are the helicopter's in world-velocity coordinates (`dynax.Quadrotor`), so
the fit is the vehicle criteria's on the body-frame form of the flights (`Quadrotor.as_helicopter`,
`Quadrotor.body_frame`), run by `identify` as for every system: one-step least squares, the lagged
criterion by the EM-free iteration and the same loss by backprop. The frequency-domain criterion is
the helicopter's alone (its CIFER structure and frequency responses are written in the helicopter's
inputs). Several flights (or the runs of one flight between its ground segments and glitches) are joined
into one record with breaks that no window crosses.
"""

from collections.abc import Sequence

import numpy as np

from ..._data._flight import warn_if_units_differ
from ..._data._motor_order import warn_if_numbered_otherwise
from ..._data._trajectory import Trajectory
from ..._errors import DataError
from ..._fit import Solution
from ..._model._quadrotor import Quadrotor
from .._method import FitSettings
from ._body_file import body_from_json, body_to_json, model_file_fields
from ._criteria import Backprop, Lagged, OneStep
from ._fit import fit_all
from ._frequency import FrequencyDomain
from ._records import join_flights as join_flights


def fit_quadrotor(
    system: Quadrotor,
    flights: Sequence[Trajectory] | Trajectory,
    criterion: OneStep | Lagged | Backprop | FrequencyDomain | None = None,
    *,
    progress: bool | None = None,
    callback=None,
    warm_start: bool = False,
) -> Solution:
    r"""Learn the body model of a `Quadrotor` from flights with a vehicle criterion.

    The quadrotor spelling of `identify`: `identify(system, flights, criterion,
    settings=FitSettings(warm_start=..., callback=..., progress=...), validation=Validate(holdout=0))`
    fits every flight (joined in body-frame coordinates, no window crossing from one to the next),
    and this is its `solution`; `identify` with a validation holds flights out and scores the fit on
    them by the vehicle horizon error.

    **Arguments:**

    - `system`: the starting `Quadrotor` (`dynax.Quadrotor.from_flights`); its body model's mask says
      which weights to fit.
    - `flights`: one `Trajectory` or several, with the `quadrotor` columns, uniformly sampled
      at one interval (the usable runs of `dynax.load_flight`'s records: `dynax.usable_segments`).
    - `criterion`: `OneStep()` (the default), `Lagged(horizon=...)` or `Backprop(horizon=...)` (both
      start from the one-step fit). `FrequencyDomain()` is refused: its structure is the
      helicopter's.
    - `progress`, `callback`, `warm_start`: as for `fit_vehicle` (`warm_start`: `Lagged` or
      `Backprop` start from `system`'s weights, e.g. `Backprop` refining a `Lagged` fit).

    **Returns:** the engine's `Solution`: `model` the fitted `Quadrotor`, `value` its free weights
    named `d<axis>/<feature>`. For one-step the covariance is the least-squares one,
    $\hat\sigma^2 (A^\top A)^{-1}$ (a lower bound: the residuals are correlated in time); for the
    iterative criteria it is NaN and `loss_history` holds the loss after each iteration.

    ??? cite "Reference"

        P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
        modeling helicopters", NIPS 18, 2005.
    """
    criterion = OneStep() if criterion is None else criterion
    settings = FitSettings(warm_start=warm_start, callback=callback, progress=progress)
    warn_if_numbered_otherwise(flights)
    warn_if_units_differ(flights)
    return fit_all(system, flights, criterion, settings)


def quadrotor_to_json(system: Quadrotor, **info) -> dict:
    """The `MODEL.json` object of a `Quadrotor`: body model kind, features, mask, weights, input
    scales and named parameters, with `info` (criterion, horizon, loss, ...) beside them."""
    body = body_to_json(system.body_model)
    out = {"system": "quadrotor", "model": body.pop("model"), **info}
    for key in ("features", "mask", "weights"):
        out[key] = body.pop(key)
    return {**out, "input_scale": [float(s) for s in system.input_scale], **body}  # then parameters, gravity


def quadrotor_from_json(obj: dict, path=None) -> Quadrotor:
    """The `Quadrotor` of a `MODEL.json` object (as written by `quadrotor_to_json`), checked:
    known features, a 6-row mask and weights of matching shape, finite numbers, positive scales."""
    with model_file_fields(path):
        if obj.get("system") != "quadrotor":
            raise DataError(f"not a quadrotor model file (system = {obj.get('system')!r})", path=path)
        body = body_from_json(obj, path, gravity=-9.81)
        scale = tuple(float(s) for s in obj["input_scale"])
        if len(scale) != 5 or not all(np.isfinite(s) and s > 0 for s in scale):
            raise DataError(
                f"'input_scale' must be 5 positive numbers, got {obj['input_scale']}", path=path, column="input_scale"
            )
    return Quadrotor(body, scale)
