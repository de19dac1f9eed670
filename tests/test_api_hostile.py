"""The Python API met with hostile but ordinary input (issue 47, item 6): every call ends in an answer or a
refusal that names the argument (and, for data, the column and row), never in a traceback from inside JAX or
NumPy nor in a silent wrong answer. The probe table (before and after) is `docs/devdocs/api_hostile.md`.

The records are built with NumPy (sines, not simulations): every case here is refused before any fit, so the
file runs in seconds.
"""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import DataError, Trajectory, UsageError

# The calls are wrong on purpose: a type checker would refuse them before dynax could.
# pyright: reportArgumentType=false, reportCallIssue=false

STATES = ("q1", "q2", "dq1", "dq2")
INPUTS = ("tau2",)
N = 200


def _arrays(n=N):
    ts = np.arange(n) * 0.01
    q = np.stack([0.3 * np.sin(2 * ts), 0.5 * np.sin(3 * ts + 1)], axis=1)
    dq = np.stack([0.6 * np.cos(2 * ts), 1.5 * np.cos(3 * ts + 1)], axis=1)
    return ts, np.concatenate([q, dq], axis=1), np.sin(5 * ts)[:, None]


def _record(n=N, edit=None, **fields):
    ts, xs, us = _arrays(n)
    if edit is not None:
        edit(ts, xs, us)
    args = dict(ts=ts, xs=xs, us=us, state_names=STATES, input_names=INPUTS, system="acrobot", source="")
    args.update(fields)
    return Trajectory(**args)


