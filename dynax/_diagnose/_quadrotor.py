r"""The quadrotor's diagnosis: the rigid-body model on flight logs, the multirotor causes, the gain.

A `Quadrotor` is the `Helicopter`'s dynamics in world-velocity coordinates (`dynax.Quadrotor`), so
its diagnosis is `diagnose` on the body-frame form: the flights through `to_body_frame` (body
velocity $R^\top v$, inputs divided by `input_scale`) and the system `BodyFrameQuadrotor` (the
`Helicopter` of `Quadrotor.as_helicopter()` that keeps the quadrotor's input names `m1..m4, vbat`,
so that causes at the motors are named at them). Every step of the engine (the nominal refit, the
held-out simulation error against horizon, screening, the joint refit, the paired held-out test)
is the one every other system gets.

The vocabulary for a multirotor (`quadrotor_candidates`):

- `rotor_drag` on `u` ... `r` (`RotorDrag`): body-frame drag linear in velocity, $-d\,\nu_i$, and on
  `p, q, r` the rotors' damping of the body rates, $-d\,\omega_i$; and at `u+v` (`PlanarRotorDrag`) one
  coefficient on both axes of the rotor plane, as a vehicle symmetric in $x$ and $y$ has it: flown forwards
  and sideways alike, each horizontal axis alone shows only its part of the drag;
- `body_bias` on `u, v, w, p, q, r` (`BodyBias`): a constant body-frame force or moment (the
  centre of mass off the thrust centre, an IMU or motion-capture frame offset, a bent arm);
- `motor_delay` at `motors` (`MotorDelay`): one dead time between every motor's logged command and
  its thrust (the speed controller, the motors' spin-up, the logging chain's latency); the rotors'
  moments then answer the commands late, which a rigid body driven by the commands of the same sample
  cannot follow;
- `motor_lag` at `motors` (`MotorLag`): one first-order lag shared by every motor (identical motors and speed
  controllers spin up alike); told apart from `motor_delay` by the response's shape (look-alikes);
- `input_lag` per motor (`InputLag` at `m1..m4`): the motor's first-order lag behind its command;
- `battery_sag` at `vbat` (`BatterySag`, where the flights log `vbat`): thrust and moments per command that
  change with the battery voltage, which a motor map that does not read `vbat` misses;
- `ground_effect` at `z` (`GroundEffect`): thrust that rises near the floor, proposed only where the
  floor's height is given (`quadrotor_candidates(..., floor=z0)`; flight segments do not show where the
  floor is, and a floor guessed from the lowest height makes the term a thrust change at the lowest point
  of any flight, which on real flights crowds out the candidates that are there);
- `input_gain` per motor (`InputGain` at `m1..m4`): one motor's thrust per command off the others'.
  Tested against the held motor map; where the motor weights are refitted with it
  (`Refit(parameters=...)` naming them) the learned map carries any per-motor scale and the report
  lists it as not identifiable.

In `Refit()` mode (the default) the rigid body's weights are the one-step least-squares fit of the
given model's structure on the training flights (`fit_quadrotor`; `Quadrotor.from_flights("nominal")`
needs no starting values); `Known()` trusts the given weights (see `frame_quadrotor`).

Battery sag and ground effect change the thrust per command, and in a closed-loop flight the
command follows the thrust the vehicle needs: the one-step motor map fitted without them takes up
most of their effect (a map of $m_i^2, m_i$ bends to give the same thrust at the higher commands of
a low battery), so that, the map held, neither term adds anything and its true size even makes the
held-out error worse. They are tested with the thrust map refitted by simulation error with each
candidate, `Refit(parameters=thrust_parameters(quad))` (the CLI's `--refit thrust`): then the
term's coefficient is the physical one (the square law's 2 for a map that ignores `vbat`,
Cheeseman and Bennett's $R^2/16$) and its held-out gain is the effect's.
"""

