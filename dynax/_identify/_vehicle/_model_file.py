"""`save_model` / `load_model`: a learned vehicle model to and from its JSON file (`MODEL.json`)."""

import json
import os

from ..._errors import DataError, UsageError
from ..._model._helicopter import Helicopter
from ..._model._quadrotor import Quadrotor
from ._fit import model_from_json
from ._quadrotor import quadrotor_from_json, quadrotor_to_json


def save_model(model: Quadrotor, path: str | os.PathLike, **info) -> None:
    """Write a fitted `Quadrotor` as `MODEL.json` (atomically), with `info` (criterion, loss, ...) in it.

    Helicopter fits are written by `dynax fit helicopter` (`model_to_json` of the fit).
    """
    if not isinstance(model, Quadrotor):
        raise UsageError(f"save_model: expected a Quadrotor, got {type(model).__name__}")
    path = str(path)
    text = json.dumps(quadrotor_to_json(model, **info), indent=2, allow_nan=False)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"save_model: cannot write {path}: the folder {folder} does not exist")
    tmp = os.path.join(folder, f".{os.path.basename(path)}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text + "\n")
        os.replace(tmp, path)
    except OSError as e:  # no permission, a name over the file system's limit, a full disk: the user's path named
        raise UsageError(f"save_model: cannot write {path} ({e.strerror or e})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def load_model(path: str | os.PathLike) -> Quadrotor | Helicopter:
    """The vehicle model in a `MODEL.json` written by `dynax fit` or `save_model`.

    **Returns:** a `Quadrotor` or a `Helicopter`, by the file's `system`.

    **Raises:** `DataError` naming the file (and the field) for a file that is not such a model.
    """
    path = str(path)
    try:
        with open(path, encoding="utf-8") as f:
            obj = json.load(f)
    except OSError as e:
        raise DataError(f"cannot be read ({e.strerror or e})", path=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DataError(f"is not a JSON model file ({e})", path=path) from None
    if not isinstance(obj, dict):
        raise DataError("is not a model file (a JSON object is expected)", path=path)
    if obj.get("system") == "quadrotor":
        return quadrotor_from_json(obj, path)
    if obj.get("system") == "helicopter":
        return model_from_json(obj, path)
    raise DataError(f"is not a vehicle model file (system = {obj.get('system')!r})", path=path, column="system")
