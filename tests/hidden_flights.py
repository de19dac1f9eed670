"""The calibration battery's quadrotor cases: flights of `tests/quadrotor/synthetic_flight.py`, made outside dynax.

Each flight is a Crazyflie-sized X quadrotor (`synthetic_flight.NANO`: 30 g, 46 mm arms) under a geometric
controller at 100 Hz, integrated by scipy's DOP853 with the hidden effect written out there in numpy: rotor drag
as a body-frame force, a constant body force or moment, one motor's first-order lag, a true dead time on every
motor, one motor's thrust per command off the others', the voltage's square law on thrust per command, and
Cheeseman and Bennett's ground effect. `tests.hidden_cases` holds the cases (system `quadrotor`); this module
flies them (`flights`), diagnoses them as the quadrotor tests do (`diagnose_flights`) and computes the truth's own
gain on the held-out flights (`truth_gain`), by fixed-step RK4 on the generator's own vector field, not by dynax.
"""

import functools

import numpy as np

from tests.quadrotor import synthetic_flight as sf

FLIGHT_S = 10.0  # every training and held-out flight, unless a case says otherwise (its `flight`)
BODY_AXES = ("u", "v", "w", "p", "q", "r")
MOTORS = ("m1", "m2", "m3", "m4")
GROUPS = ((0, 1, 2), (3, 4, 5, 6), (7, 8, 9), (10, 11, 12))  # position, attitude, body velocity, rates
DRAG_W = 10.31 / 9.18  # rotor drag on w per drag on u and v: the Crazyflie 2.0's (Foerster 2015)


def effects(case) -> dict:
    """The hidden effect of `case` as `synthetic_flight.quadrotor_flight`'s keywords (no sag: see `plan`)."""
    if case.cause == "rotor_drag":
        return {"drag": (case.size, case.size, DRAG_W * case.size)}
    if case.cause == "body_bias":
        return {"bias": (BODY_AXES.index(case.where), case.size)}
    if case.cause == "motor_delay":
        return {"delay": case.size}
    if case.cause == "input_lag":
        return {"lag": (MOTORS.index(case.where), case.size)}
    if case.cause == "motor_lag":
        return {"lag": ("all", case.size)}
    if case.cause == "input_gain":
        return {"gain": (MOTORS.index(case.where), case.size)}
    if case.cause == "ground_effect":
        return {"ground": case.size}
    return {}


def sag_schedule(span: float) -> tuple[list, tuple]:
    """Flights at different charges over a pack that falls `span` volts from 4.2 V: two training flights (the
    first and last thirds of the span, apart by a seventh) and one held out between them (4.2-3.9 and 3.8-3.5,
    held out 4.1-3.6, for 0.7 V)."""
    at = lambda share: 4.2 - share * span  # noqa: E731
    return [(at(0.0), at(3 / 7)), (at(4 / 7), at(1.0))], (at(1 / 7), at(6 / 7))


def plan(case) -> dict:
    """The flights of `case` (keywords of `quadrotor_flight`, seeds from the case's) and how it is diagnosed.

    `train`, `validation`: one dict per flight; `healthy`: in `known` mode, the flight of the healthy vehicle the
    trusted model is fitted on (the effect appears afterwards, as a propeller is chipped); `battery`: the motor
    map reads `vbat` (False for every case whose flights log it: the sag must be found, not modelled);
    `thrust`: the thrust map is refitted by simulation error with each candidate (`Refit(parameters=...)`, as
    battery sag and ground effect need); `floor`: the floor's height, given (`ground_effect` a candidate)."""
    common = dict(case.flight)
    duration = common.pop("duration", FLIGHT_S)
    n_train, n_held = common.pop("n_train", 1), common.pop("n_held", 1)
    base = {"duration": duration, **common, **effects(case)}
    s = case.seed * 10
    out = {"healthy": None, "battery": None, "thrust": case.mode == "refit thrust", "floor": None}
    sagging = case.cause == "battery_sag" or case.law == "steady vbat"
    if sagging:
        span = case.size if case.cause == "battery_sag" else 0.0
        train, held = sag_schedule(span)
        if span == 0.0:  # the control: a steady 4 V logged, no sag
            out["train"] = [{**base, "vbat": True, "seed": s + k} for k in range(2)]
            out["validation"] = [{**base, "vbat": True, "seed": s + 5, "duration": duration + 5.0}]
        else:
            out["train"] = [{**base, "sag": v, "seed": s + k} for k, v in enumerate(train)]
            out["validation"] = [{**base, "sag": held, "seed": s + 5, "duration": duration + 5.0}]
        out["battery"] = False
    else:
        out["train"] = [{**base, "seed": s + k} for k in range(n_train)]
        out["validation"] = [{**base, "seed": s + 5 + k} for k in range(n_held)]
    if case.cause == "ground_effect" or case.law == "over the floor":
        out["floor"] = 0.0
    if case.mode == "known":
        healthy = {k: v for k, v in base.items() if k not in effects(case)}
        out["healthy"] = {**healthy, "seed": s + 9}
    return out