from collections.abc import Callable, Sequence
import dataclasses
from typing import ClassVar, TYPE_CHECKING

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._data._flight import warn_if_units_differ
from .._data._motor_order import warn_if_numbered_otherwise
from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._model._extensions import AbstractTerm, InputGain, InputLag, MotorDelay, MotorLag
from .._model._extensions._vehicle_terms import BatterySag, BodyBias, GroundEffect, PlanarRotorDrag, RotorDrag
from .._model._helicopter import ANGULAR_RATE, BODY, Helicopter, QUATERNION, quaternion_to_rotation
from .._model._quadrotor import (
    motor_features,
    MOTORS,
    Quadrotor,
    QUADROTOR_INPUT_NAMES,
    QUADROTOR_STATE_NAMES,
    to_body_frame,
    WORLD_VELOCITY,
)
from .._model._system import AbstractSystem

if TYPE_CHECKING:
    from ._problem import Known, Refit
    from ._settings import Horizons

#: The reference horizons of a flight diagnosis [s]: 0.1 to 0.5 s, where flight models are scored.
QUADROTOR_HORIZONS_S = (0.1, 0.25, 0.5)
#: The steps at which a flight diagnosis scores its models per group (0.01, 0.1 and 0.5 s at 100 Hz).
FLIGHT_STEPS = (1, 10, 50)


class BodyFrameQuadrotor(Helicopter):
    """A `Quadrotor` in the helicopter's body-frame coordinates (`Quadrotor.as_helicopter()`), its
    inputs named as the quadrotor's (`m1..m4` and, when the flights have it, `vbat`), scaled by the
    quadrotor's `input_scale` (`to_body_frame` scales the records)."""

    inputs: tuple[str, ...] = eqx.field(static=True, default=QUADROTOR_INPUT_NAMES)
    # Its window score and refits weigh position, attitude, body velocity, rates alike (`flight_state_scale`).
    score_by_group: ClassVar[bool] = True

    @property
    def input_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.inputs


def body_frame_system(system: Quadrotor, inputs: Sequence[str] = QUADROTOR_INPUT_NAMES) -> BodyFrameQuadrotor:
    """The `BodyFrameQuadrotor` of `system` for flights with the inputs `inputs`."""
    return BodyFrameQuadrotor(system.body_model, system.normalisation_gain, tuple(inputs))


def as_quadrotor(body: BodyFrameQuadrotor, like: Quadrotor) -> Quadrotor:
    """The world-frame `Quadrotor` of a body-frame system's (refitted) body model, `like`'s input scales."""
    return like.with_body_model(body.body_model)


def quadrotor_candidates(system, floor: float | None = None) -> tuple:
    """The multirotor vocabulary at neutral values (see the module docs): `rotor_drag` on `u` ... `r` and `u+v`,
    `body_bias` on `u, v, w, p, q, r`, `battery_sag` where the system has `vbat`, `ground_effect` over a
    floor at height `floor` (world `z`) where one is given, `motor_delay` and `motor_lag` on all motors,
    `input_lag` and `input_gain` at each motor `m1..m4`."""
    terms: list[AbstractTerm] = [RotorDrag(i) for i in range(6)]
    terms.append(PlanarRotorDrag())  # u and v as one: the drag of the rotor plane
    terms += [BodyBias(i) for i in range(6)]
    if "vbat" in tuple(system.input_names):
        terms.append(BatterySag())
    if floor is not None:
        terms.append(GroundEffect(floor=float(floor)))
    terms.append(MotorDelay(tuple(range(len(MOTORS)))))
    terms.append(MotorLag(tuple(range(len(MOTORS)))))
    terms += [InputLag(i) for i in range(len(MOTORS))]
    terms += [InputGain(i) for i in range(len(MOTORS))]
    return tuple(terms)


