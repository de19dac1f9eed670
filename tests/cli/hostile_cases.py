"""Hostile but ordinary inputs, of the kinds real logs contain, and what dynax must do with each.

Grown from the classes of faults a careful user meets: single-sample glitches, stuck sensors, wrapped
angles, stretches where a velocity stops agreeing with its position, sign flips, a velocity that lags its
angle (a driver's filter or backward difference), one joint's or motor's columns read as the other's, zero or constant
columns, inputs the system ignores, time in milliseconds, the same record twice, non-finite values,
unsorted time, absurd magnitudes, impossible models and bad arguments. Each `Case` builds its inputs in a
folder and names the command line (or a Python call) and the one acceptable outcome:

- `refuse`: exit status 2, a one-line message holding every string of `needles` (the column, the row
  or time, the fix), no traceback, nothing written to `--out`; and no string of `forbidden` (advice
  that would make the data worse, such as a `--scale` for a stretch's fault);
- `warn`: exit status 0, a warning line holding `needles` on the terminal and an entry of the written JSON's
  `warnings` list whose message holds them too (what a script reading the answer sees), and an output that
  passes `check`;
- `accept`: exit status 0 and an output that passes `check` (a right answer, checked against the
  truth the record was made from).

The records are made apart from dynax's model code (`tests.reference.arm_reference`, the arm's
equations written with numpy, integrated by scipy's DOP853), so a right answer is the truth, not
dynax agreeing with itself. Used by `tests/cli/test_hostile_inputs.py` and by
`experiments/hostile_inputs.py`, which tallies the outcomes against another checkout.
"""

from collections.abc import Callable
import contextlib
import dataclasses
import io
import json
import os
import pathlib
import sys
import traceback
import warnings

import numpy as np

ACROBOT = ("t", "q1", "q2", "dq1", "dq2", "tau2")
PENDULUM = ("t", "q1", "q2", "dq1", "dq2", "tau1", "tau2")
ENCODERS = ("t", "q1", "q2", "tau2")
# Drake's acrobot in base parameters (theta1..theta7), written out here rather than read from dynax.
TRUTH = {"theta1": 1.333, "theta2": 1.33, "theta3": 1.0, "theta4": 14.715, "theta5": 9.81, "theta6": 0.1, "theta7": 0.1}


@dataclasses.dataclass(frozen=True)
class Case:
    id: str
    kind: str  # the class of fault (for the tally)
    build: Callable  # build(folder, fixtures) -> argv (list of str), or a callable for a Python case
    expect: str  # "refuse", "warn" or "accept"
    needles: tuple = ()  # strings the refusal or warning must hold
    forbidden: tuple = ()  # strings it must not hold (advice that corrupts)
    check: Callable | None = None  # check(out_path) -> bool, for "warn" and "accept"
    heavy: bool = False  # runs a fit (seconds to a minute): `@pytest.mark.heavy` in the test
    slow: bool = False  # repeats a kept case's check through a longer run: `@pytest.mark.slow` (`make slow`)


# --- records made apart from dynax's model code ---------------------------------------------------


def _arm(theta, duration, rate_hz, drive, x0=(0.2, 0.0, 0.0, 0.0)):
    from tests.reference import arm_run

    return arm_run(theta, duration, rate_hz, drive, x0)


def _multisine(seed, amplitude=3.0):
    rng = np.random.default_rng(seed)
    freqs, phases = rng.uniform(0.2, 2.0, 6), rng.uniform(0, 2 * np.pi, 6)
    return lambda t: amplitude * float(np.sum(np.sin(2 * np.pi * freqs * t + phases))) / np.sqrt(6)


def make_fixtures(root) -> dict:
    """The clean records the cases corrupt: an acrobot (8 s at 100 Hz, velocities measured), a double
    pendulum (both joints driven), and a helicopter hover flight."""
    import dynax
    from dynax import Helicopter
    from dynax.synthetic import generate_helicopter_flight

    root = pathlib.Path(root)
    theta = list(TRUTH.values())
    elbow = _multisine(0)
    ts, xs, taus = _arm(theta, 8.0, 100.0, lambda t: (0.0, elbow(t)))
    acrobot = np.column_stack([ts, xs, taus[:, 1]])
    shoulder, elbow2 = _multisine(1, 2.0), _multisine(2)
    ts2, xs2, taus2 = _arm(theta, 8.0, 100.0, lambda t: (shoulder(t), elbow2(t)))
    pendulum = np.column_stack([ts2, xs2, taus2])
    free_ts, free_xs, _ = _arm(theta, 8.0, 100.0, lambda t: (0.0, 0.0), x0=(1.0, -0.5, 0.0, 0.0))
    free = np.column_stack([free_ts, free_xs, np.zeros_like(free_ts)])
    heli = generate_helicopter_flight("hover", 4.0, seed=1, truth=Helicopter())
    dynax.save_trajectory(heli, root / "heli.csv")
    lines = (root / "heli.csv").read_text().splitlines()
    heli_header = tuple(lines[0].split(","))
    heli_table = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    fx = {"acrobot": acrobot, "pendulum": pendulum, "free": free, "heli": heli_table, "heli_header": heli_header}
    fx["acrobot_csv"] = write_table(root / "acrobot.csv", ACROBOT, acrobot)
    return fx


def write_table(path, header, table) -> str:
    lines = [",".join(header)] + [",".join(f"{v:.17g}" for v in row) for row in table]
    pathlib.Path(path).write_text("\n".join(lines) + "\n")
    return str(path)


def _acrobot(folder, fx, edit=None, name="run.csv", header=ACROBOT, table="acrobot"):
    t = np.array(fx[table], copy=True)
    t = edit(t) if edit else t
    return write_table(folder / name, header, t)


def _encoders(folder, fx, edit=None, name="encoders.csv"):
    t = np.array(fx["acrobot"], copy=True)[:, [0, 1, 2, 5]]
    t = edit(t) if edit else t
    return write_table(folder / name, ENCODERS, t)


def _reformatted(folder, fx, delimiter, decimal=".", header_prefix="", rename=None, name="exported.csv"):
    """The clean acrobot record written another way: `delimiter`, a decimal mark, a prefix to the header line
    (numpy's `savetxt` writes `# `), column names renamed."""
    header = [rename(c) if rename else c for c in ACROBOT]
    rows = [delimiter.join(f"{v:.17g}".replace(".", decimal) for v in row) for row in fx["acrobot"]]
    path = pathlib.Path(folder) / name
    path.write_text(header_prefix + delimiter.join(header) + "\n" + "\n".join(rows) + "\n")
    return str(path)