@functools.lru_cache(maxsize=2)  # the diagnosis and the truth's gain read the same flights
def flights(case):
    """`(healthy, train, validation)`: the flights of `case` (`healthy` None outside `known` mode)."""
    p = plan(case)
    fly = lambda kw: sf.quadrotor_flight(**kw)  # noqa: E731
    return (
        None if p["healthy"] is None else fly(p["healthy"]),
        [fly(kw) for kw in p["train"]],
        [fly(kw) for kw in p["validation"]],
    )


def diagnose_flights(case, flights_=None):
    """`dynax.diagnose` on `case`'s flights as `tests/quadrotor` diagnoses each cause: from `Quadrotor.from_flights
    ("nominal")`, refitted one step (`Refit()`), with the thrust map refitted with each candidate (`refit thrust`),
    or the model fitted on the healthy vehicle's flight and trusted (`known`); at most two causes, as every case."""
    import dynax
    import dynax.internal

    p = plan(case)
    healthy, train, validation = flights(case) if flights_ is None else flights_
    if healthy is not None:
        quad = dynax.Quadrotor.from_flights("nominal", [healthy], battery=p["battery"])
        quad = dynax.fit_quadrotor(quad, healthy, progress=False).model
        mode = dynax.Known()
    else:
        quad = dynax.Quadrotor.from_flights("nominal", train, battery=p["battery"])
        mode = dynax.Refit(parameters=dynax.internal.thrust_parameters(quad)) if p["thrust"] else dynax.Refit()
    body = dynax.internal.body_frame_system(quad, train[0].input_names)
    return dynax.diagnose(
        quad,
        train,
        validation,
        mode=mode,
        selection=dynax.Selection(max_terms=2),
        progress=False,
        candidates=dynax.internal.quadrotor_candidates(body, floor=p["floor"]),
    )


# --- the truth's own gain ----------------------------------------------------------------------------------------


def _body_states(xs):
    """World-frame flight states with the body velocity R^T v in place of v (the diagnosis's coordinates)."""
    out = np.array(xs, float)
    for i, x in enumerate(out):
        out[i, 7:10] = sf.rotation(x[3:7]).T @ x[7:10]
    return out


def _rollout(x0, commands, late, effects_, battery, rotor0, n_steps, substeps=1, vehicle=sf.NANO):
    """The generator's vector field (`synthetic_flight._field`) by RK4 from `x0` under the logged normalised
    `commands` (rows from `late` samples before the window; the rotors receive row `j` at step `j`), the
    battery factor of each step, the lagged motor's rotor starting at `rotor0`; `n_steps` samples."""
    dt = 0.01
    h = dt / substeps
    s = np.concatenate([x0, rotor0])
    lagged = sf.lagging(effects_)
    out = []
    for j in range(n_steps):
        received = commands[j]
        s[13:17] = np.where(lagged, s[13:17], received)
        for _ in range(substeps):
            # private: the generator's own law (tests/quadrotor/synthetic_flight.py, not dynax)
            f = lambda y: sf._field(0.0, y, received, effects_, battery[j], vehicle)  # noqa: E731
            a = f(s)
            b = f(s + 0.5 * h * a)
            c = f(s + 0.5 * h * b)
            s = s + h / 6 * (a + 2 * b + 2 * c + f(s + h * c))
        s[3:7] /= np.linalg.norm(s[3:7])
        out.append(s[:13].copy())
    return np.asarray(out)


