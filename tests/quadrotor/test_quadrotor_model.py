"""The `Quadrotor` learned back from a rigid body simulated by scipy's DOP853 (written here, independently
of dynax's model code), `predict_ahead` against a rollout by hand, and the model file round trip."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynax
from dynax.internal import (
    body_frame_records,
    diagnosis_summary,
    score_flights,
    stable_substeps,
    write_json,
    write_report,
)

# A Crazyflie-sized X quadrotor: thrust per motor a m^2 + b m with m in PWM counts (hover near 40000).
MASS, GRAVITY = 0.030, 9.81
INERTIA = np.array([1.4e-5, 1.4e-5, 2.2e-5])
ARM, YAW_ARM = 0.0325, 0.006  # moment arm of each thrust about x and y [m]; yaw torque per newton [m]
A, B = 3.975e-11, 2.5e-7
ROLL_SIGNS = np.array([-1.0, -1.0, 1.0, 1.0])
PITCH_SIGNS = np.array([-1.0, 1.0, 1.0, -1.0])
YAW_SIGNS = np.array([-1.0, 1.0, -1.0, 1.0])
DT = 0.01


def _rotation(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _truth(t, state, m):
    q, v, omega = state[3:7], state[7:10], state[10:13]
    f = A * m**2 + B * m
    torque = np.array([ARM * ROLL_SIGNS @ f, ARM * PITCH_SIGNS @ f, YAW_ARM * YAW_SIGNS @ f])
    w, x, y, z = q
    p, qq, r = omega
    dq = 0.5 * np.array(
        [-x * p - y * qq - z * r, w * p + y * r - z * qq, w * qq + z * p - x * r, w * r + x * qq - y * p]
    )
    dv = _rotation(q) @ np.array([0.0, 0.0, f.sum() / MASS]) - np.array([0.0, 0.0, GRAVITY])
    domega = (torque - np.cross(omega, INERTIA * omega)) / INERTIA
    return np.concatenate([v, dq, dv, domega])


def _flight(seed, seconds=1.5, hold=5):
    """Random motor commands about hover (each held for `hold` samples) with a rate damper added at
    every sample (so the open-loop body does not tumble), integrated by DOP853 between samples."""
    rng = np.random.default_rng(seed)
    hover = (-B + np.sqrt(B**2 + A * MASS * GRAVITY)) / (2 * A)
    n = round(seconds / DT)
    noise = np.repeat(0.2 * rng.uniform(-1, 1, size=(n // hold + 1, 4)), hold, axis=0)[:n]
    state = np.concatenate([[0, 0, 1.0], [1.0, 0, 0, 0], rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3)])
    xs, us = [state], []
    for k in range(n):
        p, q, r = xs[-1][10:13]
        damping = 0.05 * (ROLL_SIGNS * p + PITCH_SIGNS * q + 0.3 * YAW_SIGNS * r)
        m = hover * (1 + noise[k] - damping)
        us.append(m)
        if k < n - 1:
            sol = solve_ivp(_truth, (0.0, DT), xs[-1], method="DOP853", rtol=1e-11, atol=1e-13, args=(m,))
            xs.append(sol.y[:, -1])
    xs, us = np.asarray(xs), np.asarray(us)
    us = np.concatenate([us, np.full((n, 1), 3.7)], axis=1)  # a steady battery
    return dynax.Trajectory(
        DT * np.arange(n),
        jnp.asarray(xs),
        jnp.asarray(us),
        dynax.Quadrotor.state_names,
        dynax.Quadrotor.input_names,
        "quadrotor",
    )


@pytest.fixture(scope="module")
def flights():
    return [_flight(seed) for seed in range(4)]


@pytest.fixture(scope="module")
def fitted(flights):
    start = dynax.Quadrotor.from_flights("nominal", flights, battery=False)
    return dynax.fit_quadrotor(start, flights, dynax.OneStep())


def test_one_step_learns_the_rigid_body_back(fitted):
    quad = fitted.model
    s = quad.input_scale[0]
    estimates = fitted.estimates()
    truth = {}
    for i in range(4):
        truth[f"dw/m{i + 1}^2"] = A * s**2 / MASS
        truth[f"dw/m{i + 1}"] = B * s / MASS
        for axis, signs, arm, inertia in (
            ("p", ROLL_SIGNS, ARM, INERTIA[0]),
            ("q", PITCH_SIGNS, ARM, INERTIA[1]),
            ("r", YAW_SIGNS, YAW_ARM, INERTIA[2]),
        ):
            truth[f"d{axis}/m{i + 1}^2"] = signs[i] * arm * A * s**2 / inertia
            truth[f"d{axis}/m{i + 1}"] = signs[i] * arm * B * s / inertia
    truth["dp/qr"] = (INERTIA[1] - INERTIA[2]) / INERTIA[0]
    truth["dq/pr"] = (INERTIA[2] - INERTIA[0]) / INERTIA[1]
    truth["dr/pq"] = (INERTIA[0] - INERTIA[1]) / INERTIA[2]
    assert set(estimates) == set(truth)
    # Trapezoidal one-step targets from DOP853 data at 100 Hz: quadrature errors of order dt^2 of the
    # accelerations' curvature, amplified by the near-collinearity of m^2 and m over the commands' range.
    # The thrust and moment maps (what the model is for) are checked tightly below; each weight to 3 %
    # of the largest weight of its axis.
    for name, value in truth.items():
        axis = name.split("/")[0]
        largest = max(abs(v) for k, v in truth.items() if k.startswith(axis + "/"))
        assert abs(estimates[name] - value) < 0.03 * largest, (name, estimates[name], value)
    # The learned accelerations at new states and commands: within 0.2 % of their spread.
    rng = np.random.default_rng(7)
    errors, scales = [], []
    for _ in range(20):
        state = np.concatenate([rng.normal(0, 1, 3), [1.0, 0, 0, 0], rng.normal(0, 0.5, 3), rng.normal(0, 1, 3)])
        state[3:7] = rng.normal(size=4)
        state[3:7] /= np.linalg.norm(state[3:7])
        m = s * (1 + 0.1 * rng.uniform(-1, 1, 4))
        want = _truth(0.0, state, m)[7:]
        got = np.asarray(quad.vector_field(0.0, jnp.asarray(state), jnp.asarray(np.append(m, 3.7))))[7:]
        errors.append(got - want)
        scales.append(want)
    assert np.max(np.abs(errors)) < 2e-3 * np.max(np.abs(scales))


def test_identify_fits_a_quadrotor_and_validates_it_on_held_out_flights(flights, fitted):
    """`fit_quadrotor` is `identify` with nothing held out (the same `Solution`, flights with or without
    `vbat` alike for a model that does not read it); with a flight held out, `identify` fits the others and
    scores the fitted quadrotor on it by the vehicle horizon error, ahead of holding the velocity."""
    start = dynax.Quadrotor.from_flights("nominal", flights, battery=False)
    whole = dynax.identify(start, flights, dynax.OneStep(), validation=dynax.Validate(holdout=0))
    assert whole.validation is None and whole.n_samples == sum(len(f) for f in flights)
    for field in ("value", "covariance", "std_errors", "loss"):
        np.testing.assert_array_equal(np.asarray(getattr(whole.solution, field)), np.asarray(getattr(fitted, field)))
    assert isinstance(whole.system, dynax.Quadrotor) and whole.system.input_scale == start.input_scale
    motors_only = [
        dynax.Trajectory(f.ts, f.xs, f.us[:, :4], f.state_names, f.input_names[:4], "quadrotor") for f in flights
    ]
    again = dynax.identify(start, motors_only, dynax.OneStep(), validation=dynax.Validate(holdout=0))
    np.testing.assert_allclose(np.asarray(again.value), np.asarray(fitted.value), rtol=1e-10)

    result = dynax.identify(start, flights[:3], dynax.OneStep(), validation=flights[3:])
    np.testing.assert_array_equal(
        np.asarray(result.value), np.asarray(dynax.fit_quadrotor(start, flights[:3], dynax.OneStep()).value)
    )
    error = result.validation
    assert error is not None and error.steps == (10, 25, 50) and error.n_windows == len(flights[3]) - 50
    np.testing.assert_array_equal(
        error.mae_per_state, dynax.flight_error(result.system, flights[3:], (10, 25, 50)).mae_per_state
    )
    held = dynax.flight_error(dynax.ConstantVelocity(), flights[3:], (10, 25, 50)).table("mae")
    # The model family holds the truth and the weights come back within 3 % (above): 0.5 s ahead on a flight it
    # never saw, a few per cent of what holding the velocity misses (the commands' effect) at most.
    for group in ("position", "velocity", "attitude", "body_rate"):
        assert error.table("mae")[group][-1] < 0.05 * held[group][-1], group
    # without validation records, each flight's last 20 % (0.3 s) is held out, at the horizons it holds
    tails = dynax.identify(start, flights, dynax.OneStep())
    assert tails.validation is not None and tails.validation.steps == (10, 25)
    assert tails.n_samples == sum(len(f) for f in flights) - 4 * 30
    with pytest.raises(dynax.UsageError, match="frequency"):
        dynax.identify(start, flights, dynax.FrequencyDomain())


def test_one_step_solution_carries_standard_errors(fitted):
    std = np.asarray(fitted.std_errors)
    assert std.shape == fitted.value.shape and np.all(np.isfinite(std)) and np.all(std > 0)
    assert fitted.names == fitted.model.body_model.parameter_names


def _by_hand(model, flight, start, n, **solver):
    """The states 1..n samples after `start`, each interval integrated by scipy under its held input."""
    field = jax.jit(lambda x, u: model.vector_field(0.0, x, u))
    state, us, path = np.asarray(flight.xs[start]), np.asarray(flight.us), []
    for h in range(n):
        u = jnp.asarray(us[start + h])
        state = solve_ivp(lambda t, y, u=u: np.asarray(field(jnp.asarray(y), u)), (0, DT), state, **solver).y[:, -1]
        path.append(state)
    return np.asarray(path)


def test_predict_ahead_matches_a_rollout_by_hand(fitted, flights):
    quad, flight = fitted.model, flights[0]
    steps = (1, 4, 12)
    predicted = np.asarray(dynax.predict_ahead(quad, flight, steps))
    assert predicted.shape == (len(flight) - 12, 3, 13)
    for i in (0, 37, len(flight) - 13):
        path = _by_hand(quad, flight, i, 12, method="DOP853", rtol=1e-12, atol=1e-14)
        # RK4 at the sample interval against DOP853: an error of order dt^4 per step.
        np.testing.assert_allclose(predicted[i], path[np.asarray(steps) - 1], rtol=0, atol=1e-6)


class _RateDamped(eqx.Module):
    """A fitted quadrotor with a rate damping faster than the sample rate resolves (as a refit can give)."""

    body: eqx.Module
    damping: float

    def vector_field(self, t, x, u):
        return self.body.vector_field(t, x, u).at[10:13].add(-self.damping * x[10:13])


def test_predict_ahead_resolves_a_mode_faster_than_the_sample_rate(fitted, flights):
    # 341 1/s at 100 Hz: h * lambda = -3.4, outside RK4's stability region (real-axis limit 2.785), so one
    # step per sample diverges; the chosen substeps follow the stiff reference (Radau) instead.
    stiff, flight = _RateDamped(fitted.model, 341.0), flights[0]
    assert stable_substeps(fitted.model, flight) == 1
    assert stable_substeps(stiff, flight) == 4
    one_step = np.asarray(dynax.predict_ahead(stiff, flight, (50,), substeps=1))
    assert not np.all(np.isfinite(one_step)) or np.max(np.abs(one_step[:, 0, 10:13])) > 1e3
    predicted = np.asarray(dynax.predict_ahead(stiff, flight, (1, 50)))
    for i in (0, 91):
        state = _by_hand(stiff, flight, i, 50, method="Radau", rtol=1e-10, atol=1e-12)[-1]
        # Four RK4 steps of 2.5 ms on a mode of 341 1/s: R(h lambda) = 0.4296 against the exact 0.4263 per step,
        # so the fast transient decays as it should: the rates within 1e-3 of about 0.6 rad/s after 0.5 s (two
        # steps of 5 ms, stable but at h lambda = -1.7, are 0.027 off).
        np.testing.assert_allclose(predicted[i, 1], state, rtol=0, atol=1e-3)


@pytest.fixture(scope="module")
def diagnosed(fitted, flights):
    """`dynax.diagnose` of the fitted rigid body, trusted as given, on two of the rigid-body flights held out; rate
    damping on `p` its one candidate (what the refit on whole NanoBench flights names on `q`)."""
    return dynax.diagnose(
        fitted.model,
        flights[:2],
        flights[2:],
        mode=dynax.Known(),
        candidates=(dynax.RotorDrag(3),),
        selection=dynax.Selection(max_terms=1, discovery=False, cross_fit=False),
        progress=False,
    )


def _with_rate_damping(report, fitted, flights, damping):
    """`report` with a rotor drag of `damping` on `p` as its finding, its held-out flights scored again as `diagnose`
    scores them (`score_flights`)."""
    import dataclasses

    extended = dynax.Extended(report.nominal_model, (dynax.RotorDrag(3, damping),))
    finding = {  # as the report lists a finding (its test's numbers are not what is scored here)
        "cause": "rotor_drag",
        "where": "p",
        "parameter": "drag_p",
        "coefficient": damping,
        "std_error": float("nan"),
        "gain": float("nan"),
        "p_value": float("nan"),
        "confidence": "not tested",
        "look_alikes": [],
    }
    named = dataclasses.replace(report, extended_model=extended, findings=[finding], flight_error=None)
    return score_flights(named, fitted.model, flights[2:])


@pytest.mark.slow  # about 4 min, the diagnosis in its fixture
def test_a_term_that_spoils_the_next_sample_is_noted_in_the_report(diagnosed, fitted, flights, tmp_path):
    # The flights are a rigid body without rate damping. The report scores its held-out flights per group beside
    # constant velocity. A damping of 341 1/s (what the joint refit gave on whole NanoBench flights) pulls every
    # predicted rate towards zero within a sample, and the report notes it; a physical 2 1/s barely moves it.
    j = diagnosed.to_json()
    assert set(j["flight_error"]["models"]) == {"constant velocity", "nominal", "extended"}
    assert j["flight_error"]["steps"] == [1, 10, 50] and j["flight_error"]["note"] is None
    groups = j["flight_error"]["models"]
    assert groups["nominal"]["mae"]["position"][-1] < groups["constant velocity"]["mae"]["position"][-1]

    stiff = _with_rate_damping(diagnosed, fitted, flights, 341.0)
    note = stiff.flight_error.note
    assert note is not None and "body_rate" in note and "rotor_drag@p" in note
    # (the position's first step moves by a micrometre against a sample's 0.1 mm of constant-velocity error)
    assert "position" not in note
    assert note in stiff.notes
    gentle = _with_rate_damping(diagnosed, fitted, flights, 2.0)
    assert gentle.flight_error.note is None and gentle.notes == diagnosed.notes

    # One source: report.json, report.md and the CLI's summary carry the report's note as it is.
    write_report(stiff, tmp_path, body_frame_records(fitted.model, flights[2:]), write_json=write_json)
    written = json.loads((tmp_path / "report.json").read_text())
    assert written["flight_error"]["note"] == note and note in written["notes"]
    assert note in (tmp_path / "report.md").read_text() and note in diagnosis_summary(stiff)


def test_unevenly_sampled_flights_are_refused_by_name(fitted, flights):
    # one sample dropped in the middle: no fixed-step rollout fits it, and each entry point says which it is
    flight = flights[0]
    keep = np.r_[0:40, 41 : len(flight)]
    gappy = dynax.Trajectory(
        flight.ts[keep],
        flight.xs[keep],
        flight.us[keep],
        flight.state_names,
        flight.input_names,
        flight.system,
        "gappy.csv",
    )
    with pytest.raises(dynax.UsageError, match=r"predict_ahead: the trajectory \(gappy.csv\) must be uniformly"):
        dynax.predict_ahead(fitted.model, gappy, (1, 10))
    with pytest.raises(dynax.UsageError, match=r"flight_error: the trajectory \(gappy.csv\) must be uniformly"):
        dynax.flight_error(fitted.model, [flights[1], gappy], (1, 10))


def test_predict_ahead_in_float32(fitted, flights):
    flight = flights[2]
    double = np.asarray(dynax.predict_ahead(fitted.model, flight, (1, 10)))
    single = dynax.predict_ahead(fitted.model, flight.astype(jnp.float32), (1, 10))
    assert single.dtype == jnp.float32
    # float32 rounding (1e-7 relative) grown over 10 RK4 steps of a model with rates of a few rad/s.
    np.testing.assert_allclose(np.asarray(single), double, rtol=0, atol=1e-4)


def test_constant_velocity_baseline_moves_on_the_straight_line(flights):
    flight = flights[1]
    predicted = np.asarray(dynax.predict_ahead(dynax.ConstantVelocity(), flight, (10,)))
    xs = np.asarray(flight.xs)
    np.testing.assert_allclose(predicted[:, 0, 0:3], xs[:-10, 0:3] + 10 * DT * xs[:-10, 7:10], atol=1e-12)
    np.testing.assert_allclose(predicted[:, 0, 7:13], xs[:-10, 7:13], atol=0)
    error = dynax.flight_error(dynax.ConstantVelocity(), flights, (1, 10))
    mae = np.asarray(error.mae_per_state)
    assert mae.shape == (2, 4) and np.all(mae[1] > mae[0])
    assert error.n_windows == sum(len(f) - 10 for f in flights) and error.rmse is None


def test_model_file_round_trip(fitted, tmp_path):
    path = tmp_path / "model.json"
    dynax.save_model(fitted.model, path, criterion="one-step")
    loaded = dynax.load_model(path)
    assert isinstance(loaded, dynax.Quadrotor) and loaded.input_scale == fitted.model.input_scale
    x = jnp.asarray(np.concatenate([[0, 0, 1], [0.9, 0.1, -0.2, 0.3], [0.2, -0.1, 0.3], [1.0, -2.0, 0.5]]))
    u = jnp.asarray([4e4, 4.1e4, 3.9e4, 4e4, 3.7])
    np.testing.assert_array_equal(
        np.asarray(loaded.vector_field(0.0, x, u)), np.asarray(fitted.model.vector_field(0.0, x, u))
    )
    obj = json.loads(path.read_text())
    obj["weights"][3][0] = "a lot"
    path.write_text(json.dumps(obj))
    with pytest.raises(dynax.DataError, match="model.json"):
        dynax.load_model(path)
    obj["weights"][3][0] = 0.0
    obj["mask"][2][1] = 7  # not a mask entry: an edited file, not read as True
    path.write_text(json.dumps(obj))
    with pytest.raises(dynax.DataError, match=r"mask \[2\]\[1\] is 7"):
        dynax.load_model(path)
    # A folder that does not exist: refused naming the user's path and the folder (was a FileNotFoundError naming a
    # temporary file beside it), and nothing is written.
    missing = tmp_path / "no-such-folder" / "model.json"
    with pytest.raises(dynax.UsageError, match="no-such-folder.*does not exist"):
        dynax.save_model(fitted.model, missing)
    assert not missing.parent.exists()


def test_joined_flights_give_no_window_across_a_break():
    # (fit_quadrotor joins the four flights above: a window across a join would see a jump of metres
    # and rad/s between samples, and the rigid body would not be learned back to 0.2 %.)
    from dynax.internal import valid_starts

    # Two records of 5 and 6 samples joined: 3-step windows start at 0, 1 (first) and 5, 6, 7 (second).
    np.testing.assert_array_equal(valid_starts(11, 3, 1, breaks=[5]), [0, 1, 5, 6, 7])
    np.testing.assert_array_equal(valid_starts(11, 3, 2, breaks=[5]), [0, 5, 7])
    np.testing.assert_array_equal(valid_starts(11, 3, 1), np.arange(8))  # no breaks: as before


def test_backprop_warm_start_refines_the_given_weights(fitted, flights):
    # A thrust map 20 % too strong: refined from there (warm start) the backprop fit moves it back
    # toward the one-step fit (the truth, to its quadrature error); from the one-step fit (cold) it
    # starts at the truth already, so its loss stays below the warm start's after the same steps.
    body = fitted.model.body_model
    thrust = np.asarray([name.startswith("dw/") for name in body.parameter_names])
    truth = np.asarray(fitted.value)
    wrong = np.where(thrust, 1.2 * truth, truth)
    start = fitted.model.with_body_model(body.with_parameter_vector(jnp.asarray(wrong)))
    criterion = dynax.Backprop(horizon=0.2, max_steps=8, stride=5)
    warm = dynax.fit_quadrotor(start, flights, criterion, warm_start=True, progress=False)
    cold = dynax.fit_quadrotor(start, flights, criterion, progress=False)
    losses = [loss for _, loss in warm.history]
    assert losses[-1] < losses[0] and cold.history[-1][1] < losses[-1]
    refined = np.asarray(warm.value)
    assert np.linalg.norm((refined - truth)[thrust]) < 0.5 * np.linalg.norm((wrong - truth)[thrust])


def test_a_one_step_fit_singular_in_float32_is_refused_not_returned():
    """Each motor's m^2, m and the constant are nearly collinear, so on a flight about hover the one-step normal
    equations have a condition number near 1e8: singular to float32's precision. With JAX's float64 mode off the
    fit used to return weights with no error (on this 3 s flight they differed from the float64 fit's by 96 % in
    the median; on 15 s they were infinite); it now refuses them, naming the fix. In float64 it goes through."""
    from .synthetic_flight import quadrotor_flight

    flight = quadrotor_flight(3.0, seed=20)
    start = dynax.Quadrotor.from_flights("nominal", [flight])
    with jax.enable_x64(False):
        with pytest.raises(FloatingPointError, match=r"fit_one_step: .*float32, condition number .*jax_enable_x64"):
            dynax.fit_quadrotor(start, flight.astype(jnp.float32), dynax.OneStep(), progress=False)
    assert np.all(np.isfinite(np.asarray(dynax.fit_quadrotor(start, flight, progress=False).value)))


@pytest.mark.slow  # about 1 min; the suite keeps the one-step fit's refusal
def test_a_lagged_fit_singular_in_float32_is_refused_not_returned():
    """The lagged (EM-free) iteration solves normal equations as collinear as the one-step fit's at every step. Warm
    started in float32 from a float64 one-step fit, it used to stop after one step and return weights 93 % off the
    float64 lagged fit's in the median, with no error; it now refuses them as the one-step fit does."""
    from .synthetic_flight import quadrotor_flight

    flight = quadrotor_flight(3.0, seed=20)
    start = dynax.Quadrotor.from_flights("nominal", [flight])
    one_step = dynax.fit_quadrotor(start, flight, progress=False).model
    lagged = dynax.Lagged(horizon=0.2, max_iterations=3)
    with jax.enable_x64(False):
        model32 = jax.tree_util.tree_map(
            lambda a: a.astype(jnp.float32) if isinstance(a, jax.Array) and a.dtype == jnp.float64 else a, one_step
        )
        with pytest.raises(FloatingPointError, match=r"fit_lagged: .*float32, condition number"):
            dynax.fit_quadrotor(model32, flight.astype(jnp.float32), lagged, warm_start=True, progress=False)
    fitted = dynax.fit_quadrotor(one_step, flight, lagged, warm_start=True, progress=False)
    assert np.all(np.isfinite(np.asarray(fitted.value)))


def test_scaled_inputs_of_a_float64_log_in_float32_mode_say_nothing(flights):
    """A log read as numpy float64 while JAX's float64 mode is off is scaled in float32 without JAX's "float64
    requested ... truncated" warning on every call (a float32 diagnosis printed it dozens of times)."""
    import warnings

    quad = dynax.Quadrotor.from_flights("nominal", flights, battery=False)
    with jax.enable_x64(False), warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        scaled = quad.scaled_inputs(np.asarray(flights[0].us, dtype=np.float64))
    assert scaled.dtype == jnp.float32
