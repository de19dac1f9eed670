r"""`fit_quadrotor`: learn a `Quadrotor`'s body model from flights with the vehicle criteria.

The quadrotor's dynamics are the helicopter's in world-velocity coordinates (`dynax.Quadrotor`), so
the fit is `fit_vehicle` on the body-frame form of the flights (`Quadrotor.as_helicopter`,
`to_body_frame`): one-step least squares, the lagged criterion by the EM-free iteration and the same
loss by backprop. The frequency-domain criterion is the helicopter's alone (its CIFER structure and
frequency responses are written in the helicopter's inputs).
Several flights (or the runs of one flight between its ground segments and glitches) are joined
into one record with breaks that no window crosses.
"""

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._data._trajectory import Trajectory
from ..._errors import UsageError
from ..._fit import Parameters, Solution
from ..._model._quadrotor import Quadrotor, to_body_frame
from ._criteria import Backprop, Lagged, normal_equations, OneStep, state_weights, window_starts
from ._fit import fit_vehicle
from ._frequency import FrequencyDomain


def join_flights(system: Quadrotor, flights: Sequence[Trajectory]) -> tuple[Trajectory, np.ndarray]:
    """The flights in body-frame coordinates (`to_body_frame`) joined into one uniformly sampled
    record, and the sample indices where each flight after the first begins (the breaks).

    All flights must share one sample interval (to 1 %) and one set of inputs.
    """
    flights = list(flights)
    if not flights:
        raise UsageError("fit_quadrotor: no flights given")
    dts = []
    for i, f in enumerate(flights):
        if len(f) < 2 or not f.is_uniform:
            raise UsageError(
                f"fit_quadrotor: flight {i} ({f.source or 'unnamed'}) must be uniformly sampled with at "
                "least 2 samples (dynax.load_flight resamples; dynax.usable_segments cuts)"
            )
        dts.append(f.dt)
    dt = float(np.median(dts))
    off = [i for i, d in enumerate(dts) if abs(d - dt) > 0.01 * dt]
    if off:
        raise UsageError(
            f"fit_quadrotor: flight {off[0]} is sampled every {dts[off[0]]:.6g} s, the others every "
            f"{dt:.6g} s; resample it first"
        )
    inputs = {tuple(f.input_names) for f in flights}
    if len(inputs) > 1:
        raise UsageError(f"fit_quadrotor: the flights have different inputs {sorted(inputs)}")
    if system.uses_battery and "vbat" not in flights[0].input_names:
        raise UsageError("fit_quadrotor: the model's features use `vbat`, which the flights do not have")
    body = [to_body_frame(system, f) for f in flights]
    lengths = np.array([len(b) for b in body])
    xs = jnp.concatenate([b.xs for b in body])
    us = jnp.concatenate([b.us for b in body])
    ts = float(np.asarray(flights[0].ts)[0]) + dt * np.arange(xs.shape[0])
    joined = Trajectory(ts, xs, us, body[0].state_names, body[0].input_names, "helicopter", "joined flights")
    return joined, np.cumsum(lengths)[:-1]


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

    **Arguments:**

    - `system`: the starting `Quadrotor` (`dynax.initial_quadrotor`); its body model's mask says
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
    if isinstance(criterion, FrequencyDomain):
        raise UsageError(
            "fit_quadrotor: the frequency-domain criterion identifies the helicopter's linear model "
            "(its structure and frequency responses are written in the helicopter's inputs u1..u4); "
            "for a quadrotor use OneStep, Lagged or Backprop"
        )
    if isinstance(flights, Trajectory):
        flights = [flights]
    joined, breaks = join_flights(system, flights)
    helicopter = system.as_helicopter()
    fit = fit_vehicle(
        helicopter, joined, criterion, progress=progress, callback=callback, breaks=breaks, warm_start=warm_start
    )
    fitted = system.with_body_model(fit.model.body_model)
    solution = eqx.tree_at(lambda s: (s.model, s.parameters), fit, (fitted, Parameters.of(fitted)))
    if not isinstance(criterion, OneStep):  # lagged, backprop: the engine's Solution of the helicopter form
        return solution
    n = solution.value.shape[0]
    starts = window_starts(joined, 1, 1, breaks)
    w = state_weights(None, joined.xs.dtype)
    ata, _, mse = normal_equations(fit.model, joined, starts, 1, w, False, 1024)
    windows = int(starts.shape[0])  # `mse` is per window, its six body axes summed
    sigma2 = mse * windows / max(6 * windows - n, 1)
    covariance = sigma2 * jnp.linalg.pinv(ata)
    std = jnp.sqrt(jnp.diag(covariance))
    return eqx.tree_at(lambda s: (s.covariance, s.std_errors), solution, (covariance, std))


