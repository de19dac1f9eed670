"""A vehicle's body model (`AccelerationModel`, `LinearVelocityModel`) to and from the fields of its `MODEL.json`:
what a helicopter's and a quadrotor's model files share."""

import contextlib

import jax.numpy as jnp
import numpy as np

from ..._errors import DataError
from ..._model._helicopter import AccelerationModel, FEATURES, LinearVelocityModel


def body_to_json(body) -> dict:
    """The body model's fields of `MODEL.json`: its kind, features, mask, weights, named parameters and (for the
    acceleration model) gravity."""
    out = {
        "model": body.kind,
        "features": list(body.feature_names),
        "mask": [[int(v) for v in row] for row in body.mask],
        "weights": np.asarray(body.weights).tolist(),
        "parameters": {k: float(v) for k, v in body.parameters.items()},
    }
    if body.kind == "acceleration":
        out["gravity"] = body.gravity
    return out


def body_from_json(obj: dict, path, gravity: float) -> AccelerationModel | LinearVelocityModel:
    """The body model of a `MODEL.json` object, checked: known features, mask entries true or false, a 6-row mask
    and weights of matching shape, finite weights (a `DataError` naming the field). `gravity`: the acceleration
    model's gravity where the file gives none (the vehicle's frame: +9.81 down in NED, -9.81 with z up). A
    missing field raises `KeyError` for the caller to name with its file."""
    features = tuple(obj["features"])
    unknown = [f for f in features if not isinstance(f, str) or f not in FEATURES]
    if unknown:
        raise DataError(f"unknown features {unknown}", path=path, column="features")
    bad = [(i, j) for i, row in enumerate(obj["mask"]) for j, v in enumerate(row) if v not in (True, False)]
    if bad:  # a mask is written as true/false (or 1/0): anything else is an edited or foreign file, not a mask
        i, j = bad[0]
        raise DataError(
            f"mask [{i}][{j}] is {obj['mask'][i][j]!r}: a mask entry is true or false", path=path, column="mask"
        )
    mask = tuple(tuple(bool(v) for v in row) for row in obj["mask"])
    weights = np.asarray(obj["weights"], float)
    if weights.shape != (6, len(features)) or len(mask) != 6 or any(len(r) != len(features) for r in mask):
        raise DataError(
            f"'weights' and 'mask' must be 6 x {len(features)} (axes x features), got weights of shape {weights.shape}",
            path=path,
            column="weights",
        )
    if not np.all(np.isfinite(weights)):
        axis, j = np.argwhere(~np.isfinite(weights))[0]
        raise DataError(
            f"weight [{axis}][{j}] (feature '{features[j]}') is not a finite number", path=path, column="weights"
        )
    if obj["model"] == "acceleration":
        return AccelerationModel(
            weights=jnp.asarray(weights),
            feature_names=features,
            mask=mask,
            gravity=float(obj.get("gravity", gravity)),
        )
    if obj["model"] == "linear":
        return LinearVelocityModel(weights=jnp.asarray(weights), feature_names=features, mask=mask)
    raise DataError(f"unknown model kind {obj['model']!r}", path=path, column="model")


@contextlib.contextmanager
def model_file_fields(path):
    """Reading a `MODEL.json` object's fields: a missing field or a value of the wrong type becomes a `DataError`
    naming the file (a `DataError` raised inside passes as it is)."""
    try:
        yield
    except KeyError as e:
        raise DataError(f"the model file lacks the field {e.args[0]!r}", path=path) from None
    except (TypeError, ValueError) as e:
        if isinstance(e, DataError):
            raise
        raise DataError(f"malformed model file ({e})", path=path) from None