def thrust_parameters(system: Quadrotor) -> tuple[str, ...]:
    """The names of the thrust axis' motor weights of `system`'s body model (`dw/` of the motor features):
    the nominal parameters to refit with battery sag and ground effect (`Refit(parameters=...)`)."""
    return _motor_weights(system, ("dw",), "thrust_parameters", "the thrust axis")


def moment_parameters(system: Quadrotor) -> tuple[str, ...]:
    """The names of the roll, pitch and yaw axes' motor weights of `system`'s body model (`dp/`, `dq/`, `dr/` of
    the motor features): the nominal parameters to refit with rate damping (`rotor_drag` at `p, q, r`). A moment
    map fitted one step at a time on commands that a closed loop sets takes up part of the vehicle's damping of
    its rates, as the thrust map takes up a battery's sag (`thrust_parameters`)."""
    return _motor_weights(system, ("dp", "dq", "dr"), "moment_parameters", "the roll, pitch and yaw axes")


def _motor_weights(system: Quadrotor, axes: tuple[str, ...], caller: str, where: str) -> tuple[str, ...]:
    """The body model's weights of the motor features (with or without `vbat`) on `axes`, in its order."""
    features = {name for battery in (False, True) for name in motor_features(battery)}
    motors = {f"{axis}/{name}" for axis in axes for name in features}
    names = tuple(n for n in system.body_model.parameter_names if n in motors)
    if not names:
        raise UsageError(f"{caller}: {type(system.body_model).__name__} has no motor weights on {where}")
    return names


def quadrotor_refit_names(system: Quadrotor, text: str | None) -> tuple[str, ...] | None:
    """The command line's `--refit` for a quadrotor: comma-separated parameter names, where `thrust` stands for
    `thrust_parameters` and `moments` for `moment_parameters`; `None` where nothing is given."""
    if not text:
        return None
    groups = {"thrust": thrust_parameters, "moments": moment_parameters}
    names: list[str] = []
    for item in (n.strip() for n in text.split(",")):
        if item:
            names += groups[item](system) if item in groups else [item]
    return tuple(dict.fromkeys(names)) or None


def _as_list(flights, where: str) -> list[Trajectory]:
    if flights is None:
        return []
    if isinstance(flights, Trajectory):
        return [flights]
    flights = list(flights)
    if not all(isinstance(f, Trajectory) for f in flights):
        raise UsageError(
            f"diagnose: `{where}` must be quadrotor Trajectories (dynax.load_flight, dynax.usable_segments)"
        )
    return flights


def prepare_quadrotor(system: Quadrotor, train, validation, *, refit: bool) -> tuple:
    """The body-frame system and records of a quadrotor diagnosis, the nominal `Quadrotor` and its fit: with
    `refit`, the one-step least-squares fit of `system`'s body model on `train` (`fit_quadrotor`; its
    `Solution`, else `None`)."""
    from .._identify._vehicle._quadrotor import join_flights

    train = _as_list(train, "train")
    held = _as_list(validation, "validation") if validation is not None else None
    if not train:
        raise UsageError("diagnose: no training flights given")
    join_flights(system, train + (held or []))  # one interval, one set of inputs, vbat where the model reads it
    one_step = None
    if refit:
        one_step = _quiet_fit(system, train)
        system = one_step.model
    elif not np.any(np.asarray(system.body_model.weights)):
        raise UsageError(
            "diagnose: Known() trusts the quadrotor's weights, but they are all zero; fit it first "
            "(dynax.fit_quadrotor) or diagnose in Refit() mode"
        )
    inputs = tuple(train[0].input_names)
    body = body_frame_system(system, inputs)
    as_body = lambda flights: [to_body_frame(system, f) for f in flights]  # noqa: E731
    return body, as_body(train), (None if held is None else as_body(held)), system, one_step


