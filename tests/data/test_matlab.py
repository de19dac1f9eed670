"""MATLAB files as users have them: iddata-style matrix variables mapped by name[col], v5 and v7.3 (HDF5)."""

import h5py
import numpy as np
import pytest
import scipy.io

import dynax


def _signals(n=400):
    t = np.arange(n) * 0.01
    q = np.sin(t)
    return t, q, np.cos(t), 2 * np.sin(3 * t)


def test_v5_matrix_variables_are_mapped_by_column(tmp_path):
    t, q, dq, force = _signals()
    path = tmp_path / "iddata.mat"
    # iddata style: outputs y (N x 2), input u (N x 1); a second matrix stored transposed (2 x N).
    scipy.io.savemat(
        path,
        {
            "t": t[:, None],
            "y": np.column_stack([q, dq]),
            "u": force[:, None],
            "yT": np.vstack([q, dq]),
            "Ts": 0.01,
            "note": "rig 3",
        },
    )
    run = dynax.load_trajectory(path, "linear_axis", mapping={"q": "y[0]", "dq": "y[1]", "force": "u"})
    np.testing.assert_array_equal(np.asarray(run.xs), np.column_stack([q, dq]))
    np.testing.assert_array_equal(np.asarray(run.us)[:, 0], force)
    transposed = dynax.load_trajectory(path, "linear_axis", mapping={"q": "yT[0]", "dq": "yT[1]", "force": "u"})
    np.testing.assert_array_equal(np.asarray(transposed.xs), np.asarray(run.xs))
    with pytest.raises(dynax.DataError, match=r"y\[0\]', 'y\[1\]'"):  # the error lists the columns there are
        dynax.load_trajectory(path, "linear_axis", mapping={"q": "y[2]", "force": "u"})


def _write_v73(path, variables):
    """A file laid out as MATLAB -v7.3 writes it: a 512-byte text header, HDF5, dimensions reversed."""
    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            value = np.atleast_2d(np.asarray(value))
            dataset = f.create_dataset(name, data=value.T)  # MATLAB is column-major: h5py sees the transpose
            dataset.attrs["MATLAB_class"] = np.bytes_("double")
        f.create_dataset("label", data=np.frombuffer(b"rig", dtype=np.uint8).astype(np.uint16)).attrs[
            "MATLAB_class"
        ] = np.bytes_("char")
        f.create_group("#refs#")
    with open(path, "r+b") as f:
        f.write(
            b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 12:00:00 2026 HDF5 schema 1.00 .".ljust(
                116
            )
            + b"\0" * 8
            + b"\x00\x02IM"
        )  # subsystem offset, version 0x0200, endianness


def test_v73_hdf5_file_reads_like_v5(tmp_path):
    t, q, dq, force = _signals()
    path = tmp_path / "v73.mat"
    _write_v73(path, {"t": t[:, None], "y": np.column_stack([q, dq]), "u": force[:, None]})
    with pytest.raises(NotImplementedError):
        scipy.io.loadmat(path)  # what a user hits with scipy alone
    run = dynax.load_trajectory(path, "linear_axis", mapping={"q": "y[0]", "dq": "y[1]", "force": "u"})
    np.testing.assert_array_equal(np.asarray(run.ts), t)
    np.testing.assert_array_equal(np.asarray(run.xs), np.column_stack([q, dq]))


def test_a_corrupt_mat_file_is_refused_by_name(tmp_path):
    path = tmp_path / "broken.mat"
    path.write_bytes(b"MATLAB 7.3 MAT-file" + b"\0" * 600)
    with pytest.raises(dynax.DataError, match="broken.mat.*v7.3"):
        dynax.load_trajectory(path, "linear_axis")


def test_the_emps_benchmark_file_still_loads(datasets):
    run = dynax.load_trajectory(
        datasets / "emps" / "DATA_EMPS.mat",
        "linear_axis",
        mapping={"q": "qm", "force": "vir"},
        scale={"force": 35.15065188},
    )
    assert len(run) == 24841 and run.is_uniform


def test_v73_without_h5py_says_what_to_install(tmp_path, monkeypatch):
    t, q, dq, force = _signals(50)
    path = tmp_path / "v73.mat"
    _write_v73(path, {"t": t[:, None], "q": q[:, None], "force": force[:, None]})
    monkeypatch.setitem(__import__("sys").modules, "h5py", None)  # as if it were not installed
    with pytest.raises(dynax.DataError, match=r'v73.mat.*needs h5py: pip install "dynax\[mat\]"'):
        dynax.load_trajectory(path, "linear_axis")