def truth_gain(case, horizon_s: float, stride_s: float = 0.05) -> float:
    """The truth's held-out gain over the truth without its effect, scored as the diagnosis scores a candidate: on
    every held-out flight a window every `stride_s`, started from the measured state (the body velocity in place of
    the world velocity, as the diagnosis's coordinates), rolled out `horizon_s` under the logged commands; the mean
    over steps and states of the squared error with each group of states (position, attitude, body velocity, rates)
    in units of the effect-free law's RMS error of that group on these windows, as the diagnosis scales a vehicle by
    its starting model's (`dynax.internal.flight_state_scale`); gain = 1 - mean score with the effect / mean score
    without, the mean of the four groups' gains. A lagged motor's rotor starts settled on the window's first
    command. Without the effect a sagging battery is held at the training flights' median voltage (what a map of
    the commands alone is fitted to). Exact in `known` mode; in refit mode, where the refit absorbs part of the
    effect, an upper bound. `truth_gains` also gives the same windows' position RMSE gain (the report's `gain`)."""
    return truth_gains(case, horizon_s, stride_s)[0]


@functools.lru_cache(maxsize=4)
def truth_gains(case, horizon_s: float, stride_s: float = 0.05) -> tuple[float, float]:
    """`(gain, position_gain)`: `truth_gain`'s, and the gain in the held-out windows' position RMSE at `horizon_s`
    (the report's `gain`: 1 - RMSE with the effect / RMSE without, over every window's last step)."""
    if case.cause is None:
        return 0.0, 0.0
    p = plan(case)
    _, _, validation = flights(case)
    truth = effects(case)
    late = int(round(truth.pop("delay", 0.0) / 0.01))
    median_v = float(np.median(np.concatenate([_volts(kw) for kw in p["train"]])))
    n_ref, stride = round(horizon_s / 0.01), max(1, round(stride_s / 0.01))
    errors = ([], [])
    for kw, flight in zip(p["validation"], validation):
        xs, commands = np.asarray(flight.xs, float), np.asarray(flight.us, float)[:, :4] / sf.NANO.unit
        measured = _body_states(xs)
        volts = _volts(kw)
        for k in range(max(late, 0), len(xs) - n_ref, stride):
            factor = (volts[k : k + n_ref] / sf.V_REF) ** 2
            held = np.full(n_ref, (median_v / sf.V_REF) ** 2) if case.cause == "battery_sag" else factor
            models = ((commands[k - late : k - late + n_ref], truth, factor), (commands[k : k + n_ref], {}, held))
            for i, (u, eff, bat) in enumerate(models):
                sim = _body_states(_rollout(xs[k], u, 0, eff, bat, u[0].copy(), n_ref))
                errors[i].append(sim - measured[k + 1 : k + n_ref + 1])
    with_effect, without = (np.asarray(e) for e in errors)  # (window, step, state)
    mse = np.mean(without**2, axis=(0, 1))
    scale = np.empty(mse.size)
    for group in GROUPS:
        scale[list(group)] = np.sqrt(np.sum(mse[list(group)]))
    score = lambda e: np.mean(np.minimum((e / scale) ** 2, 1e6))  # noqa: E731
    gain = 1.0 - score(with_effect) / score(without)
    end = lambda e: np.mean(np.sum(e[:, -1, :3] ** 2, axis=-1))  # noqa: E731
    position = 1.0 - np.sqrt(end(with_effect) / end(without))
    return float(gain), float(position)


def _volts(kw) -> np.ndarray:
    """The battery voltage of a flight of keywords `kw`, sample by sample, as `quadrotor_flight` writes it."""
    n = int(round(kw["duration"] / 0.01)) + 1
    v0, v1 = kw.get("sag", (sf.V_REF, sf.V_REF))
    return v0 + (v1 - v0) * np.arange(n) / max(n - 1, 1)