@dataclasses.dataclass(frozen=True)
class BodyFrameDiagnosis:
    """What `diagnose` runs its engine on for a `Quadrotor` (`frame_quadrotor`): the body-frame system,
    records, candidates, mode and horizons, and how the held map is refitted through input dynamics
    (`through`: the problem's nominal names -> `Problem.nominal_through`, or `None`); the nominal `quadrotor`
    and the `held_out` flights as logged (world frame); `finish` names the report's system and mode as the
    user asked and scores the held-out flights per group (`score_flights`)."""

    system: AbstractSystem
    train: list
    validation: list
    candidates: tuple
    mode: "Refit | Known"
    horizons: "Horizons"
    through: Callable[[tuple], Callable[[tuple], tuple]] | None
    refit: bool
    refit_parameters: bool
    quadrotor: Quadrotor
    held_out: list

    def finish(self, report, say=lambda _: None):
        report = dataclasses.replace(report, system="quadrotor", mode="refit" if self.refit else report.mode)
        if self.refit:
            report.notes.append(self._refit_note())
        return score_flights(report, self.quadrotor, self.held_out, say=say)

    def _refit_note(self) -> str:
        return "The rigid body's weights are the one-step least-squares fit on the training flights" + (
            ", the named ones refitted by simulation error with each candidate."
            if self.refit_parameters
            else ", held while each candidate's coefficient is fitted by simulation error (for a motor lag or "
            "dead time, the one-step fit through it at its one-step optimum)."
        )


def frame_quadrotor(system: Quadrotor, train, validation, candidates, mode, horizons, selection) -> BodyFrameDiagnosis:
    """`diagnose`'s arguments for a `Quadrotor` in the body frame (see the module docs): `diagnose` then runs its
    own steps on them. Without `horizons.horizons_s` the error is reported at `QUADROTOR_HORIZONS_S`.

    `Refit()` (all parameters): the rigid body's weights are the one-step least-squares fit on the training
    flights and are held while the candidates' coefficients are fitted by simulation error (a simulation-error
    refit of the dozens of collinear motor weights with every candidate neither converges nor tells more);
    `Refit(parameters=names)`: those weights are also refitted by simulation error, from the one-step fit;
    `Known()`: `system`'s weights are trusted as given.
    """
    from ._problem import Known, Refit

    refit = isinstance(mode, Refit)
    given = _as_list(train, "train") + ([] if validation is None else _as_list(validation, "validation"))
    warn_if_numbered_otherwise(given, stacklevel=4)  # `diagnose`'s caller
    warn_if_units_differ(given, stacklevel=4)
    if validation is None:  # the held-out tail of each flight stays out of the one-step fit too
        from ._records import holdout_split

        halves = [holdout_split(f, selection.holdout_fraction) for f in _as_list(train, "train")]
        train, validation = [a for a, _ in halves], [b for _, b in halves]
    body, train_b, val_b, nominal, one_step = prepare_quadrotor(system, train, validation, refit=refit)
    if horizons.horizons_s is None:
        horizons = dataclasses.replace(horizons, horizons_s=QUADROTOR_HORIZONS_S)
    held_map = refit and mode.parameters is None
    through = None
    if held_map:  # the held map: a one-step fit, redone through input dynamics
        flights = _as_list(train, "train")
        through = lambda names: _one_step_through(system, body, flights, names, one_step)  # noqa: E731
    return BodyFrameDiagnosis(
        system=body,
        train=train_b,
        validation=val_b,
        candidates=quadrotor_candidates(body) if candidates is None else candidates,
        mode=mode if (refit and mode.parameters is not None) else Known(),
        horizons=horizons,
        through=through,
        refit=refit,
        refit_parameters=refit and mode.parameters is not None,
        quadrotor=nominal,
        held_out=_as_list(validation, "validation"),
    )


def _quiet_fit(system, flights):
    """The one-step fit of `system` on `flights` without `identify`'s data warnings: `diagnose` says what it finds
    in the records once (`warn_data_faults`), and these fits read the same records (or their commands passed through
    a candidate's input dynamics)."""
    from .._identify._method import FitSettings
    from .._identify._vehicle import OneStep
    from .._identify._vehicle._fit import fit_all

    return fit_all(system, flights, OneStep(), FitSettings(progress=False), warn_data=False)