def quadrotor_to_json(system: Quadrotor, **info) -> dict:
    """The `MODEL.json` object of a `Quadrotor`: body model kind, features, mask, weights, input
    scales and named parameters, with `info` (criterion, horizon, loss, ...) beside them."""
    body = system.body_model
    out = {
        "system": "quadrotor",
        "model": body.kind,
        **info,
        "features": list(body.feature_names),
        "mask": [[int(v) for v in row] for row in body.mask],
        "weights": np.asarray(body.weights).tolist(),
        "input_scale": [float(s) for s in system.input_scale],
        "parameters": {k: float(v) for k, v in body.parameters.items()},
    }
    if body.kind == "acceleration":
        out["gravity"] = body.gravity
    return out


def quadrotor_from_json(obj: dict, path=None) -> Quadrotor:
    """The `Quadrotor` of a `MODEL.json` object (as written by `quadrotor_to_json`), checked:
    known features, a 6-row mask and weights of matching shape, finite numbers, positive scales."""
    from ..._errors import DataError
    from ..._model._helicopter import AccelerationModel, FEATURES, LinearVelocityModel

    try:
        if obj.get("system") != "quadrotor":
            raise DataError(f"not a quadrotor model file (system = {obj.get('system')!r})", path=path)
        features = tuple(obj["features"])
        unknown = [f for f in features if not isinstance(f, str) or f not in FEATURES]
        if unknown:
            raise DataError(f"unknown features {unknown}", path=path, column="features")
        mask = tuple(tuple(bool(v) for v in row) for row in obj["mask"])
        weights = np.asarray(obj["weights"], float)
        if weights.shape != (6, len(features)) or len(mask) != 6 or any(len(r) != len(features) for r in mask):
            raise DataError(
                f"'weights' and 'mask' must be 6 x {len(features)} (axes x features), got weights of "
                f"shape {weights.shape}",
                path=path,
                column="weights",
            )
        if not np.all(np.isfinite(weights)):
            axis, j = np.argwhere(~np.isfinite(weights))[0]
            raise DataError(
                f"weight [{axis}][{j}] (feature '{features[j]}') is not a finite number", path=path, column="weights"
            )
        scale = tuple(float(s) for s in obj["input_scale"])
        if len(scale) != 5 or not all(np.isfinite(s) and s > 0 for s in scale):
            raise DataError(
                f"'input_scale' must be 5 positive numbers, got {obj['input_scale']}", path=path, column="input_scale"
            )
        if obj["model"] == "acceleration":
            body = AccelerationModel(
                weights=jnp.asarray(weights),
                feature_names=features,
                mask=mask,
                gravity=float(obj.get("gravity", -9.81)),
            )
        elif obj["model"] == "linear":
            body = LinearVelocityModel(weights=jnp.asarray(weights), feature_names=features, mask=mask)
        else:
            raise DataError(f"unknown model kind {obj['model']!r}", path=path, column="model")
    except KeyError as e:
        raise DataError(f"the model file lacks the field {e.args[0]!r}", path=path) from None
    except (TypeError, ValueError) as e:
        if isinstance(e, DataError):
            raise
        raise DataError(f"malformed model file ({e})", path=path) from None
    return Quadrotor(body, scale)
