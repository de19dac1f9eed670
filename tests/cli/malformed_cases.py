"""Malformed inputs, as a careless or hostile user gives them, and what dynax must do with each.

Each `Case` builds its inputs in a folder and names the command line (or Python call) and the
expected outcome: `refuse` (exit status 2, a one-line message containing `message`, nothing written
to `--out`) or `accept` (exit status 0 and an output that passes `check`). Used by
`tests/cli/test_refusals.py` and by `experiments/malformed_inputs.py`, which tallies the outcomes.
"""

from collections.abc import Callable
import contextlib
import dataclasses
import io
import json
import os
import pathlib
import traceback

import numpy as np

ACROBOT_HEADER = ("t", "q1", "q2", "dq1", "dq2", "tau2")


@dataclasses.dataclass(frozen=True)
class Case:
    id: str
    build: Callable  # build(folder: Path, fixtures: dict) -> argv (list of str) or a Python callable
    expect: str  # "refuse" or "accept"
    message: str = ""  # a substring the one-line refusal must contain
    check: Callable | None = None  # check(out: Path) -> bool, for "accept"
    needs_permissions: bool = False  # about file permissions, which do not bind the superuser
    slow: bool = False  # runs a fit or a rollout (seconds, not milliseconds)


def make_fixtures(root) -> dict:
    """The valid inputs that the cases corrupt: an acrobot record, a helicopter flight, a model file."""
    import dynax
    from dynax import Helicopter
    from dynax.internal import initial_helicopter
    from dynax.synthetic import generate_helicopter_flight

    root = pathlib.Path(root)
    ts = np.arange(0, 2.0, 0.01)
    us = np.sin(3 * ts)[:, None] + 0.5 * np.sin(7.3 * ts)[:, None]
    sim = dynax.simulate(dynax.Acrobot(), np.array([0.3, 0.0, 0.0, 0.0]), ts, us)
    acrobot = dynax.Trajectory(ts, np.asarray(sim.xs), us, ACROBOT_HEADER[1:5], ("tau2",), "acrobot")
    dynax.save_trajectory(acrobot, root / "acrobot.csv")
    heli = generate_helicopter_flight("hover", 4.0, seed=1, truth=Helicopter())
    dynax.save_trajectory(heli, root / "heli.csv")
    body = initial_helicopter("acceleration").body_model
    model = {
        "system": "helicopter",
        "model": "acceleration",
        "features": list(body.feature_names),
        "mask": [[int(v) for v in row] for row in body.mask],
        "weights": np.asarray(body.weights).tolist(),
        "gravity": 9.81,
    }
    (root / "model.json").write_text(json.dumps(model))
    return {
        "acrobot": root / "acrobot.csv",
        "heli": root / "heli.csv",
        "model": root / "model.json",
        "acrobot_table": np.column_stack([ts, np.asarray(sim.xs), us]),
    }


# --- helpers that write corrupted copies ----------------------------------------------------


def _table_csv(path, header, table, fmt="%.17g"):
    lines = [",".join(header)] + [",".join(fmt % v for v in row) for row in table]
    pathlib.Path(path).write_text("\n".join(lines) + "\n")
    return str(path)


def _acrobot_with(folder, fx, edit, name="run.csv", header=ACROBOT_HEADER):
    """The acrobot table after `edit(table) -> table`, as a CSV."""
    table = edit(np.array(fx["acrobot_table"], copy=True))
    return _table_csv(folder / name, header, table)


def _text(folder, fx, edit, name="run.csv"):
    """The acrobot CSV's text after `edit(text) -> text`."""
    path = folder / name
    path.write_text(edit(pathlib.Path(fx["acrobot"]).read_text()))
    return str(path)


def _bytes(folder, data, name="run.csv"):
    path = folder / name
    path.write_bytes(data)
    return str(path)


def _cell(text, row, column, value):
    lines = text.splitlines()
    cells = lines[row].split(",")
    cells[column] = value
    lines[row] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _identify(path, *extra, method="power", out="out.json"):
    return ["identify", "acrobot", str(path), "--method", method, *extra, "--out", out]


def _npz(folder, fx, columns_edit, name="run.npz"):
    table = fx["acrobot_table"]
    columns = {n: table[:, i] for i, n in enumerate(ACROBOT_HEADER)}
    columns = columns_edit(columns)
    np.savez(folder / name, **columns)
    return str(folder / name)