def _heli(folder, fx, edit, name="heli_bad.csv"):
    header = fx["heli_header"]
    t = edit(header, np.array(fx["heli"], copy=True))
    return write_table(folder / name, header, t)


def _set(rows, column, value, header=ACROBOT):
    """An edit that sets `column` at `rows` (an index or slice) to `value` (a number, or a function of the old)."""

    def edit(t):
        j = header.index(column)
        t[rows, j] = value(t[rows, j]) if callable(value) else value
        return t

    return edit


def excerpt(first):
    """An edit that keeps rows `first:`, re-stamped from zero (an excerpt saved as a file of its own)."""

    def edit(t):
        t = t[first:].copy()
        t[:, 0] -= t[0, 0]
        return t

    return edit


def resampled(rate, first=0):
    """An edit that reads rows `first:` onto a clock of `rate` Hz by linear interpolation, re-stamped from zero (a
    copy resampled at another rate, as `np.interp` or pandas would make it)."""

    def edit(t):
        t = t[first:]
        ts = np.arange(t[0, 0], t[-1, 0], 1.0 / rate)
        return np.column_stack([ts - ts[0]] + [np.interp(ts, t[:, 0], c) for c in t[:, 1:].T])

    return edit


def _rows(first, stop):
    """An edit that keeps rows `first:stop`, stamps and all (one of two logs that overlap)."""
    return lambda t: t[first:stop].copy()


def _rounded(folder, fx, digits, name):
    """The acrobot record saved again with `digits` significant digits."""
    table = np.array(fx["acrobot"], copy=True)
    lines = [",".join(ACROBOT)] + [",".join(f"{v:.{digits}g}" for v in row) for row in table]
    path = pathlib.Path(folder) / name
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def _counts(joints, per_turn):
    """An edit that writes the angles of `joints`, and their velocities, in encoder counts (`per_turn` a turn)."""

    def edit(t):
        for q in joints:
            for c in (q, "d" + q):
                t[:, ACROBOT.index(c)] *= per_turn / (2 * np.pi)
        return t

    return edit


def _jittered(spread, seed=0):
    """An edit that moves every stamp by up to `spread` seconds either way (stamped on receipt), the samples
    staying where they were read."""

    def edit(t):
        t[:, 0] += np.random.default_rng(seed).uniform(-spread, spread, len(t))
        return t

    return edit


def _identify(path, *extra, out="out.json", system="acrobot", method="power"):
    return ["identify", system, str(path), "--method", method, *extra, "--out", out]


def _diagnose(path, *extra, out="report", system="acrobot"):
    return ["diagnose", system, str(path), *extra, "--out", out]


# --- checks of an answer against the truth ----------------------------------------------------------


def params_close(tolerance=0.02, names=tuple(TRUTH), friction_tolerance=0.05):
    """The written parameters within `tolerance` of the truth (`friction_tolerance` for theta6, theta7: on a
    clean 8 s record at 100 Hz the dynamic model leaves them 1 to 3 % off)."""

    def check(out):
        obj = json.loads(pathlib.Path(out).read_text())["parameters"]
        return all(
            isinstance(obj.get(n), float)
            and abs(obj[n] / TRUTH[n] - 1) < (friction_tolerance if n in ("theta6", "theta7") else tolerance)
            for n in names
        )

    return check


def _heli_fitted(out):
    obj = json.loads(pathlib.Path(out).read_text())
    return all(isinstance(v, float) and np.isfinite(v) for v in obj["parameters"].values())


def _python(call, exception, *needles):
    """A Python case: `call()` must raise `exception` with every needle in its message."""

    def run():
        try:
            call()
        except exception as e:
            return "raised", str(e)
        except Exception as e:  # noqa: BLE001 - another exception is a failure of its own
            return "other exception", f"{type(e).__name__}: {e}"
        return "returned", ""

    run.needles = needles
    return run


def _from_physical_negative_inertia():
    import dynax

    return dynax.DoublePendulum.from_physical(I2=-0.05)


