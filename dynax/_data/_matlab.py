"""MATLAB `.mat` files as users have them: vectors, iddata-style matrix variables, v4/v5 and v7.3 (HDF5).

A vector variable (`t`, `qm`) is one column under its own name. A matrix variable with several
columns, as System Identification Toolbox users store outputs and inputs (`y` of size N x ny,
`u` of size N x nu), becomes one column per matrix column, named `name[col]` with `col` counted
from 0 as in Python: `y[0]` is MATLAB's `y(:,1)`. Samples run along the longer dimension, so an
ny x N matrix is read the same way. Scalars, strings, structs and cell arrays are skipped.

Files of version 4 to 7 are read by `scipy.io.loadmat`; version 7.3 files are HDF5 and are read
with `h5py` (`pip install "dynax[mat]"`). HDF5 stores MATLAB's column-major arrays with their
dimensions reversed; they are transposed back here so both versions give the same columns.
"""

import numpy as np

from .._errors import DataError


def _columns(name: str, arr: np.ndarray, columns: dict) -> None:
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool) or np.iscomplexobj(arr):
        return
    if arr.ndim == 1 or (arr.ndim == 2 and 1 in arr.shape):
        if arr.size > 1:
            columns[name] = arr.reshape(-1)
    elif arr.ndim == 2:
        matrix = arr if arr.shape[0] >= arr.shape[1] else arr.T
        for j in range(matrix.shape[1]):
            columns[f"{name}[{j}]"] = matrix[:, j]


def _read_v73(path: str) -> dict:
    try:
        import h5py
    except ImportError:
        raise DataError(
            'is a MATLAB v7.3 (HDF5) file; reading it needs h5py: pip install "dynax[mat]"', path=path
        ) from None
    columns: dict = {}
    try:
        with h5py.File(path, "r") as f:
            for name, item in f.items():
                if name.startswith("#") or not isinstance(item, h5py.Dataset):
                    continue  # MATLAB's reference store, structs (groups)
                matlab_class = item.attrs.get("MATLAB_class", b"double")
                matlab_class = matlab_class.decode() if isinstance(matlab_class, bytes) else str(matlab_class)
                if matlab_class in ("char", "cell", "struct", "function_handle") or item.dtype.names:
                    continue  # text, containers and complex numbers (compound dtype) are not signals
                _columns(name, np.asarray(item[()]).T, columns)
    except DataError:
        raise
    except Exception as e:
        raise DataError(f"cannot be read as a MATLAB v7.3 (HDF5) file ({e})", path=path) from None
    return columns


def read_mat_columns(path: str) -> dict[str, np.ndarray]:
    """The numeric columns of a MATLAB `.mat` file (any version), matrix variables split as `name[col]`.

    **Arguments:** `path`, the file.

    **Returns:** column name -> 1-d array.

    **Raises:** `DataError` naming the file when it cannot be read (and what to install for v7.3).
    """
    import scipy.io

    path = str(path)
    try:
        with open(path, "rb") as f:
            header = f.read(128)
    except OSError as e:
        raise DataError(f"cannot be opened ({e})", path=path) from None
    if b"MATLAB 7.3" in header or header.startswith(b"\x89HDF"):
        return _read_v73(path)
    try:
        data = scipy.io.loadmat(path)
    except NotImplementedError:  # scipy's answer to a v7.3 file without the usual header text
        return _read_v73(path)
    except Exception as e:
        raise DataError(f"cannot be read as a MATLAB .mat file ({e})", path=path) from None
    columns: dict = {}
    for name, value in data.items():
        if not name.startswith("__"):
            _columns(name, np.asarray(value), columns)
    return columns