def _flight(n=400):
    """A quadrotor record in hover with small sines on every state and motor (NumPy, no dynamics: the refusals
    come before any fit reads it as a flight)."""
    ts = np.arange(n) * 0.01
    wave = lambda k: 0.01 * np.sin((1 + 0.37 * k) * 3 * ts + k)  # noqa: E731
    xs = np.stack([wave(k) for k in range(13)], axis=1)
    xs[:, 2] += 1.0
    xs[:, 3:7] = np.array([1.0, 0, 0, 0]) + xs[:, 3:7]
    xs[:, 3:7] /= np.linalg.norm(xs[:, 3:7], axis=1, keepdims=True)
    us = 0.6 + np.stack([wave(13 + k) for k in range(4)], axis=1)
    states = ("x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "p", "q", "r")
    return Trajectory(ts, xs, us, states, ("m1", "m2", "m3", "m4"), "quadrotor")


def _nan_at_q2_row_101(ts, xs, us):
    xs[100, 1] = np.nan


def _inf_at_tau2_row_51(ts, xs, us):
    us[50, 0] = np.inf


def _int_record():
    ts, xs, us = _arrays()
    return Trajectory(ts, np.round(xs * 1000).astype(int), us, STATES, INPUTS, "acrobot")


def _renamed():
    ts, xs, us = _arrays()
    return Trajectory(ts, xs, us, ("a", "b", "c", "d"), ("f",), "acrobot")


def _two_columns():
    ts, xs, us = _arrays()
    return Trajectory(ts, xs[:, :2], us, ("q1", "q2"), INPUTS)


def _identify(data, **kwargs):
    return lambda: dynax.identify(dynax.Acrobot(), data() if callable(data) else data, **kwargs)


def _diagnose(train, validation=None, system=None, **kwargs):
    def call():
        return dynax.diagnose(
            system or dynax.Acrobot(),
            train() if callable(train) else train,
            validation() if callable(validation) else validation,
            progress=False,
            **kwargs,
        )

    return call


def _predict(steps=(1,), trajectory=None):
    return lambda: dynax.predict_ahead(dynax.Acrobot(), trajectory or _record(), steps=steps)


def _trajectory(ts=None, xs=None, us=None, states=STATES, inputs=INPUTS):
    t, x, u = _arrays(5)

    def call():
        return Trajectory(t if ts is None else ts, x if xs is None else xs, u if us is None else us, states, inputs)

    return call


# (id, call, the error, a pattern its message must match, {attribute: value} the error must carry).
# The first group failed on `main` (the docs page says how); the second already behaved and is kept so.
FIXED = [
    ("trajectory-xs-short", _trajectory(xs=np.zeros((4, 4))), UsageError, r"`xs` must have shape \(5, 4\)", {}),
    ("trajectory-xs-1d", _trajectory(xs=np.zeros(5), states=("q",)), UsageError, r"`xs` must have shape", {}),
    ("trajectory-us-1d", _trajectory(us=np.zeros(5)), UsageError, r"`us` must have shape \(5, 1\)", {}),
    ("trajectory-names-count", _trajectory(states=STATES[:3]), UsageError, r"`xs` must have shape \(5, 3\)", {}),
    ("trajectory-ts-2d", _trajectory(ts=np.zeros((5, 1))), UsageError, r"`ts` must be 1-d", {}),
    ("trajectory-lists", _trajectory(ts=[0.0, 1, 2, 3, 4]), UsageError, r"`ts` must be an array", {}),
    ("trajectory-names-str", _trajectory(xs=np.zeros((5, 1)), states="q"), UsageError, r"`state_names`", {}),
    (
        "trajectory-names-repeated",
        _trajectory(states=("q1", "q1", "dq1", "dq2")),
        UsageError,
        r"`state_names` names \['q1'\] more than once",
        {},
    ),
    ("trajectory-complex", _trajectory(xs=np.zeros((5, 4), complex)), UsageError, r"`xs` must hold real", {}),
    ("trajectory-strings", _trajectory(ts=np.array(list("01234"))), UsageError, r"`ts` must hold real", {}),
    (
        "identify-nan",
        _identify(lambda: _record(edit=_nan_at_q2_row_101)),
        DataError,
        r"a sample of nan at t = 1 s",
        {"column": "q2", "row": 101},
    ),
    (
        "identify-inf-input",
        _identify(lambda: _record(edit=_inf_at_tau2_row_51)),
        DataError,
        r"a sample of inf at t = 0.5 s",
        {"column": "tau2", "row": 51},
    ),
    ("identify-int", _identify(_int_record), UsageError, r"`xs` holds int64, not floating point", {}),
    ("identify-renamed", _identify(_renamed), UsageError, r"has columns \('a', 'b', 'c', 'd'\)", {}),
    (
        "identify-class",
        lambda: dynax.identify(dynax.Acrobot, _record()),  # pyright: ignore[reportArgumentType]
        UsageError,
        r"`system` must be a dynax system instance",
        {},
    ),
    (
        "diagnose-nan",
        _diagnose(lambda: _record(edit=_nan_at_q2_row_101), _record),
        DataError,
        r"`train` record 0: a sample of nan",
        {"column": "q2", "row": 101},
    ),
    (
        "diagnose-inf-input",
        _diagnose(_record, lambda: _record(edit=_inf_at_tau2_row_51)),
        DataError,
        r"`validation` record 0: a sample of inf",
        {"column": "tau2", "row": 51},
    ),
    ("diagnose-int", _diagnose(_int_record, _record), UsageError, r"`xs` holds int64", {}),
    ("diagnose-validation-columns", _diagnose(_record, _two_columns), UsageError, r"`validation` record 0 has", {}),
    ("diagnose-one-sample", _diagnose(lambda: _record(1), _record), DataError, r"has 1 sample\(s\)", {}),
    (
        "simulate-complex",
        lambda: dynax.simulate(dynax.Acrobot(), np.zeros(4, complex), np.arange(5) * 0.01),
        UsageError,
        r"`x0` must be real",
        {},
    ),
    ("predict-fraction", _predict(steps=(2.5,)), UsageError, r"`steps` must be whole numbers", {}),
    ("predict-bool", _predict(steps=(True,)), UsageError, r"`steps` must be whole numbers", {}),
    ("predict-str", _predict(steps="10"), UsageError, r"`steps` must be a sequence", {}),
    (
        "predict-other-states",
        _predict(trajectory=Trajectory(*_arrays()[:1], _arrays()[1][:, :3], _arrays()[2], ("a", "b", "c"), INPUTS)),
        UsageError,
        r"states \('a', 'b', 'c'\) are not Acrobot's",
        {},
    ),
    ("from-physical-str", lambda: dynax.Acrobot.from_physical(lc2="1"), UsageError, r"`lc2` must be a real", {}),
    ("from-physical-negative", lambda: dynax.Acrobot.from_physical(m1=-1.0), UsageError, r"`m1` = -1.0", {}),
    ("from-physical-nan", lambda: dynax.Acrobot.from_physical(m1=float("nan")), UsageError, r"`m1` = nan", {}),
    ("from-physical-unknown", lambda: dynax.Acrobot.from_physical(mass=1.0), UsageError, r"\['mass'\]", {}),
    (
        "load-trajectory-instance",
        lambda: dynax.load_trajectory("x.csv", dynax.Acrobot()),  # pyright: ignore[reportArgumentType]
        UsageError,
        r"`system` must be a system's name",
        {},
    ),
    # simulation_error: a horizon of zero, below zero or not a number was scored as one sample; none or a bare
    # number ended in a numpy or JAX error from inside.
    *[
        (
            f"simulation-error-horizons-{name}",
            (lambda h: lambda: dynax.simulation_error(dynax.Acrobot(), _record(), h))(horizons),
            UsageError,
            r"`horizons_s` must be a non-empty sequence of positive, finite seconds",
            {},
        )
        for name, horizons in (
            ("negative", (-0.1,)),
            ("zero", (0.0,)),
            ("nan", (float("nan"),)),
            ("empty", ()),
            ("scalar", 0.5),
        )
    ],
    # a delay or time constant below zero (an input acting before its command, an unstable filter) or NaN was
    # accepted and simulated; a term's or `Extended`'s refusal was a ValueError (exit 1 on the command line)
    *[
        (f"{name}-{label}", (lambda make, v: lambda: make(v))(make, value), UsageError, pattern, {})
        for name, make, pattern in (
            ("input-delay", lambda v: dynax.InputDelay(0, v), r"InputDelay: `delay` must be a time >= 0"),
            ("input-lag", lambda v: dynax.InputLag(0, v), r"InputLag: `time_constant` must be a time >= 0"),
            ("motor-delay", lambda v: dynax.MotorDelay(delay=v), r"MotorDelay: `delay` must be a time >= 0"),
        )
        for label, value in (("negative", -0.02), ("nan", float("nan")))
    ],
    # a flight of 8 samples gave 7 one-step equations per axis for up to 9 weights an axis: fitted without a word
    (
        "fit-quadrotor-eight-samples",
        lambda: dynax.fit_quadrotor(dynax.Quadrotor.from_flights("nominal", [_flight()]), _flight(8), progress=False),
        DataError,
        r"7 one-step equation\(s\) per body axis, fewer than the 9 weights the model fits on `p`",
        {},
    ),
    (
        "simulation-error-stride-zero",
        lambda: dynax.simulation_error(dynax.Acrobot(), _record(), (0.1,), stride=0),
        UsageError,
        r"`stride` must be a positive whole number",
        {},
    ),
]

BEHAVED = [
    ("trajectory-unknown-column", lambda: _record().state("x"), UsageError, r"no state column 'x'", {}),
    ("trajectory-split", lambda: _record().split(1.5), UsageError, r"`fraction` must be in \(0, 1\)", {}),
    (
        "identify-unsorted-ts",
        _identify(lambda: _record(edit=lambda ts, xs, us: ts.__setitem__(slice(100, 102), ts[[101, 100]]))),
        UsageError,
        r"row 102: time does not strictly increase",
        {},
    ),
    ("identify-three-states", _identify(_two_columns), UsageError, r"has 2 states and 1 inputs", {}),
    ("identify-one-sample", _identify(lambda: _record(1)), DataError, r"has 1 sample\(s\): too few", {}),
    ("identify-two-samples", _identify(lambda: _record(2)), DataError, r"has 2 sample\(s\): too few", {}),
    ("identify-empty-list", _identify([]), UsageError, r"non-empty list", {}),
    ("identify-array", _identify(np.zeros((5, 4))), UsageError, r"got ndarray", {}),
    (
        "diagnose-known-other-system",
        _diagnose(_record, lambda: _record(150), system=dynax.DoublePendulum(), mode=dynax.Known()),
        UsageError,
        r"DoublePendulum has",
        {},
    ),
    (
        "simulate-x0-length",
        lambda: dynax.simulate(dynax.Acrobot(), np.zeros(3), np.arange(5) * 0.01),
        UsageError,
        r"`x0` has 3 entries",
        {},
    ),
    (
        "simulate-ts-decreasing",
        lambda: dynax.simulate(dynax.Acrobot(), np.zeros(4), np.arange(5)[::-1] * 0.01),
        UsageError,
        r"`ts` must strictly increase",
        {},
    ),
    (
        "simulate-us-width",
        lambda: dynax.simulate(dynax.Acrobot(), np.zeros(4), np.arange(5) * 0.01, np.zeros((5, 2))),
        UsageError,
        r"`us` must have shape \(time, 1\)",
        {},
    ),
    (
        "simulate-nan-x0",
        lambda: dynax.simulate(dynax.Acrobot(), np.array([0, np.nan, 0, 0]), np.arange(5) * 0.01),
        UsageError,
        r"`x0`\[1\] is nan",
        {},
    ),
    (
        # a model with an internal state (a lag): an IndexError from inside before
        "predict-internal-states",
        lambda: dynax.predict_ahead(dynax.Extended(dynax.Acrobot(), (dynax.InputLag(0, 0.03),)), _record(), (1,)),
        UsageError,
        r"internal states \('tau2_lag',\).*simulation_error",
        {},
    ),
    ("predict-zero", _predict(steps=(0,)), UsageError, r"positive numbers of samples", {}),
    ("predict-negative", _predict(steps=(-3,)), UsageError, r"positive numbers of samples", {}),
    ("predict-too-long", _predict(steps=(500,)), UsageError, r"too few for 500 steps ahead", {}),
    ("predict-scalar", _predict(steps=5), UsageError, r"`steps` must be", {}),
    (
        "coulomb-joint-out-of-range",
        lambda: dynax.Extended(dynax.Acrobot(), (dynax.CoulombFriction(5, 0.1),)),
        UsageError,
        r"`joint=5` but Acrobot has 2 joint",
        {},
    ),
    ("coulomb-joint-negative", lambda: dynax.CoulombFriction(-1, 0.1), UsageError, r"non-negative int index", {}),
    (
        "delay-input-out-of-range",
        lambda: dynax.Extended(dynax.Acrobot(), (dynax.InputDelay(3, 0.01),)),
        UsageError,
        r"`input=3` but Acrobot has inputs",
        {},
    ),
    (
        "extended-terms-not-tuple",
        lambda: dynax.Extended(dynax.Acrobot(), dynax.CoulombFriction(1, 0.1)),  # pyright: ignore[reportArgumentType]
        UsageError,
        r"`terms` must be a tuple",
        {},
    ),
    ("load-model-missing", lambda: dynax.load_model("/nonexistent/m.json"), DataError, r"cannot be read", {}),
    (
        "save-model-acrobot",
        lambda: dynax.save_model(dynax.Acrobot(), "m.json"),
        UsageError,
        r"expected a Quadrotor",
        {},
    ),  # pyright: ignore[reportArgumentType]
    (
        "load-trajectory-missing",
        lambda: dynax.load_trajectory("/nonexistent.csv", "acrobot"),
        DataError,
        r"no such file",
        {},
    ),
    ("load-trajectory-unknown-system", lambda: dynax.load_trajectory("x.csv", "zeppelin"), UsageError, r"zeppelin", {}),
]


@pytest.mark.wrong_types
@pytest.mark.parametrize(
    "call, error, pattern, attributes", [case[1:] for case in FIXED + BEHAVED], ids=[c[0] for c in FIXED + BEHAVED]
)
def test_refused_by_name(call, error, pattern, attributes):
    with pytest.raises(error, match=pattern) as caught:
        call()
    for name, value in attributes.items():
        assert getattr(caught.value, name) == value


def test_load_model_refuses_a_truncated_or_foreign_file(tmp_path):
    truncated = tmp_path / "truncated.json"
    truncated.write_text('{"system": "quadrotor", "model": "accel')
    with pytest.raises(DataError, match="is not a JSON model file"):
        dynax.load_model(truncated)
    foreign = tmp_path / "acrobot.json"
    foreign.write_text(json.dumps({"system": "acrobot"}))
    with pytest.raises(DataError, match="system = 'acrobot'") as caught:
        dynax.load_model(foreign)
    assert caught.value.column == "system"


def test_valid_records_keep_their_answers():
    """The new checks pass what was valid: integer times, float32 records, a record constructed under `jit`."""
    ts, xs, us = _arrays(5)
    assert len(Trajectory(np.arange(5), xs, us, STATES, INPUTS)) == 5
    assert Trajectory(ts, xs, us, list(STATES), INPUTS).xs.shape == (5, 4)
    assert _record().astype(jnp.float32).xs.dtype == jnp.float32
    import jax

    @jax.jit
    def length(t, x, u):
        return Trajectory(t, x, u, STATES, INPUTS).xs.sum()

    assert np.isfinite(float(length(ts, xs, us)))


@pytest.mark.parametrize(
    "edit, pattern",
    [
        (lambda obj: obj["mask"][2].__setitem__(1, 7), r"mask \[2\]\[1\] is 7"),
        (lambda obj: obj["weights"][3].__setitem__(0, float("nan")), r"weight \[3\]\[0\] .* not a finite number"),
        (lambda obj: obj["features"].__setitem__(0, "thrust"), r"unknown features \['thrust'\]"),
        (lambda obj: obj["weights"].pop(), r"must be 6 x 11 .*shape \(5, 11\)"),
    ],
    ids=["mask-entry-7", "nan-weight", "unknown-feature", "five-rows"],
)
def test_load_model_checks_a_helicopter_file_as_a_quadrotor_file(tmp_path, edit, pattern):
    # A helicopter MODEL.json was read without the quadrotor file's checks: a mask entry of 7 as True, a NaN weight
    # as a model that predicts NaN, an unknown feature or five rows of weights as a KeyError or a shape error later.
    from tests.cli.hostile_cases import helicopter_model_file

    path = helicopter_model_file(tmp_path, 9.81)
    assert isinstance(dynax.load_model(path), dynax.Helicopter)  # the file as written loads
    obj = json.loads(open(path).read())
    edit(obj)
    open(path, "w").write(json.dumps(obj))
    with pytest.raises(DataError, match=pattern):
        dynax.load_model(path)