def _one_step_through(
    system: Quadrotor, body, train: list[Trajectory], names, fitted=None
) -> Callable[[tuple], tuple[np.ndarray, float, int]]:
    """`Problem.nominal_through` of a quadrotor diagnosis in `Refit()` mode: the one-step least-squares fit of
    `system`'s body model (`fit_quadrotor`) on the `train`ing flights with their commands as given input terms
    pass them on (`applied_inputs`: a motor's lag, a dead time): `(nominal values names, one-step loss, the number of
    one-step residuals)`. `fitted`: the fit through no term, where it is already made (`prepare_quadrotor`'s)."""
    from ._fit import nominal_values
    from ._residuals import applied_inputs

    inputs = tuple(train[0].input_names)
    n_residuals = 6 * sum(len(f) - 1 for f in train)  # one-step predictions of the six body velocities
    made: dict[tuple, tuple[np.ndarray, float, int]] = {}

    def outcome(solution) -> tuple[np.ndarray, float, int]:
        values = np.asarray(nominal_values(body_frame_system(solution.model, inputs), names))
        return values, float(solution.loss), n_residuals

    if fitted is not None:
        made[()] = outcome(fitted)

    def through(terms: tuple) -> tuple[np.ndarray, float, int]:
        key = tuple((type(t).__name__, t.inputs, round(float(t.coefficient), 9)) for t in terms)
        if key not in made:  # each fit once per diagnosis: every round asks for the same ones
            flights = (
                [
                    Trajectory(
                        f.ts, f.xs, applied_inputs(body, terms, f), f.state_names, f.input_names, f.system, f.source
                    )
                    for f in train
                ]
                if terms
                else train
            )
            made[key] = outcome(_quiet_fit(system, flights))
        return made[key]

    return through