def _identify_one_sample():
    import dynax

    ts = np.array([0.0])
    record = dynax.Trajectory(ts, np.zeros((1, 4)), np.zeros((1, 1)), ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot")
    return dynax.identify(dynax.Acrobot(), record)


def _nominal(folder, text, name="nominal.json"):
    (folder / name).write_text(text)
    return str(folder / name)


def helicopter_model_file(folder, gravity):
    """A helicopter acceleration model file (`model.json` in `folder`) with the given `gravity`: the model JSON
    a user hands `evaluate` or `simulate`, written out by hand."""
    from dynax.internal import initial_helicopter

    body = initial_helicopter("acceleration").body_model
    obj = {
        "system": "helicopter",
        "model": "acceleration",
        "features": list(body.feature_names),
        "mask": [[int(v) for v in row] for row in body.mask],
        "weights": np.asarray(body.weights).tolist(),
        "gravity": gravity,
    }
    (folder / "model.json").write_text(json.dumps(obj))
    return str(folder / "model.json")


def _tail(seconds, factor, column="dq2"):
    def edit(t):
        t[t[:, 0] > t[-1, 0] - seconds, ACROBOT.index(column)] *= factor
        return t

    return edit


def _shift(column, start, amount, header=ACROBOT):
    def edit(t):
        t[start:, header.index(column)] += amount
        return t

    return edit


def _replayed(start, source, n, header=ACROBOT):
    """A logger that writes rows `source..source+n` again at `start..start+n`, under the later rows' times."""

    def edit(t):
        t[start : start + n, 1:] = t[source : source + n, 1:]
        return t

    return edit


def _swap_rows(a, b):
    def edit(t):
        t[[a, b]] = t[[b, a]]
        return t

    return edit


def _time_scale(factor):
    def edit(t):
        t[:, 0] *= factor
        return t

    return edit


def _time_offset(seconds):
    """Time stamps that start at `seconds` (a clock's epoch) rather than 0."""

    def edit(t):
        t[:, 0] += seconds
        return t

    return edit


def _heli_set(column, rows, value):
    def edit(header, t):
        t[rows, header.index(column)] = value(t[rows, header.index(column)]) if callable(value) else value
        return t

    return edit


def _with_tau1(values):
    def edit(t):
        return np.column_stack([t, values(t)])

    return edit


def _lagged(samples, columns=("dq1", "dq2"), start=0, header=ACROBOT):
    """A velocity logged `samples` late (a driver's delay) from row `start` on."""

    def edit(t):
        for c in columns:
            j = header.index(c)
            t[start + samples :, j] = t[start:-samples, j].copy()
        return t

    return edit


def _stamped_late(rows, fraction=0.7):
    """Rows whose time stamp is taken `fraction` of an interval late (their angles and velocities as read)."""

    def edit(t):
        t[list(rows), 0] += fraction * float(np.median(np.diff(t[:, 0])))
        return t

    return edit


def _low_passed(tau, columns=("dq1", "dq2")):
    """A velocity through a causal first-order low-pass of time constant `tau` (a driver's filter)."""

    def edit(t):
        for c in columns:
            j = ACROBOT.index(c)
            y = t[0, j]
            for i in range(len(t)):
                a = (t[i, 0] - t[i - 1, 0]) / (tau + t[i, 0] - t[i - 1, 0]) if i else 1.0
                y += a * (t[i, j] - y)
                t[i, j] = y
        return t

    return edit


def _backward_differences(t):
    """The velocities a driver logs: each angle's backward difference (the DFKI rig's `vel_meas`)."""
    t[1:, 3:5] = np.diff(t[:, 1:3], axis=0) / np.diff(t[:, :1], axis=0)
    t[0, 3:5] = t[1, 3:5]
    return t


def _swapped(*pairs, header=ACROBOT):
    def edit(t):
        for a, b in pairs:
            i, j = header.index(a), header.index(b)
            t[:, [i, j]] = t[:, [j, i]]
        return t

    return edit


def _absolute_q2(t, header=ACROBOT):
    """Link 2's absolute angle and rate in place of the elbow's: q2 + q1, dq2 + dq1."""
    for a, b in (("q2", "q1"), ("dq2", "dq1")):
        t[:, header.index(a)] += t[:, header.index(b)]
    return t


def _written(out):
    """The output is there and holds finite parameters (for a warned case whose data are mislabelled)."""
    obj = json.loads(pathlib.Path(out).read_text())["parameters"]
    return all(isinstance(v, float) and np.isfinite(v) for v in obj.values())


# --- the cases ---------------------------------------------------------------------------------

C = Case
CASES = [
    # Single-sample glitches: refused at the sample, with the stretch to cut.
    C(
        "glitch-dq2-460",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(300, "dq2", 460.0))),
        "refuse",
        ("column 'dq2'", "row 301", "--exclude 2.99:3.01"),
    ),
    C(
        "glitch-q1-jump",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(250, "q1", lambda v: v + 40.0))),
        "refuse",
        ("column 'q1'", "row 251"),
    ),
    C(
        "glitch-tau2-spike",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(400, "tau2", 1e4))),
        "refuse",
        ("column 'tau2'", "row 401"),
    ),
    C(
        "glitch-two-samples",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(500, 502), "dq1", -300.0))),
        "refuse",
        ("column 'dq1'", "rows 501-502"),
    ),
    C(
        "glitch-first-sample",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(0, "dq1", 500.0))),
        "refuse",
        ("column 'dq1'", "row 1", "--exclude :0.01"),
    ),
    C(
        "glitch-last-sample",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(-1, "q2", 99.0))),
        "refuse",
        ("column 'q2'", "row 801"),
    ),
    C(
        "glitch-encoder-only",
        "glitch",
        lambda d, fx: _identify(_encoders(d, fx, _set(300, "q2", lambda v: v + 30.0, ENCODERS))),
        "refuse",
        ("column 'q2'", "row 301"),
    ),
    C(
        "glitch-heli-gyro-460",
        "glitch",
        lambda d, fx: ["fit", "helicopter", _heli(d, fx, _heli_set("p", 200, 460.0)), "--out", "out.json"],
        "refuse",
        ("column 'p'", "row 201"),
    ),
    C(
        "glitch-diagnose",
        "glitch",
        lambda d, fx: _diagnose(_acrobot(d, fx, _set(350, "dq2", -460.0))),
        "refuse",
        ("column 'dq2'", "row 351"),
    ),
    # Stuck sensors.
    C(
        "stuck-dq1-1s",
        "stuck",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(300, 400), "dq1", lambda v: v[0]))),
        "refuse",
        ("column 'dq1'", "rows 301-400"),
    ),
    C(
        "stuck-q2-tail",
        "stuck",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(600, None), "q2", lambda v: v[0]))),
        "refuse",
        ("column 'q2'", "rows 601-801"),
    ),
    C(
        "stuck-encoder-q1",
        "stuck",
        lambda d, fx: _identify(_encoders(d, fx, _set(slice(200, 350), "q1", lambda v: v[0], ENCODERS))),
        "refuse",
        ("column 'q1'", "rows 201-350"),
    ),
    C(
        "stuck-heli-r",
        "stuck",
        lambda d, fx: [
            "fit",
            "helicopter",
            _heli(d, fx, _heli_set("r", slice(100, 250), lambda v: v[0])),
            "--out",
            "out.json",
        ],
        "refuse",
        ("column 'r'", "rows 101-250"),
    ),
    # Wrapped angles.
    C(
        "wrapped-q1",
        "wrapped",
        lambda d, fx: _identify(_acrobot(d, fx, _shift("q1", 400, -2 * np.pi))),
        "refuse",
        ("column 'q1'", "rows 400-401", "unwrap"),
    ),
    C(
        "wrapped-q2-encoder-only",
        "wrapped",
        lambda d, fx: _identify(_encoders(d, fx, _shift("q2", 333, 2 * np.pi, ENCODERS))),
        "refuse",
        ("column 'q2'", "rows 333-334"),
    ),
    C(
        "wrapped-diagnose",
        "wrapped",
        lambda d, fx: _diagnose(_acrobot(d, fx, _shift("q2", 500, 4 * np.pi))),
        "refuse",
        ("column 'q2'", "unwrap"),
    ),
    # A position that leaps and stays (an encoder re-zeroed, rows dropped or replayed): cut at the leap.
    C(
        "jump-q1-encoder-rezeroed",
        "jump",
        lambda d, fx: _identify(_acrobot(d, fx, _shift("q1", 400, 0.8))),
        "refuse",
        ("column 'q1'", "rows 400-401", "--exclude"),
    ),
    C(
        "jump-q2-encoder-only",
        "jump",
        lambda d, fx: _identify(_encoders(d, fx, _shift("q2", 333, -0.5, ENCODERS))),
        "refuse",
        ("column 'q2'", "rows 333-334", "--exclude"),
    ),
    C(
        "logger-replays-a-stretch",
        "jump",
        lambda d, fx: _identify(_acrobot(d, fx, _replayed(300, 100, 150))),
        "refuse",
        ("rows 300-301", "rows 450-451", "--exclude"),
    ),
    # A velocity that stops agreeing with its position in a stretch: named, never a --scale.
    C(
        "velocity-tail-1.2s-x3",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _tail(1.2, 3.0))),
        "refuse",
        ("column 'dq2'", "--exclude 6.8"),
        ("--scale",),
    ),
    C(
        "velocity-tail-1.2s-zero",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _tail(1.2, 0.0))),
        "refuse",
        ("column 'dq2'", "t = 6.8"),
        ("--scale",),
    ),
    C(
        "velocity-sign-flips-halfway",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(400, None), "dq1", lambda v: -v))),
        "refuse",
        ("column 'dq1'", "t = 4"),
        ("--scale",),
    ),
    C(
        "velocity-sign-flips-diagnose",
        "velocity",
        lambda d, fx: _diagnose(_acrobot(d, fx, _set(slice(400, None), "dq2", lambda v: -v))),
        "refuse",
        ("column 'dq2'",),
        ("--scale",),
    ),
    C(
        "velocity-stretch-middle",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(300, 420), "dq2", lambda v: 2.5 * v))),
        "refuse",
        ("column 'dq2'", "--exclude 2.9"),
        ("--scale",),
    ),
    C(
        "velocity-degrees-everywhere",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(None), "dq1", lambda v: v * 180 / np.pi))),
        "refuse",
        ("column 'dq1'", "--scale dq1=0.0174533"),
    ),
    C(  # the angle in degrees, its velocity in rad/s: it advised leaving the velocity out (the angle stays in degrees)
        "position-degrees-velocity-radians",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(None), "q1", np.degrees))),
        "refuse",
        ("column 'dq1'", "the position in degrees", "--scale q1=0.0174533"),
        forbidden=("leave its columns out",),
    ),
    C(
        "velocity-tail-cut-with-exclude",
        "velocity",
        lambda d, fx: _identify(_acrobot(d, fx, _tail(1.2, 3.0)), "--exclude", "6.8:", method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "glitch-cut-with-exclude",
        "glitch",
        lambda d, fx: _identify(_acrobot(d, fx, _set(300, "dq2", 460.0)), "--exclude", "2.99:3.01", method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    # Zero or constant columns.
    C(
        "zero-input-tau2",
        "zero",
        lambda d, fx: _identify(_acrobot(d, fx, table="free")),
        "refuse",
        ("column 'tau2'", "nothing drives"),
    ),
    C(
        "zero-input-dynamic",
        "zero",
        lambda d, fx: _identify(_acrobot(d, fx, table="free"), method="dynamic"),
        "refuse",
        ("column 'tau2'",),
    ),
    C(
        "constant-input-tau2",
        "zero",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(None), "tau2", 0.7))),
        "refuse",
        ("column 'tau2'", "constant"),
    ),
    C(
        "locked-elbow",
        "zero",
        lambda d, fx: _identify(_acrobot(d, fx, lambda t: (t.__setitem__((slice(None), [2, 4]), 0.0), t)[1])),
        "refuse",
        ("column 'q2'", "never moves"),
    ),
    C(
        "zero-tau1-double-pendulum",
        "zero",
        lambda d, fx: _identify(
            _acrobot(d, fx, lambda t: np.column_stack([t[:, :5], np.zeros(len(t)), t[:, 5]]), header=PENDULUM),
            system="double_pendulum",
            method="dynamic",
        ),
        "warn",
        ("column 'tau1'",),
        check=params_close(0.05, ("theta1", "theta2", "theta3", "theta4", "theta5")),
        heavy=True,
    ),
    # Inputs the system ignores.
    C(
        "ignored-tau1-acrobot",
        "ignored_input",
        lambda d, fx: _identify(_acrobot(d, fx, header=PENDULUM, table="pendulum")),
        "refuse",
        ("column 'tau1'", "double_pendulum"),
    ),
    C(
        "ignored-tau1-diagnose",
        "ignored_input",
        lambda d, fx: _diagnose(_acrobot(d, fx, header=PENDULUM, table="pendulum")),
        "refuse",
        ("column 'tau1'",),
    ),
    C(
        "zero-tau1-column-acrobot",
        "ignored_input",
        lambda d, fx: _identify(
            _acrobot(d, fx, _with_tau1(lambda t: np.zeros(len(t))), header=ACROBOT + ("tau1",)), method="dynamic"
        ),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    # Time units.
    C(
        "time-ms-with-velocities",
        "time_units",
        lambda d, fx: _identify(_acrobot(d, fx, _time_scale(1e3))),
        "refuse",
        ("--scale t=0.001",),
        ("dq1=0.001", "dq2=0.001"),
    ),
    C(  # refused before too, naming the velocity's gain of 1/60 but not the time
        "time-minutes-with-velocities",
        "time_units",
        lambda d, fx: _identify(_acrobot(d, fx, _time_scale(1 / 60))),
        "refuse",
        ("column 't'", "minutes", "--scale t=60"),
        ("--scale dq",),
    ),
    C(
        "time-ms-encoder-only",
        "time_units",
        lambda d, fx: _identify(_encoders(d, fx, _time_scale(1e3))),
        "refuse",
        ("column 't'", "--scale t=0.001"),
    ),
    C("time-us", "time_units", lambda d, fx: _identify(_acrobot(d, fx, _time_scale(1e6))), "refuse", ("t=1e-06",)),
    C(
        "time-ms-diagnose",
        "time_units",
        lambda d, fx: _diagnose(_acrobot(d, fx, _time_scale(1e3))),
        "refuse",
        ("--scale t=0.001",),
    ),
    C(
        "time-ms-scaled-back",
        "time_units",
        lambda d, fx: _identify(_acrobot(d, fx, _time_scale(1e3)), "--scale", "t=0.001", method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "diagnose-dt-10",
        "time_units",
        lambda d, fx: _diagnose(fx["acrobot_csv"], "--dt", "10"),
        "refuse",
        ("--dt 10", "at most"),
    ),
    # The same record twice, or as its own validation.
    C(
        "same-file-twice",
        "duplicate",
        lambda d, fx: ["identify", "acrobot", fx["acrobot_csv"], fx["acrobot_csv"], "--out", "out.json"],
        "refuse",
        ("same data",),
    ),
    C(
        "copy-under-another-name",
        "duplicate",
        lambda d, fx: ["identify", "acrobot", fx["acrobot_csv"], _acrobot(d, fx, name="copy.csv"), "--out", "out.json"],
        "refuse",
        ("copy.csv", "same data"),
    ),
    C(
        "validation-is-the-data",
        "duplicate",
        lambda d, fx: [
            "identify",
            "acrobot",
            fx["acrobot_csv"],
            "--validation",
            fx["acrobot_csv"],
            "--out",
            "out.json",
        ],
        "refuse",
        ("in-sample",),
    ),
    C(
        "diagnose-validation-is-the-data",
        "duplicate",
        lambda d, fx: _diagnose(fx["acrobot_csv"], "--validation", _acrobot(d, fx, name="v.csv")),
        "refuse",
        ("in-sample",),
    ),
    # An excerpt of a record given beside it: it ran to exit 0, held-out error in-sample, the stretch's weight doubled.
    C(
        "validation-cut-from-the-data",
        "duplicate",
        lambda d, fx: _diagnose(fx["acrobot_csv"], "--validation", _acrobot(d, fx, excerpt(500), name="v.csv")),
        "refuse",
        ("v.csv", "rows 1-301", "in-sample", "rows 501-801", "--exclude acrobot.csv@4.99:"),
    ),
    C(
        "logs-that-overlap",
        "duplicate",
        lambda d, fx: _identify(
            _acrobot(d, fx, _rows(0, 601), name="first.csv"),
            "--validation",
            _acrobot(d, fx, _rows(400, 801), name="second.csv"),
        ),
        "refuse",
        ("second.csv", "rows 1-201", "t = 4 to 6 s", "in-sample", "--exclude first.csv@3.99:"),
    ),
    C(
        "copy-saved-with-six-digits",
        "duplicate",
        lambda d, fx: [
            "identify",
            "acrobot",
            fx["acrobot_csv"],
            _rounded(d, fx, 6, "rounded.csv"),
            "--out",
            "out.json",
        ],
        "refuse",
        ("rounded.csv", "rows 1-801", "counted twice", "give the record once"),
    ),
    C(
        "validation-at-half-the-rate",
        "duplicate",
        lambda d, fx: _diagnose(
            fx["acrobot_csv"], "--validation", _acrobot(d, fx, lambda t: t[::2].copy(), name="v50.csv")
        ),
        "refuse",
        ("v50.csv", "every 2nd row", "in-sample"),
    ),
    C(
        "validation-resampled-at-75-hz",
        "duplicate",
        lambda d, fx: _diagnose(
            fx["acrobot_csv"], "--validation", _acrobot(d, fx, resampled(75.0, first=500), name="v75.csv")
        ),
        "refuse",
        ("v75.csv", "resampled at another rate", "in-sample", "--exclude acrobot.csv@"),
    ),
    C(
        "validation-cut-and-excluded",
        "duplicate",
        lambda d, fx: _identify(
            fx["acrobot_csv"],
            "--validation",
            _acrobot(d, fx, excerpt(500), name="v.csv"),
            "--exclude",
            "acrobot.csv@4.99:",
            method="dynamic",
        ),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    # One file column read as two (a --map slip): it ran to exit 0 with every parameter at its bound, NaN standard
    # errors and an infinite held-out error.
    C(
        "one-column-mapped-twice",
        "duplicate",
        lambda d, fx: _identify(_acrobot(d, fx), "--map", "q2=q1,dq2=dq1", method="dynamic"),
        "refuse",
        ("column 'q2'", "same as column 'q1'", "column 'dq2'", "map q2 to its own column"),
    ),
    C(
        "diagnose-one-column-mapped-twice",
        "duplicate",
        lambda d, fx: _diagnose(_acrobot(d, fx, name="elbow.csv"), "--map", "q2=q1,dq2=dq1"),
        "refuse",
        ("elbow.csv", "column 'q2'", "same as column 'q1'"),
    ),
    # Non-finite values, unsorted time, absurd magnitudes.
    C(
        "nan-in-dq2",
        "non_finite",
        lambda d, fx: _identify(_acrobot(d, fx, _set(123, "dq2", np.nan))),
        "refuse",
        ("column 'dq2'", "row 124"),
    ),
    C(
        "inf-in-tau2",
        "non_finite",
        lambda d, fx: _identify(_acrobot(d, fx, _set(77, "tau2", np.inf))),
        "refuse",
        ("column 'tau2'", "row 78"),
    ),
    C(
        "two-rows-swapped",
        "time",
        lambda d, fx: _identify(_acrobot(d, fx, _swap_rows(200, 201))),
        "refuse",
        ("column 't'", "row 202"),
    ),
    C(
        "time-reversed-diagnose",
        "time",
        lambda d, fx: _diagnose(_acrobot(d, fx, lambda t: t[::-1])),
        "refuse",
        ("time does not strictly increase",),
    ),
    C(
        "huge-value-1e13",
        "magnitude",
        lambda d, fx: _identify(_acrobot(d, fx, _set(40, "q1", 1e13))),
        "refuse",
        ("column 'q1'", "row 41"),
    ),
    C(
        "heli-huge-gyro-1e6",
        "magnitude",
        lambda d, fx: ["fit", "helicopter", _heli(d, fx, _heli_set("q", 50, 1e6)), "--out", "out.json"],
        "refuse",
        ("column 'q'", "row 51"),
    ),
    # Impossible models.
    C(
        "nominal-negative-theta1-theta4",
        "model",
        lambda d, fx: _diagnose(
            fx["acrobot_csv"],
            "--mode",
            "known",
            "--nominal",
            _nominal(d, '{"parameters": {"theta1": -1.333, "theta4": -14.715}}'),
        ),
        "refuse",
        ("theta1", "theta4", "nominal.json"),
    ),
    C(
        "nominal-indefinite-mass-matrix",
        "model",
        lambda d, fx: _diagnose(
            fx["acrobot_csv"], "--nominal", _nominal(d, '{"parameters": {"theta1": 0.2, "theta2": 0.3, "theta3": 1.0}}')
        ),
        "refuse",
        ("theta1 * theta2",),
    ),
    C(
        "nominal-negative-mass-axis",
        "model",
        lambda d, fx: [
            "diagnose",
            "linear_axis",
            write_table(
                d / "axis.csv",
                ("t", "q", "force"),
                np.column_stack([fx["acrobot"][:, 0], fx["acrobot"][:, 1], fx["acrobot"][:, 5]]),
            ),
            "--nominal",
            _nominal(d, '{"parameters": {"mass": -2.0}}'),
            "--out",
            "report",
        ],
        "refuse",
        ("mass",),
    ),
    C(
        "model-file-negative-gravity",
        "model",
        lambda d, fx: [
            "evaluate",
            helicopter_model_file(d, -9.81),
            _heli(d, fx, lambda h, t: t),
            "--horizons",
            "0.1",
            "--out",
            "m.json",
        ],
        "refuse",
        ("gravity",),
    ),
    C(
        "from-physical-negative-I2",
        "model",
        lambda d, fx: _python(_from_physical_negative_inertia, ValueError, "I2"),
        "refuse",
        ("I2",),
    ),
    # Bad arguments.
    C(
        "identify-one-sample",
        "args",
        lambda d, fx: _identify(_acrobot(d, fx, lambda t: t[:1])),
        "refuse",
        ("has 1 samples",),
    ),
    C(
        "python-identify-one-sample",
        "args",
        lambda d, fx: _python(_identify_one_sample, ValueError, "1 sample"),
        "refuse",
        ("1 sample",),
    ),
    C(
        "demo-seed-huge",
        "args",
        lambda d, fx: ["demo", "--seed", "99999999999999999999999", "--out", "demo"],
        "refuse",
        ("--seed",),
    ),
    C(
        "out-name-too-long",
        "args",
        lambda d, fx: _identify(fx["acrobot_csv"], out="x" * 300 + ".json"),
        "refuse",
        ("--out", "bytes long"),
    ),
    C(
        "out-path-too-long",
        "args",
        lambda d, fx: _identify(fx["acrobot_csv"], out="x/" * 2100 + "o.json"),
        "refuse",
        ("--out",),
    ),
    C(
        "exclude-malformed",
        "args",
        lambda d, fx: _identify(fx["acrobot_csv"], "--exclude", "5"),
        "refuse",
        ("--exclude",),
    ),
    C(
        "exclude-reversed",
        "args",
        lambda d, fx: _identify(fx["acrobot_csv"], "--exclude", "5:3"),
        "refuse",
        ("--exclude", "T0 < T1"),
    ),
    C(
        "exclude-everything",
        "args",
        lambda d, fx: _identify(fx["acrobot_csv"], "--exclude", ":"),
        "refuse",
        ("--exclude leaves nothing",),
    ),
    C(
        "exclude-unknown-file",
        "args",
        lambda d, fx: _identify(fx["acrobot_csv"], "--exclude", "nofile.csv@1:2"),
        "refuse",
        ("nofile.csv",),
    ),
    # A logged velocity that lags its angle (a driver's filter or backward difference): named with the lag.
    C(
        "velocity-lag-one-sample",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _lagged(1))),
        "refuse",
        ("column 'dq1'", "lags q1 by 9.9", "--velocities positions"),
        ("--scale",),
    ),
    C(
        "velocity-lag-backward-difference",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _backward_differences)),
        "refuse",
        ("column 'dq1'", "lags q1 by 5", "--velocities positions"),
    ),
    C(
        "velocity-lag-low-pass-10ms",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _low_passed(0.01))),
        "refuse",
        ("column 'dq1'", "lags q1", "--velocities positions"),
    ),
    C(
        "velocity-lag-elbow-only",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _lagged(2, ("dq2",)))),
        "refuse",
        ("column 'dq2'", "lags q2 by 20", "--velocities positions"),
    ),
    C(
        "velocity-lag-second-half",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _lagged(1, start=400))),
        "refuse",
        ("column 'dq1'", "t = 4", "to 8 s", "lags q1"),
    ),
    C(  # a lag from inside a 0.5 s stretch: its start placed to the sample, not at the stretch's edge
        "velocity-lag-from-4.41s",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _lagged(1, start=440))),
        "refuse",
        ("column 'dq1'", "rows 442-801", "t = 4.41 to 8 s", "lags q1"),
    ),
    C(  # four rows stamped 0.7 of an interval late (a logger that stalls between its sensors and its clock), the
        # velocities read with the angles: the stamps are named, and no velocity fix is offered (none is needed)
        "late-stamps",
        "stamps",
        lambda d, fx: _identify(_acrobot(d, fx, _stamped_late((150, 320, 480, 650)))),
        "warn",
        ("column 't'", "rows 151, 321, 481, 651", "ms late", "only the stamps are off"),
        forbidden=("--velocities positions",),
        check=params_close(0.05, ("theta1", "theta2", "theta3", "theta4", "theta5")),
        heavy=True,
    ),
    # Stamps taken on receipt about samples read on a steady clock (a message's arrival time): it ran to exit 0
    # with the dampings 13 % off and nothing said.
    C(
        "stamps-jitter-on-receipt",
        "stamps",
        lambda d, fx: _identify(_acrobot(d, fx, _jittered(0.002))),
        "refuse",
        ("column 't'", "rows 1-801", "jitter", "--even-times"),
    ),
    C(
        "stamps-jitter-diagnose",
        "stamps",
        lambda d, fx: _diagnose(_acrobot(d, fx, _jittered(0.002))),
        "refuse",
        ("column 't'", "jitter", "--even-times"),
    ),
    C(
        "stamps-jitter-even-times",
        "stamps",
        lambda d, fx: _identify(_acrobot(d, fx, _jittered(0.002)), "--even-times", method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(  # a sample dropped as well: its tick is left out, every other sample keeps its own
        "even-times-with-a-dropped-sample",
        "stamps",
        lambda d, fx: _identify(
            _acrobot(d, fx, lambda t: np.delete(_jittered(0.002)(t), 400, axis=0)), "--even-times", method="dynamic"
        ),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "velocity-lag-diagnose",
        "velocity_lag",
        lambda d, fx: _diagnose(_acrobot(d, fx, _lagged(1))),
        "refuse",
        ("column 'dq1'", "lags q1", "--velocities positions"),
    ),
    C(
        "velocity-lag-estimated-instead",
        "velocity_lag",
        lambda d, fx: _identify(_acrobot(d, fx, _lagged(1)), "--velocities", "positions", method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    # Columns mapped to the wrong joint or motor: every column is a fine signal, so only the fit can tell.
    C(
        "swapped-torques-double-pendulum",
        "swapped",
        lambda d, fx: _identify(
            _acrobot(d, fx, _swapped(("tau1", "tau2"), header=PENDULUM), header=PENDULUM, table="pendulum"),
            system="double_pendulum",
            method="dynamic",
        ),
        "warn",
        ("tau1, tau2", "look swapped", "--map tau1=tau2,tau2=tau1"),
        check=_written,
        heavy=True,
    ),
    C(
        "swapped-joints-acrobot",
        "swapped",
        lambda d, fx: _identify(_acrobot(d, fx, _swapped(("q1", "q2"), ("dq1", "dq2"))), method="dynamic"),
        "warn",
        ("q1, q2 and dq1, dq2", "look swapped", "--map q1=q2,q2=q1,dq1=dq2,dq2=dq1"),
        check=_written,
        heavy=True,
    ),
    C(  # link 2's angle from the vertical, as motion capture or an IMU on the link logs it: warned before only as an
        # inconsistent estimate that named no cause
        "absolute-q2-acrobot",
        "swapped",
        lambda d, fx: _identify(_acrobot(d, fx, _absolute_q2), method="dynamic"),
        "warn",
        ("q2 looks like link 2's absolute angle", "q2 - q1"),
        check=_written,
        heavy=True,
    ),
    # Angles (and their velocities, so that the two agree) logged in encoder counts: it ran to exit 0 with every
    # parameter near zero and a warning that the data determine them poorly, naming no cause.
    C(
        "angles-in-encoder-counts",
        "angle_units",
        lambda d, fx: _identify(_acrobot(d, fx, _counts(("q1", "q2"), 4096)), method="dynamic"),
        "warn",
        ("look like encoder counts (4096 a turn)", "--scale q1=0.001533981,dq1=0.001533981,q2=0.001533981"),
        check=_written,
        heavy=True,
    ),
    C(
        "elbow-in-encoder-counts",
        "angle_units",
        lambda d, fx: _identify(_acrobot(d, fx, _counts(("q2",), 10000)), method="dynamic"),
        "warn",
        ("q2 looks like encoder counts (10000 a turn)", "--scale q2=0.0006283185,dq2=0.0006283185"),
        check=_written,
        heavy=True,
    ),
    C(
        "angles-in-encoder-counts-scaled-back",
        "angle_units",
        lambda d, fx: _identify(
            _acrobot(d, fx, _counts(("q1", "q2"), 4096)),
            "--scale",
            "q1=0.001533981,dq1=0.001533981,q2=0.001533981,dq2=0.001533981",
            method="dynamic",
        ),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "swapped-torques-diagnose",
        "swapped",
        lambda d, fx: _diagnose(
            _acrobot(d, fx, _swapped(("tau1", "tau2"), header=PENDULUM), header=PENDULUM, table="pendulum"),
            system="double_pendulum",
        ),
        "warn",
        ("tau1, tau2", "look swapped", "--map tau1=tau2,tau2=tau1"),
        check=lambda out: isinstance(json.loads((pathlib.Path(out) / "report.json").read_text())["verdict"], str),
        heavy=True,
        # The swap check is the one `identify` runs in `swapped-torques-double-pendulum`; here a whole double
        # pendulum diagnosis follows it (about 3 minutes of compilation and fitting on two cores).
        slow=True,
    ),
    C(
        "swapped-joints-mapped-back",
        "swapped",
        lambda d, fx: _identify(
            _acrobot(d, fx, _swapped(("q1", "q2"), ("dq1", "dq2"))),
            "--map",
            "q1=q2,q2=q1,dq1=dq2,dq2=dq1",
            method="dynamic",
        ),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "reversed-torque-acrobot",
        "swapped",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(None), "tau2", lambda v: -v)), method="dynamic"),
        "warn",
        ("tau2 looks reversed", "--scale tau2=-1"),
        check=_written,
        heavy=True,
    ),
    # A sign that turns part way through the record (a motor's direction reconfigured while recording): no
    # scale is right for the whole record, so the stretch is named with the --exclude that leaves it out.
    C(
        "torque-sign-flips-partway",
        "swapped",
        lambda d, fx: _identify(
            _acrobot(
                d, fx, _set(slice(400, None), "tau2", lambda v: -v, header=PENDULUM), header=PENDULUM, table="pendulum"
            ),
            system="double_pendulum",
            method="dynamic",
        ),
        "warn",
        ("run.csv: the recorded tau2 looks reversed from about t = 4 s", "--exclude run.csv@4:"),
        ("--scale tau2=-1",),
        check=_written,
        heavy=True,
    ),
    C(
        "torque-sign-flips-partway-acrobot",
        "swapped",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(None, 300), "tau2", lambda v: -v)), method="dynamic"),
        "warn",
        ("run.csv: the recorded tau2 looks reversed from its start to about t = 3", "--exclude run.csv@:3"),
        ("--scale tau2=-1",),
        check=_written,
        heavy=True,
    ),
    C(
        "torque-scale-halves-partway",
        "swapped",
        lambda d, fx: _identify(
            _acrobot(
                d,
                fx,
                _set(slice(400, None), "tau2", lambda v: 0.5 * v, header=PENDULUM),
                header=PENDULUM,
                table="pendulum",
            ),
            system="double_pendulum",
            method="dynamic",
        ),
        "warn",
        ("run.csv: the recorded tau2 looks scaled by 0.5 ", "from about t = 4", "--exclude run.csv@4"),
        ("--scale",),
        check=_written,
        heavy=True,
    ),
    C(
        "torque-scale-doubles-partway-acrobot",
        "swapped",
        lambda d, fx: _identify(_acrobot(d, fx, _set(slice(None, 300), "tau2", lambda v: 2.0 * v)), method="dynamic"),
        "warn",
        ("run.csv: the recorded tau2 looks scaled by", "--exclude run.csv@"),
        ("--scale",),
        check=_written,
        heavy=True,
    ),
    C(
        "time-epoch-offset",
        "clean",
        lambda d, fx: _identify(_acrobot(d, fx, _time_offset(1.7e9)), method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    # The file formats spreadsheets, loggers and numpy write: read where unambiguous, else the cell named.
    C(
        "csv-semicolons",
        "format",
        lambda d, fx: _identify(_reformatted(d, fx, ";"), method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "csv-savetxt-header-as-comment",
        "format",
        lambda d, fx: _identify(_reformatted(d, fx, ",", header_prefix="# "), method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "csv-decimal-comma",
        "format",
        lambda d, fx: _identify(_reformatted(d, fx, ";", decimal=","), method="dynamic"),
        "refuse",
        needles=("column 't', row 2", "'0,01'", "decimal comma"),
    ),
    C(
        "csv-header-in-capitals-with-units",
        "format",
        lambda d, fx: _identify(_reformatted(d, fx, ",", rename=lambda c: f"{c.upper()} [SI]"), method="dynamic"),
        "refuse",
        needles=("missing column", "--map 't=T [SI],q1=Q1 [SI]"),
    ),
    # Clean records must keep their right answers.
    C(
        "clean-contract-file",
        "clean",
        lambda d, fx: _identify(fx["acrobot_csv"], method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
    C(
        "clean-encoder-only",
        "clean",
        lambda d, fx: _identify(_encoders(d, fx), method="dynamic"),
        "accept",
        check=params_close(),
        heavy=True,
    ),
]


# --- running and judging a case ------------------------------------------------------------------------


def _snapshot(path):
    path = pathlib.Path(path)
    with contextlib.suppress(OSError):
        if path.is_dir():
            return sorted((p.name, p.read_bytes() if p.is_file() else None) for p in path.iterdir())
        if path.is_file():
            return path.read_bytes()
    return None


@dataclasses.dataclass
class Outcome:
    id: str
    status: object
    stderr: str
    verdict: str = ""
    stdout: str = ""
    warnings: list | None = None  # the written JSON's `warnings` list (None: no JSON, or none in it)

    @property
    def message(self) -> str:
        lines = [l for l in self.stderr.splitlines() if l.startswith("dynax") and "error" in l]
        return lines[-1] if lines else (self.stderr.strip().splitlines() or [""])[-1]


def _warning_to_stderr(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def run_case(case: Case, folder, fixtures, main) -> Outcome:
    """Run `case` in `folder` through `main(argv)` (or its Python call), and judge it (`Outcome.verdict`)."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        built = case.build(folder, fixtures)
        if callable(built):
            result, text = built()
            ok = result == "raised" and all(n in text for n in built.needles)
            verdict = (
                "refused correctly"
                if ok
                else "silent failure"
                if result == "returned"
                else "traceback"
                if result == "other exception"
                else "refused badly (message)"
            )
            return Outcome(case.id, result, text, verdict)
        argv = [str(a) for a in built]
        out = pathlib.Path(argv[argv.index("--out") + 1]) if "--out" in argv else folder / "dynax-demo"
        out = out if out.is_absolute() else folder / out
        before = _snapshot(out)
        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), warnings.catch_warnings():
            # as the console script shows them: every Python warning on stderr (pytest would record them instead)
            warnings.simplefilter("always")
            warnings.showwarning = _warning_to_stderr
            try:
                status = main(argv)
            except SystemExit as e:
                status = e.code
            except BaseException:  # noqa: BLE001 - an escaped exception is what is looked for
                traceback.print_exc()
                status = "exception"
        changed = _snapshot(out) != before
        check_ok = None
        if status == 0 and case.check is not None:
            try:  # a check marked `with_fixtures` compares with the unfaulted records' answers
                with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                    check_ok = bool(
                        case.check(out, fixtures) if getattr(case.check, "with_fixtures", False) else case.check(out)
                    )
            except Exception:  # noqa: BLE001 - an unreadable output fails the check
                check_ok = False
    finally:
        os.chdir(cwd)
    outcome = Outcome(case.id, status, stderr.getvalue(), stdout=stdout.getvalue())
    if status == 0:
        outcome.warnings = written_warnings(out)
    outcome.verdict = judge(case, outcome, changed, check_ok)
    return outcome


def written_warnings(out) -> list | None:
    """The `warnings` list of the JSON a command wrote at `out` (a file, or a report folder's `report.json`)."""
    out = pathlib.Path(out)
    path = out / "report.json" if out.is_dir() else out
    try:
        found = json.loads(path.read_text()).get("warnings")
    except (OSError, ValueError, AttributeError):
        return None
    return found if isinstance(found, list) else None


def judge(case: Case, o: Outcome, changed: bool, check_ok) -> str:
    """One of: refused correctly, warned correctly, accepted correctly, silent failure (exit 0 with a wrong
    answer or no warning), misleading (advice that corrupts), traceback, refused badly, wrongly refused."""
    traced = "Traceback" in o.stderr or o.status not in (0, 2)
    if traced:
        return "traceback"
    text = o.message if case.expect == "refuse" else o.stderr
    if any(f in text for f in case.forbidden):
        return "misleading"
    if case.expect == "refuse":
        if o.status == 0:
            return "silent failure"
        if all(n in o.message for n in case.needles) and not changed:
            return "refused correctly"
        return "refused badly" + (" (output written)" if changed else " (message)")
    if o.status != 0:
        return "wrongly refused"
    if not check_ok:
        return "silent failure"
    if case.expect == "warn":
        # a warning on stderr, or a flight's note on stdout (what `load_flight` found and left out)
        warned = [l for l in o.stderr.splitlines() if "warning" in l.lower()]
        warned += [l for l in o.stdout.splitlines() if l.startswith("note: ")]
        if not any(all(n in l for n in case.needles) for l in warned):
            return "silent failure"
        # ... and the same in the answer's own `warnings`, where a script reading the JSON looks
        kept = [str(w.get("message", "")) for w in o.warnings or () if isinstance(w, dict)]
        if not any(all(n in m for n in case.needles) for m in kept):
            return "silent failure (warned on the terminal only)"
        return "warned correctly"
    return "accepted correctly"


GOOD = ("refused correctly", "warned correctly", "accepted correctly")