def _heli_with(folder, fx, edit, name="heli_bad.csv"):
    text = pathlib.Path(fx["heli"]).read_text().splitlines()
    header, rows = text[0].split(","), np.array([[float(v) for v in line.split(",")] for line in text[1:]])
    rows = edit(header, rows)
    return _table_csv(folder / name, header, rows)


def _set_col(header, rows, name, index, value):
    rows[index, header.index(name)] = value
    return rows


def _model_with(folder, fx, edit, name="model_bad.json"):
    obj = json.loads(pathlib.Path(fx["model"]).read_text())
    text = edit(obj)
    (folder / name).write_text(text if isinstance(text, str) else json.dumps(text))
    return str(folder / name)


def _evaluate(model, data, *extra, out="out.json"):
    return ["evaluate", str(model), str(data), "--horizons", "0.1,0.2", "--stride", "10", *extra, "--out", out]


def _nominal(folder, fx, text):
    (folder / "nominal.json").write_text(text)
    return ["diagnose", "acrobot", str(fx["acrobot"]), "--nominal", str(folder / "nominal.json"), "--out", "report"]


def _readonly(folder):
    ro = folder / "readonly"
    ro.mkdir(exist_ok=True)
    os.chmod(ro, 0o555)
    return ro


def _append_column(name):
    def edit(text):
        lines = text.splitlines()
        return "\n".join([lines[0] + "," + name] + [line + ",0" for line in lines[1:]]) + "\n"

    return edit


def _nan_weight(obj):
    obj["weights"][0][0] = "NAN_HERE"
    return json.dumps(obj).replace('"NAN_HERE"', "NaN")


def _unstable(obj):
    """Each body axis's damping made a growth rate of 300 /s: every rollout leaves the finite range in 0.1 s."""
    for axis, name in enumerate(("u", "v", "w", "p", "q", "r")):
        obj["weights"][axis][obj["features"].index(name)] = 300.0
        obj["mask"][axis][obj["features"].index(name)] = 1
    return obj


def _fifo(folder):
    """A named pipe, standing in for /dev/null (which an atomic rename would replace)."""
    path = folder / "pipe"
    os.mkfifo(path)
    return path


def _gap(last):
    def edit(t):
        t[-1, 0] = last
        return t

    return edit


def _params_finite(out):
    obj = json.loads(pathlib.Path(out).read_text())
    return all(isinstance(v, float) and np.isfinite(v) for v in obj["parameters"].values())


def _acrobot_params_close(out):
    """The power model on noise-free data of the default acrobot (simulated with another integrator
    than the model's finite differences) recovers its inertial and gravity parameters to 5 %."""
    import dynax

    obj = json.loads(pathlib.Path(out).read_text())["parameters"]
    truth = dynax.Acrobot().base_parameters
    return _params_finite(out) and all(
        abs(obj[k] - float(truth[k])) < 0.05 * abs(float(truth[k]))
        for k in ("theta1", "theta2", "theta3", "theta4", "theta5")
    )


def _mode_follows_umask(out):
    mask = os.umask(0o022)
    os.umask(mask)
    return (os.stat(out).st_mode & 0o777) == (0o666 & ~mask) and _params_finite(out)


def _metrics_honest(out):
    """Diverged horizons are null with a 'diverged' status, never a huge number standing for inf."""
    obj = json.loads(pathlib.Path(out).read_text())
    values = [v for group in obj["mse"].values() for v in group]
    status = obj.get("status", ["ok"] * len(obj["horizons_s"]))
    finite_ok = all(v is None or (np.isfinite(v) and v < 1e100) for v in values) and None in values
    # A horizon's error is null exactly where its status says the rollouts diverged.
    nulls_explained = all(
        (v is None) == (status[i] == "diverged") for g in obj["mse"].values() for i, v in enumerate(g)
    )
    return finite_ok and nulls_explained


def _heli_model_fitted(out):
    obj = json.loads(pathlib.Path(out).read_text())
    return all(np.isfinite(v) for v in obj["parameters"].values()) and abs(obj["parameters"]["dp/p"] + 12.78) < 2.0


# --- the cases -----------------------------------------------------------------------------