class WorldFrameQuadrotor(AbstractSystem):
    r"""A body-frame system (`BodyFrameQuadrotor`, or it `Extended` with vehicle terms) on the quadrotor's
    world-frame states and logged inputs: what `dynax.flight_error` and `dynax.predict_ahead` score.

    With body velocity $\nu = R^\top v$ and the body system's $(\dot\nu, \dot\omega)$ at the scaled
    inputs, $\dot v = R(\dot\nu + \omega\times\nu)$ (as `Quadrotor.vector_field`). Only systems
    without internal states (no input lag or delay) have this form.

    **Fields:** `body` (the body-frame system), `input_scale` (the quadrotor's, static).
    """

    body: AbstractSystem
    input_scale: tuple[float, ...] = eqx.field(static=True)

    state_names: ClassVar[tuple[str, ...]] = QUADROTOR_STATE_NAMES
    input_names: ClassVar[tuple[str, ...]] = QUADROTOR_INPUT_NAMES

    def __check_init__(self):
        if self.body.n_states != len(QUADROTOR_STATE_NAMES):
            raise UsageError(
                f"WorldFrameQuadrotor: the body system has {self.body.n_states} states (internal "
                "states of an input lag or delay); only a 13-state body model has a world-frame form"
            )

    def state_error(self, simulated, measured):
        quat = simulated[..., QUATERNION]
        sign = jnp.where(jnp.sum(quat * measured[..., QUATERNION], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        return simulated.at[..., QUATERNION].set(sign * quat) - measured

    def vector_field(self, t, x, u):
        rotation = quaternion_to_rotation(x[QUATERNION])
        nu, omega = rotation.T @ x[WORLD_VELOCITY], x[ANGULAR_RATE]
        scaled = u / jnp.asarray(self.input_scale[: u.shape[-1]], u.dtype)
        d = self.body.vector_field(t, x.at[WORLD_VELOCITY].set(nu), scaled)
        dvel = rotation @ (d[BODY][:3] + jnp.cross(omega, nu))
        return jnp.concatenate([x[WORLD_VELOCITY], d[QUATERNION], dvel, d[BODY][3:]])


def quadrotor_flight_errors(report, like: Quadrotor, flights, steps=FLIGHT_STEPS) -> dict:
    """The held-out scores per group (`dynax.flight_error`) of the report's nominal and extended models
    and the constant-velocity baseline: `{name: SimulationError}`; the extended model only where it has a
    world-frame form (`WorldFrameQuadrotor`: no internal states; a dead time on the commands is scored as the
    commands shifted by it)."""
    from .._model._extensions import Extended
    from .._model._quadrotor import ConstantVelocity
    from .._simulate import flight_error

    flights = _as_list(flights, "flights")
    out = {"constant velocity": flight_error(ConstantVelocity(), flights, steps)}
    for name, model in (("nominal", report.nominal_model), ("extended", report.extended_model)):
        if model is None:
            continue
        if (  # nothing added (no finding): the nominal model's scores, not scored twice
            name == "extended"
            and "nominal" in out
            and isinstance(model, Extended)
            and not model.terms
            and eqx.tree_equal(model.system, report.nominal_model) is True
        ):
            out[name] = out["nominal"]
            continue
        model, scored = _dead_times_as_shifted_commands(model, flights)
        if model.n_states != len(QUADROTOR_STATE_NAMES):
            continue
        out[name] = flight_error(WorldFrameQuadrotor(model, like.input_scale), scored, steps)
    return out


def short_horizon_note(errors: dict, causes: Sequence[str] = ()) -> str | None:
    r"""A note where the extended model predicts some group worse than the nominal model one step ahead.

    `errors` is `quadrotor_flight_errors`'s `{name: SimulationError}`; `causes` the named causes' labels.
    `diagnose` gives it for every quadrotor (`score_flights`: why it stays a note).
    A physical effect of a term's form acts at every time scale, so its extended model should predict
    the next sample at least as well as the nominal one. A term refitted to the long-horizon error can
    instead stand in for motion the vocabulary lacks (on a closed-loop vehicle, a rate damping of hundreds
    of 1/s can take the place of the rate controller acting between the logged commands): it gains
    over the reference horizon and makes the next sample's prediction worse. The note is given where
    some group's MAE at the first step grows by the inverse of the smallest gain that matters, a factor
    $1/(1 - $`MIN_PRACTICAL_GAIN`$)$ = 4/3, and by at least `MIN_PRACTICAL_GAIN` of the constant-velocity
    baseline's MAE there (where `errors` has it: on noise-free data a ratio of two tiny errors is no loss),
    and says which group and by how much. `None` otherwise.
    """
    from ._verdict import MIN_PRACTICAL_GAIN

    nominal, extended = errors.get("nominal"), errors.get("extended")
    if nominal is None or extended is None or nominal.mae_per_state is None or extended.mae_per_state is None:
        return None
    from .._simulate import FLIGHT_UNITS

    baseline = errors.get("constant velocity")
    worse = []
    for j, group in enumerate(nominal.state_names):
        a, b = float(nominal.mae_per_state[0, j]), float(extended.mae_per_state[0, j])
        # and on the scale of holding the state: a billionth of a metre against a thousandth is no practical loss
        scale = (
            float(baseline.mae_per_state[0, j]) if baseline is not None and baseline.mae_per_state is not None else 0
        )
        if (
            np.isfinite(a)
            and a > 0
            and not b * (1.0 - MIN_PRACTICAL_GAIN) < a
            and not b - a < MIN_PRACTICAL_GAIN * scale
        ):
            worse.append(f"{group} {b:.3g} against {a:.3g} {FLIGHT_UNITS[group]} ({b / a:.1f}x)")
    if not worse:
        return None
    named = ", ".join(causes) if causes else "the discovered terms"
    return (
        f"One step ahead ({nominal.horizons_s[0]:g} s) the extended model predicts worse than the nominal model: "
        f"{'; '.join(worse)}. A physical effect of the form of {named} would act at every time scale; these gain over "
        "the reference horizon at the cost of the next sample, so they stand in for motion the candidates do not "
        "model (on a closed-loop vehicle, for example the rate controller acting between the logged commands) "
        "rather than measure the named causes."
    )


def score_flights(report, like: Quadrotor, flights, steps=FLIGHT_STEPS, say=lambda _: None):
    r"""`report` with its held-out flights scored per group (`Report.flight_error`, a `FlightScores`: the nominal
    and extended models and constant velocity, `quadrotor_flight_errors` at `steps`) and, where the extended model
    predicts some group much worse one step ahead, `short_horizon_note` added to its notes. Flights too short for
    the longest step are left out; `report` as it is where none is long enough.

    **Why a note and not a rule of the selection.** The forward selection does not act on it:

    - it can be read only for an extended model with a world-frame form (`WorldFrameQuadrotor`): a motor lag has
      internal states and is never scored, so a rule on it would judge some candidates and not others;
    - it is read after the selection, on the held-out flights the paired test has already used: a second
      criterion on them is outside the test's level;
    - the gain the term buys at the reference horizon is real on those flights (on the NanoBench slices of
      `experiments/nanobench_diagnosis.py`, `rotor_drag@q` and `@p` halve the 0.5 s attitude and body-rate
      error); what the note questions is what the coefficient means, not whether the model predicts better
      where it is judged;
    - the hidden-effect flights cannot show that stopping such a term helps: there the named physical terms
      (rotor drag, body bias; `tests/quadrotor/test_diagnosis.py`, the CLI's rotor drag) leave no note, the motor
      lag cannot have one and the effect-free flights name nothing, so a stopping rule would change none of them.
      Of the diagnoses run here it would change only NanoBench's, where it would drop both findings.
    """
    flights = [f for f in _as_list(flights, "flights") if len(f) > max(steps)]
    if not flights:
        return report
    from ._result import FlightScores

    say(f"scoring the held-out flights per group, {', '.join(map(str, steps))} steps ahead from every start ...")
    errors = quadrotor_flight_errors(report, like, flights, steps)
    note = short_horizon_note(errors, [f"{f['cause']}@{f['where']}" for f in report.findings])
    notes = report.notes if note is None else [*report.notes, note]
    return dataclasses.replace(report, flight_error=FlightScores(errors, note), notes=notes)


def _dead_times_as_shifted_commands(model, flights) -> tuple:
    """A model whose only internal states are dead times (`motor_delay`, `input_delay`) as the model without
    them on the flights with those commands shifted by the delay (`exact_delays`: what acts over each sample
    interval); any other model and the flights as they are."""
    from .._model._extensions import AbstractInputTerm, Extended
    from ._residuals import DEAD_TIMES, exact_delays

    if not isinstance(model, Extended):
        return model, flights
    hidden = [t for t in model.input_terms if t.hidden_names(model.system)]
    if not hidden or not all(t.cause in DEAD_TIMES for t in hidden):
        return model, flights
    shifted = []
    for f in flights:
        _, us, _ = exact_delays(model, f, interval=True)
        shifted.append(Trajectory(f.ts, f.xs, us, f.state_names, f.input_names, f.system, f.source))
    kept = tuple(t for t in model.terms if not (isinstance(t, AbstractInputTerm) and t.cause in DEAD_TIMES))
    return (eqx.tree_at(lambda m: m.terms, model, kept) if kept else model.system), shifted


def body_frame_records(system: Quadrotor, flights) -> list[Trajectory]:
    """The flights in the body-frame coordinates a quadrotor diagnosis works in (`to_body_frame`): what
    `write_report` draws the held-out figures of."""
    return [to_body_frame(system, f) for f in _as_list(flights, "flights")]