CASES = [
    # Files that are not what they claim to be.
    Case(
        "missing-column",
        lambda d, fx: _identify(_text(d, fx, lambda s: s.replace("dq2,", "dqX,", 1))),
        "refuse",
        "column 'dq2'",
    ),
    Case(
        "non-numeric-cell",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 7, 1, "oops"))),
        "refuse",
        "row 7: non-numeric",
    ),
    Case(
        "nan-cell",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 9, 3, "nan"))),
        "refuse",
        "row 9: non-finite",
    ),
    Case("inf-cell", lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 9, 3, "inf"))), "refuse", "non-finite"),
    Case(
        "minus-inf-cell",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 9, 3, "-Infinity"))),
        "refuse",
        "non-finite",
    ),
    Case(
        "digit-separator-1_0",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 5, 5, "1_0"))),
        "refuse",
        "non-numeric value '1_0'",
    ),
    Case(
        "non-ascii-digits",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 5, 5, "\u0661\u0662"))),
        "refuse",
        "non-numeric",
    ),
    Case(
        "hex-number", lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 5, 5, "0x10"))), "refuse", "non-numeric"
    ),
    Case(
        "empty-cell",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 5, 2, ""))),
        "refuse",
        "row 5: non-numeric",
    ),
    Case(
        "time-repeated",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 5, 0, "0.03"))),
        "refuse",
        "time does not strictly increase",
    ),
    Case(
        "time-reversed",
        lambda d, fx: _identify(_acrobot_with(d, fx, lambda t: t[::-1])),
        "refuse",
        "time does not strictly increase",
    ),
    Case(
        "ragged-row",
        lambda d, fx: _identify(_text(d, fx, lambda s: "\n".join(s.splitlines()[:3] + ["1,2"] + s.splitlines()[3:]))),
        "refuse",
        "row 3: has 2 fields but the header has 6",
    ),
    Case("empty-file", lambda d, fx: _identify(_bytes(d, b"")), "refuse", "empty"),
    Case("header-only", lambda d, fx: _identify(_bytes(d, b"t,q1,q2,dq1,dq2,tau2\n")), "refuse", "has 0 samples"),
    Case("no-such-file", lambda d, fx: _identify(d / "nope.csv"), "refuse", "no such file"),
    Case("data-is-directory", lambda d, fx: _identify(d), "refuse", "is a directory"),
    Case(
        "binary-garbage",
        lambda d, fx: _identify(_bytes(d, np.random.default_rng(0).bytes(4000))),
        "refuse",
        "not a text CSV",
    ),
    Case(
        "binary-garbage-no-nul", lambda d, fx: _identify(_bytes(d, bytes(range(128, 256)) * 20)), "refuse", "not UTF-8"
    ),
    Case(
        "latin-1-text",
        lambda d, fx: _identify(
            _bytes(
                d,
                pathlib.Path(fx["acrobot"])
                .read_text()
                .replace("tau2", "tau2 (N\u00b7m, m\u00e9tre)", 1)
                .encode("latin-1", "replace"),
            )
        ),
        "refuse",
        "not UTF-8",
    ),
    Case(
        "png-named-csv",
        lambda d, fx: _identify(_bytes(d, b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(64))),
        "refuse",
        "not a text CSV",
    ),
    Case(  # a spreadsheet's export in a locale whose decimal mark is the comma: read as the CSV it is
        "semicolon-separated",
        lambda d, fx: _identify(_text(d, fx, lambda s: s.replace(",", ";"))),
        "accept",
        check=_acrobot_params_close,
        slow=True,
    ),
    Case(
        "duplicate-column",
        lambda d, fx: _identify(_text(d, fx, _append_column("q1"))),
        "refuse",
        "appears twice (columns 2 and 7)",
    ),
    Case(
        "value-1e308",
        lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 20, 2, "1e308"))),
        "refuse",
        "row 20: value 1e+308",
    ),
    Case(
        "value-1e13", lambda d, fx: _identify(_text(d, fx, lambda s: _cell(s, 20, 5, "1e13"))), "refuse", "beyond 1e+12"
    ),
    Case(
        "diagnose-binary-data",
        lambda d, fx: ["diagnose", "acrobot", _bytes(d, np.random.default_rng(1).bytes(3000)), "--out", "report"],
        "refuse",
        "not a text CSV",
    ),
    Case(
        "diagnose-latin-1-validation",
        lambda d, fx: [
            "diagnose",
            "acrobot",
            str(fx["acrobot"]),
            "--validation",
            _bytes(d, "t,q1,q2,dq1,dq2,tau2 # m\u00e9tre\n0,0,0,0,0,0\n".encode("latin-1"), "v.csv"),
            "--out",
            "report",
        ],
        "refuse",
        "not UTF-8",
    ),
    Case(
        "fit-latin-1-data",
        lambda d, fx: ["fit", "helicopter", _bytes(d, "t,x\n0,\u00e9\n".encode("latin-1")), "--out", "out.json"],
        "refuse",
        "not UTF-8",
    ),
    Case(
        "evaluate-binary-data",
        lambda d, fx: _evaluate(fx["model"], _bytes(d, np.random.default_rng(2).bytes(3000))),
        "refuse",
        "not a text CSV",
    ),
    Case(
        "fit-data-is-directory",
        lambda d, fx: ["fit", "helicopter", str(d), "--out", "out.json"],
        "refuse",
        "is a directory",
    ),
    # --map / --scale.
    Case(
        "scale-overflows-1e308",
        lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=1e308"),
        "refuse",
        "after scaling",
    ),
    Case(
        "scale-absurd-1e20", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=1e20"), "refuse", "after scaling"
    ),
    Case("scale-zero", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=0"), "refuse", "is zero"),
    Case("scale-nan", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=nan"), "refuse", "not finite"),
    Case("scale-inf", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=inf"), "refuse", "not finite"),
    Case(
        "scale-digit-separator", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=1_0"), "refuse", "not a number"
    ),
    Case("scale-text", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau2=abc"), "refuse", "not a number"),
    Case("scale-unknown-name", lambda d, fx: _identify(fx["acrobot"], "--scale", "tau7=2"), "refuse", "tau7"),
    Case("offset-nan", lambda d, fx: _identify(fx["acrobot"], "--offset", "q1=nan"), "refuse", "not finite"),
    Case("offset-text", lambda d, fx: _identify(fx["acrobot"], "--offset", "q1=pi"), "refuse", "not a number"),
    Case("offset-unknown-name", lambda d, fx: _identify(fx["acrobot"], "--offset", "q7=1"), "refuse", "q7"),
    Case("map-twice", lambda d, fx: _identify(fx["acrobot"], "--map", "t=t,t=q1"), "refuse", "'t' is given twice"),
    Case(
        "map-malformed", lambda d, fx: _identify(fx["acrobot"], "--map", "q1"), "refuse", "not of the form NAME=VALUE"
    ),
    Case(
        "map-to-missing-column",
        lambda d, fx: _identify(fx["acrobot"], "--map", "q1=nothere"),
        "refuse",
        "column 'nothere'",
    ),
    # Time stamps.
    Case("gap-1e5", lambda d, fx: _identify(_acrobot_with(d, fx, _gap(1e5))), "refuse", "row 200: a gap in the record"),
    Case("gap-1e9", lambda d, fx: _identify(_acrobot_with(d, fx, _gap(1e9))), "refuse", "a gap in the record"),
    Case(
        "gap-in-middle",
        lambda d, fx: _identify(
            _acrobot_with(d, fx, lambda t: np.concatenate([t[:100], t[100:] + np.r_[60, 0, 0, 0, 0, 0]]))
        ),
        "refuse",
        "row 101: a gap",
    ),
    Case(
        "near-duplicate-stamp",
        lambda d, fx: _identify(
            _acrobot_with(d, fx, lambda t: np.concatenate([t[:50], [t[49] + np.r_[1e-12, 0, 0, 0, 0, 0]], t[50:]]))
        ),
        "refuse",
        "near-duplicate time stamps",
    ),
    Case(
        "time-in-epoch-seconds",
        lambda d, fx: _identify(_acrobot_with(d, fx, lambda t: t + np.r_[1.7e9, 0, 0, 0, 0, 0])),
        "accept",
        check=_acrobot_params_close,
        slow=True,
    ),
    Case(
        "time-in-epoch-microseconds",
        lambda d, fx: _identify(
            _acrobot_with(d, fx, lambda t: t * np.r_[1e6, 1, 1, 1, 1, 1] + np.r_[1.7e15, 0, 0, 0, 0, 0])
        ),
        "refuse",
        "beyond 1e+12",
    ),
    # Too little data.
    Case(
        "three-samples-simulation",
        lambda d, fx: _identify(_acrobot_with(d, fx, lambda t: t[:3]), method="simulation"),
        "refuse",
        "has 3 samples",
    ),
    Case(
        "three-samples-power", lambda d, fx: _identify(_acrobot_with(d, fx, lambda t: t[:3])), "refuse", "has 3 samples"
    ),
    Case(
        "ten-samples-power", lambda d, fx: _identify(_acrobot_with(d, fx, lambda t: t[:10])), "refuse", "has 10 samples"
    ),
    # Files that are fine and must stay accepted.
    Case(
        "utf8-bom",
        lambda d, fx: _identify(_bytes(d, b"\xef\xbb\xbf" + pathlib.Path(fx["acrobot"]).read_bytes())),
        "accept",
        check=_acrobot_params_close,
        slow=True,
    ),
    Case(
        "crlf-and-spaces",
        lambda d, fx: _identify(_text(d, fx, lambda s: s.replace(",", " , ").replace("\n", "\r\n"))),
        "accept",
        check=_params_finite,
        slow=True,
    ),
    Case(
        "file-mode-follows-umask",
        lambda d, fx: _identify(fx["acrobot"]),
        "accept",
        check=_mode_follows_umask,
        slow=True,
    ),
    # .npz and .mat.
    Case(
        "npz-text-garbage",
        lambda d, fx: _identify(_bytes(d, b"this is not an archive\n", "run.npz")),
        "refuse",
        "not an .npz archive",
    ),
    Case(
        "npz-complex-column",
        lambda d, fx: _identify(_npz(d, fx, lambda c: {**c, "q1": c["q1"] + 1j})),
        "refuse",
        "complex",
    ),
    Case(
        "npz-2d-column",
        lambda d, fx: _identify(_npz(d, fx, lambda c: {**c, "q1": np.stack([c["q1"], c["q1"]], 1)})),
        "refuse",
        "a column must be one vector",
    ),
    Case(
        "npz-object-column",
        lambda d, fx: _identify(_npz(d, fx, lambda c: {**c, "q1": np.array([{}] * len(c["t"]), dtype=object)})),
        "refuse",
        "cannot be read as .npz",
    ),
    Case(
        "npz-string-column",
        lambda d, fx: _identify(_npz(d, fx, lambda c: {**c, "q1": np.array(["x"] * len(c["t"]))})),
        "refuse",
        "non-numeric value 'x'",
    ),
    Case(
        "npz-missing-column",
        lambda d, fx: _identify(_npz(d, fx, lambda c: {k: v for k, v in c.items() if k != "dq2"})),
        "refuse",
        "column 'dq2': missing column; the file has ['dq1'",
    ),
    Case(
        "mat-garbage",
        lambda d, fx: _identify(_bytes(d, b"MATLAB? no" * 50, "run.mat")),
        "refuse",
        "cannot be read as a MATLAB",
    ),
    Case("mat-is-directory", lambda d, fx: _identify((d / "x.mat").mkdir() or d / "x.mat"), "refuse", "x.mat"),
    # --out.
    Case(
        "out-parent-is-file",
        lambda d, fx: _identify(fx["acrobot"], out=str(pathlib.Path(fx["acrobot"]) / "out.json")),
        "refuse",
        "is a file, not a folder",
    ),
    Case(
        "out-read-only-folder",
        lambda d, fx: _identify(fx["acrobot"], out=str(_readonly(d) / "out.json")),
        "refuse",
        "permission denied",
        needs_permissions=True,
    ),
    Case("out-is-directory", lambda d, fx: _identify(fx["acrobot"], out=str(d)), "refuse", "is a directory"),
    Case(
        "out-is-the-data",
        lambda d, fx: _identify(_text(d, fx, lambda s: s), out=str(d / "run.csv")),
        "refuse",
        "is the input",
    ),
    Case("out-is-a-pipe", lambda d, fx: _identify(fx["acrobot"], out=str(_fifo(d))), "refuse", "is not a regular file"),
    Case("out-empty", lambda d, fx: _identify(fx["acrobot"], out=""), "refuse", "--out is empty"),
    Case(
        "diagnose-out-parent-is-file",
        lambda d, fx: ["diagnose", "acrobot", str(fx["acrobot"]), "--out", str(pathlib.Path(fx["acrobot"]) / "r")],
        "refuse",
        "is a file, not a folder",
    ),
    Case(
        "diagnose-out-is-file",
        lambda d, fx: ["diagnose", "acrobot", str(fx["acrobot"]), "--out", _bytes(d, b"x", "report")],
        "refuse",
        "is a file; give a folder",
    ),
    Case(
        "diagnose-out-holds-data",
        lambda d, fx: ["diagnose", "acrobot", _text(d, fx, lambda s: s), "--out", str(d)],
        "refuse",
        "holds the input",
    ),
    Case(
        "diagnose-out-holds-other-files",
        lambda d, fx: (
            ((d / "report").mkdir(), (d / "report" / "thesis.tex").write_text("x"))[-1]
            and ["diagnose", "acrobot", str(fx["acrobot"]), "--out", str(d / "report")]
        ),
        "refuse",
        "which dynax did not write",
    ),
    Case(
        "diagnose-out-read-only",
        lambda d, fx: ["diagnose", "acrobot", str(fx["acrobot"]), "--out", str(_readonly(d) / "r")],
        "refuse",
        "permission denied",
        needs_permissions=True,
    ),
    Case(
        "demo-out-parent-is-file",
        lambda d, fx: ["demo", "--out", str(pathlib.Path(fx["acrobot"]) / "r")],
        "refuse",
        "is a file, not a folder",
    ),
    Case(
        "demo-out-read-only",
        lambda d, fx: ["demo", "--out", str(_readonly(d) / "r")],
        "refuse",
        "permission denied",
        needs_permissions=True,
    ),
    # diagnose --nominal.
    Case(
        "nominal-parameters-list",
        lambda d, fx: _nominal(d, fx, '{"parameters": [1, 2]}'),
        "refuse",
        "a JSON list as 'parameters'",
    ),
    Case(
        "nominal-parameter-string",
        lambda d, fx: _nominal(d, fx, '{"parameters": {"theta1": "1.3"}}'),
        "refuse",
        "parameter 'theta1' is \"1.3\"",
    ),
    Case("nominal-parameter-nan", lambda d, fx: _nominal(d, fx, '{"parameters": {"theta1": NaN}}'), "refuse", "NaN"),
    Case(
        "nominal-parameter-null", lambda d, fx: _nominal(d, fx, '{"parameters": {"theta1": null}}'), "refuse", "is null"
    ),
    Case("nominal-overflow", lambda d, fx: _nominal(d, fx, '{"parameters": {"theta1": 1e999}}'), "refuse", "overflows"),
    Case("nominal-not-json", lambda d, fx: _nominal(d, fx, "theta1 = 1.3"), "refuse", "is not valid JSON"),
    Case("nominal-top-level-list", lambda d, fx: _nominal(d, fx, "[1, 2]"), "refuse", "holds a JSON list"),
    # fit helicopter.
    Case(
        "fit-gap-1e5",
        lambda d, fx: [
            "fit",
            "helicopter",
            _heli_with(d, fx, lambda h, r: _set_col(h, r, "t", -1, 1e5)),
            "--out",
            "out.json",
        ],
        "refuse",
        "a gap in the record",
    ),
    Case(
        "fit-gap-1e9",
        lambda d, fx: [
            "fit",
            "helicopter",
            _heli_with(d, fx, lambda h, r: _set_col(h, r, "t", -1, 1e9)),
            "--out",
            "out.json",
        ],
        "refuse",
        "a gap in the record",
    ),
    Case(
        "fit-three-samples",
        lambda d, fx: ["fit", "helicopter", _heli_with(d, fx, lambda h, r: r[:3]), "--out", "out.json"],
        "refuse",
        "has 3 samples",
    ),
    Case(
        "fit-horizon-inf",
        lambda d, fx: [
            "fit",
            "helicopter",
            str(fx["heli"]),
            "--criterion",
            "lagged",
            "--horizon",
            "inf",
            "--out",
            "out.json",
        ],
        "refuse",
        "--horizon must be a positive finite",
    ),
    Case(
        "fit-horizon-nan",
        lambda d, fx: [
            "fit",
            "helicopter",
            str(fx["heli"]),
            "--criterion",
            "lagged",
            "--horizon",
            "nan",
            "--out",
            "out.json",
        ],
        "refuse",
        "--horizon must be a positive finite",
    ),
    Case(
        "fit-horizon-longer-than-data",
        lambda d, fx: [
            "fit",
            "helicopter",
            str(fx["heli"]),
            "--criterion",
            "lagged",
            "--horizon",
            "100",
            "--out",
            "out.json",
        ],
        "refuse",
        "needs at least",
    ),
    Case(
        "fit-quaternion-norm-5",
        lambda d, fx: [
            "fit",
            "helicopter",
            _heli_with(d, fx, lambda h, r: _set_col(h, r, "qw", 10, 5.0)),
            "--out",
            "out.json",
        ],
        "refuse",
        "row 11: the quaternion",
    ),
    Case(
        "fit-quaternion-zero",
        lambda d, fx: [
            "fit",
            "helicopter",
            _heli_with(
                d, fx, lambda h, r: (r.__setitem__((slice(None), slice(h.index("qw"), h.index("qz") + 1)), 0.0), r)[1]
            ),
            "--out",
            "out.json",
        ],
        "refuse",
        "the quaternion",
    ),
    Case(
        "fit-quaternion-rounded",
        lambda d, fx: ["fit", "helicopter", _heli_with(d, fx, lambda h, r: np.round(r, 3)), "--out", "out.json"],
        "accept",
        check=_heli_model_fitted,
        slow=True,
    ),
    # evaluate.
    Case("evaluate-model-is-directory", lambda d, fx: _evaluate(d, fx["heli"]), "refuse", "is a directory"),
    Case(
        "evaluate-model-binary",
        lambda d, fx: _evaluate(_bytes(d, bytes(range(256)), "m.json"), fx["heli"]),
        "refuse",
        "not UTF-8",
    ),
    Case(
        "evaluate-model-json-list",
        lambda d, fx: _evaluate(_model_with(d, fx, lambda o: "[1, 2, 3]"), fx["heli"]),
        "refuse",
        "holds a JSON list",
    ),
    Case(
        "evaluate-model-not-json",
        lambda d, fx: _evaluate(_model_with(d, fx, lambda o: "weights: 1"), fx["heli"]),
        "refuse",
        "not valid JSON",
    ),
    Case(
        "evaluate-model-missing-field",
        lambda d, fx: _evaluate(_model_with(d, fx, lambda o: {k: v for k, v in o.items() if k != "mask"}), fx["heli"]),
        "refuse",
        "'mask'",
    ),
    Case(
        "evaluate-model-nan-weight",
        lambda d, fx: _evaluate(_model_with(d, fx, _nan_weight), fx["heli"]),
        "refuse",
        "NaN",
    ),
    Case(
        "evaluate-model-null-weight",
        lambda d, fx: _evaluate(
            _model_with(d, fx, lambda o: {**o, "weights": [[None] + r[1:] for r in o["weights"]]}), fx["heli"]
        ),
        "refuse",
        "weight [0][0]",
    ),
    Case(
        "evaluate-model-kind-edited",
        lambda d, fx: _evaluate(_model_with(d, fx, lambda o: {**o, "model": "linear"}), fx["heli"]),
        "refuse",
        "'model' is 'linear' but the features",
    ),
    Case(
        "evaluate-horizons-inf",
        lambda d, fx: ["evaluate", str(fx["model"]), str(fx["heli"]), "--horizons", "0.1,inf", "--out", "out.json"],
        "refuse",
        "--horizons",
    ),
    Case(
        "evaluate-horizons-text",
        lambda d, fx: ["evaluate", str(fx["model"]), str(fx["heli"]), "--horizons", "a,b", "--out", "out.json"],
        "refuse",
        "--horizons",
    ),
    Case(
        "evaluate-horizon-longer-than-data",
        lambda d, fx: ["evaluate", str(fx["model"]), str(fx["heli"]), "--horizons", "50", "--out", "out.json"],
        "refuse",
        "needs at least",
    ),
    Case(
        "evaluate-gap",
        lambda d, fx: _evaluate(fx["model"], _heli_with(d, fx, lambda h, r: _set_col(h, r, "t", -1, 1e5))),
        "refuse",
        "a gap in the record",
    ),
    Case(
        "evaluate-out-is-model",
        lambda d, fx: _evaluate(_model_with(d, fx, lambda o: o), fx["heli"], out=str(d / "model_bad.json")),
        "refuse",
        "is the input",
    ),
    Case(
        "evaluate-diverging-model",
        lambda d, fx: _evaluate(_model_with(d, fx, _unstable), fx["heli"]),
        "accept",
        check=_metrics_honest,
        slow=True,
    ),
]


def simulate_cases():
    """Python-level cases for `dynax.simulate`: (id, call, expected message) where call() must raise
    `UsageError` (or, under jit, an error) with that message."""
    import jax
    import jax.numpy as jnp

    import dynax

    ts = jnp.linspace(0, 0.5, 51)
    system = dynax.Acrobot()
    x0 = jnp.array([0.3, 0.0, 0.0, 0.0])
    return [
        ("x0-too-long", lambda: dynax.simulate(system, [1, 0, 0, 0, 7, 9], ts), "`x0` has 6 entries"),
        ("x0-too-short", lambda: dynax.simulate(system, [1, 0], ts), "`x0` has 2 entries"),
        ("ts-reversed", lambda: dynax.simulate(system, x0, ts[::-1]), "`ts` must strictly increase"),
        ("ts-repeated", lambda: dynax.simulate(system, x0, ts.at[5].set(ts[4])), "`ts` must strictly increase"),
        ("ts-nan", lambda: dynax.simulate(system, x0, ts.at[5].set(jnp.nan)), "non-finite input: `ts`[5]"),
        ("x0-nan", lambda: dynax.simulate(system, x0.at[1].set(jnp.nan), ts), "non-finite input: `x0`[1]"),
        (
            "us-nan",
            lambda: dynax.simulate(system, x0, ts, jnp.zeros(51).at[7].set(jnp.nan)),
            "non-finite input: `us`[7, 0]",
        ),
        (
            "us-inf-throw-false",
            lambda: dynax.simulate(system, x0, ts, jnp.zeros(51).at[7].set(jnp.inf), throw=False),
            "non-finite input",
        ),
        (
            "jit-x0-nan",
            lambda: jax.jit(lambda x: dynax.simulate(system, x, ts).xs)(x0.at[0].set(jnp.nan)).block_until_ready(),
            "non-finite input",
        ),
        (
            "jit-ts-reversed",
            lambda: jax.jit(lambda t: dynax.simulate(system, x0, t).xs)(ts[::-1]).block_until_ready(),
            "not strictly increasing",
        ),
    ]


# --- running and judging a case -----------------------------------------------------------------


def _snapshot(path):
    path = pathlib.Path(path)
    if path.is_dir():
        return sorted((p.name, p.read_bytes() if p.is_file() else None) for p in path.iterdir())
    if path.is_file():
        return path.read_bytes()
    return None


@dataclasses.dataclass
class Outcome:
    id: str
    expect: str
    status: object  # exit status, or "exception"
    stderr: str
    out_changed: bool
    check_ok: bool | None
    verdict: str = ""

    @property
    def message(self) -> str:
        lines = [l for l in self.stderr.splitlines() if l.startswith("dynax") and "error" in l]
        return lines[-1] if lines else (self.stderr.strip().splitlines() or [""])[-1]


def superuser() -> bool:
    return hasattr(os, "geteuid") and os.geteuid() == 0


def run_case(case: Case, folder, fixtures, main) -> Outcome:
    """Run `case` through the console script's entry point `main(argv)` in `folder`; judge it."""
    if case.needs_permissions and superuser():
        return Outcome(case.id, case.expect, None, "", False, None, "skipped (run as the superuser)")
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        argv = [str(a) for a in case.build(folder, fixtures)]
        out = pathlib.Path(argv[argv.index("--out") + 1]) if "--out" in argv else folder / "dynax-demo"
        out = out if out.is_absolute() else folder / out
        before = _snapshot(out)
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            try:
                status = main(argv)
            except SystemExit as e:
                status = e.code
            except BaseException:  # noqa: BLE001 - an escaped exception is what we are looking for
                traceback.print_exc()
                status = "exception"
        changed = _snapshot(out) != before
        check_ok = None
        if case.expect == "accept" and status == 0 and case.check is not None:
            try:
                check_ok = bool(case.check(out))
            except Exception:  # noqa: BLE001 - an unreadable output fails the check
                check_ok = False
    finally:
        os.chdir(cwd)
    outcome = Outcome(case.id, case.expect, status, stderr.getvalue(), changed, check_ok)
    outcome.verdict = judge(case, outcome)
    return outcome


def judge(case: Case, o: Outcome) -> str:
    """One of: refused correctly, accepted correctly, silent failure, traceback, refused badly, wrongly refused."""
    traced = "Traceback" in o.stderr or o.status not in (0, 2)
    if case.expect == "refuse":
        if o.status == 0:
            return "silent failure"
        if traced:
            return "traceback"
        if case.message in o.message and not o.out_changed:
            return "refused correctly"
        return "refused badly" + (" (output written)" if o.out_changed else " (message)")
    if o.status == 0:
        return "accepted correctly" if o.check_ok else "silent failure"
    return "traceback" if traced else "wrongly refused"


def run_simulate_case(call, message) -> str:
    """Judge a `simulate` case: it must raise an error carrying `message`, never return quietly."""
    try:
        result = call()
    except Exception as e:  # noqa: BLE001 - which exception, and its message, is what is judged
        text = str(e)
        if message in text:
            return "refused correctly"
        return f"refused badly ({type(e).__name__}: {text.splitlines()[0][:80] if text else ''})"
    return "silent failure" if result is not None else "silent failure"
