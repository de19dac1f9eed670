"""The candidate library and its structural identifiability in the diagnosis mode used."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._model._extensions import (
    AbstractInputTerm,
    AbstractTerm,
    CoulombFriction,
    InputDelay,
    InputGain,
    InputLag,
    InputOffset,
    MotorDelay,
    MotorLag,
    QuadraticDrag,
    RotorInertia,
    Stiction,
    ViscousFriction,
)
from .._model._extensions._stiction import stick_band
from .._model._extensions._vehicle_terms import AbstractVehicleTerm, BodyBias, BodyQuadraticDrag, Wind
from .._model._helicopter import BODY
from ._at_rest import LOAD_FRACTION, MIN_LOADED_REST_S, MIN_REST_S, rests_under_load
from ._fit import nominal_parameters, nominal_values
from ._residuals import input_dynamics


def host_nominal_values(system, names: tuple[str, ...]) -> np.ndarray:
    """`nominal_values(system, names)` read on the host: the same numbers (a gather of each leaf's entries), without
    the eager gathers and concatenation that `nominal_values` runs (each dispatched as a JAX operation, about 50 ms
    a call that a diagnosis makes a dozen times)."""
    parameters = nominal_parameters(system)
    if tuple(names) != parameters.names:
        raise ValueError(
            f"nominal_values: {names} are not the parameters {parameters.names} of {type(system).__name__}"
        )
    leaves = jax.tree.leaves(system)
    parts = [np.ravel(np.asarray(leaf))[list(idx)] for leaf, idx in zip(leaves, parameters.selection) if idx]
    return np.concatenate(parts) if parts else np.zeros(0)


# Groups of causes that look alike in data; the report says how well each finding is told apart.
LOOK_ALIKES = (
    frozenset({"coulomb_friction", "viscous_friction", "quadratic_drag"}),
    frozenset({"input_delay", "input_lag"}),
    frozenset({"motor_delay", "motor_lag"}),  # at `motors`: the shared dead time and the shared lag
    frozenset({"wind", "body_bias"}),
    frozenset({"rotor_drag", "quadratic_drag"}),
    # A static level holds at rest where a Coulomb friction creeps; an offset acts at rest and in motion alike.
    frozenset({"stiction", "coulomb_friction"}),
    frozenset({"stiction", "input_offset"}),
)


def coulomb_velocity_scale(system, joint: int, trajectories) -> float:
    """The smoothing speed of a Coulomb friction candidate: 5 % of the joint's RMS speed in the data.

    Below that speed the sign of a measured velocity is not trustworthy anyway, and a sharper
    switch makes the friction force stiff: with `tanh(dq / v_s)` its slope is `fc / v_s`, and at
    0.01 rad/s a few tenths of a newton metre on a light link put the fixed-step integrators that
    fit and judge the candidates past their stability limit at a 5 ms step (the simulation then
    chatters at every velocity reversal, and the candidate loses on held-out data for numerical
    reasons, not physical ones).
    """
    n = system.n_joints
    dq = np.concatenate([np.asarray(t.xs)[:, n + joint] for t in trajectories])
    return max(0.05 * float(np.sqrt(np.mean(dq**2))), 1e-3)


def stiction_candidate(system, rest, dt: float) -> Stiction:
    """The `Stiction` candidate at a joint with rests under load (`rest`, a `JointRests`), its settings from the
    data: the band of speeds in which it sticks from the velocity noise at rest (`stick_band` of `speed_noise`, as
    `identify` chooses it); its hold time two samples (the diagnosis's fixed-step rollouts take one step per
    sample)."""
    return Stiction(rest.joint, velocity_scale=stick_band(rest.speed_noise), hold_time=max(2.0 * dt, 0.01))


def default_candidates(system, trajectories=None) -> tuple[AbstractTerm, ...]:
    """The contract's vocabulary for `system`, at neutral values.

    With `trajectories` (the training runs), each Coulomb friction candidate's smoothing speed is
    set from the data (`coulomb_velocity_scale`), and a `stiction` candidate is proposed at each joint
    that the records show at rest under a net torque (`dynax.internal.rests_under_load`); without, the
    Coulomb smoothing is `CoulombFriction`'s default and no stiction is proposed.

    For a manipulator, per coordinate: `coulomb_friction`, `viscous_friction`, `quadratic_drag`,
    `rotor_inertia` (and `stiction` where it rests under load); for a `Helicopter`, `quadratic_drag` on each
    translational body axis (`u, v, w`), `wind` (its north, east and down components, each a candidate at
    `world`) and `body_bias` on each body axis (`u, v, w, p, q, r`); for every system, per input:
    `input_delay`, `input_lag`, `input_gain`, `input_offset`; for a manipulator with more than one input,
    `motor_delay` and `motor_lag` at `motors` (one dead time, one lag on every input: drives commanded through
    one chain, as a rig's bus or controller, share its latency).
    """
    terms: list[AbstractTerm] = []
    if system.joints:
        rests = rests_under_load(system, trajectories) if trajectories is not None else ()
        dt = float(np.median(np.diff(np.asarray(trajectories[0].ts, dtype=float)))) if trajectories else 0.01
        for j in system.joints:
            coulomb = (
                CoulombFriction(j)
                if trajectories is None
                else CoulombFriction(j, velocity_scale=coulomb_velocity_scale(system, j, trajectories))
            )
            terms += [coulomb, ViscousFriction(j), QuadraticDrag(j), RotorInertia(j)]
            if rests and rests[j].loaded and not builtin_friction(system):
                terms.append(stiction_candidate(system, rests[j], dt))
    if system.body_axes:
        terms += [BodyQuadraticDrag(i) for i in range(3)]
        terms += [Wind(i) for i in range(3)]
        terms += [BodyBias(i) for i in range(6)]
    for i in range(system.n_inputs):
        terms += [InputDelay(i), InputLag(i), InputGain(i), InputOffset(i)]
    if system.joints and system.n_inputs > 1:  # drives commanded through one chain share its latency and lag
        every = tuple(range(system.n_inputs))
        terms += [MotorDelay(every), MotorLag(every)]
    return tuple(terms)


def builtin_friction(system) -> bool:
    """Whether `system` carries its Coulomb friction as a parameter of its own (`LinearAxis`) rather than as a
    `CoulombFriction` term, which `Stiction` composes with (its slip excess and its hold are measured from the
    joint's friction terms)."""
    return getattr(system, "coulomb", None) is not None


def stiction_not_proposed(system, trajectories) -> list[dict]:
    """Where the default vocabulary leaves `stiction` out, and why: `{cause, where, reason}` per joint without a
    rest under load in `trajectories`, or of a system whose Coulomb friction is its own parameter (see
    `default_candidates`)."""
    out = []
    for rest in rests_under_load(system, trajectories):
        if rest.loaded and builtin_friction(system):
            why = (
                f"the joint rests under load for {rest.rest_s:.3g} s, but {type(system).__name__}'s Coulomb friction "
                "is a parameter of the system, which a static friction level does not compose with yet"
            )
            out.append({"cause": "stiction", "where": rest.coordinate, "reason": why})
            continue
        if rest.loaded:
            continue
        if rest.all_rest_s > 0:
            why = (
                f"the joint rests for {rest.all_rest_s:.3g} s in the training records, but under no net torque of "
                f"practical size for {MIN_LOADED_REST_S:g} s or more ({rest.rest_s:.2g} s where the nominal model "
                f"needs {LOAD_FRACTION:.0%} of the joint's RMS force, {rest.force_scale:.3g}, or more to hold it), "
                "so a static friction level has nothing to hold"
            )
        else:
            why = (
                f"the joint never rests (position still for {MIN_REST_S:g} s or more) in the training records; "
                "a static friction level shows only at rest under load"
            )
        out.append({"cause": "stiction", "where": rest.coordinate, "reason": why})
    return out


def look_alikes(system, term, candidates) -> list[int]:
    """Indices of the candidates that look like `term` in data: same place, cause in the same group.

    A wind (at `world`) and a body bias on a translational axis (`u`, `v`, `w`) look alike
    whatever their places: at a constant attitude a steady wind is a constant force on the body axes. A stiction
    at a joint and an offset on an input that drives it look alike too: both carry a constant torque at rest.
    """
    where = term.where(system)

    def same_place(other):
        if {term.cause, other.cause} == {"wind", "body_bias"}:
            bias = term if term.cause == "body_bias" else other
            return bias.axis < 3
        if {term.cause, other.cause} == {"stiction", "input_offset"}:
            # An offset on an input that drives the joint (a constant torque error there).
            static, offset = (term, other) if term.cause == "stiction" else (other, term)
            return bool(np.asarray(system.input_matrix())[static.joint, offset.input] != 0)
        return other.where(system) == where

    return [
        k
        for k, other in enumerate(candidates)
        if other.cause != term.cause
        and same_place(other)
        and any(term.cause in group and other.cause in group for group in LOOK_ALIKES)
    ]


def structurally_absorbed(
    family, refit, *, n_points: int = 64, seed: int = 0, tol: float = 1e-7, sensitivities=None
) -> np.ndarray:
    r"""For each candidate of `family`, whether refitting the nominal parameters reproduces it exactly.

    The test is structural, not about a data set: at random states and inputs, the derivative of
    the vector field with respect to a candidate's coefficient (at its neutral value) is projected
    on the derivatives with respect to the refitted nominal parameters (`refit`, a 0/1 mask); if
    nothing is left, a change of the coefficient is a change of nominal parameters, and the cause
    cannot be identified in this mode (an input gain on the acrobot is a rescaling of
    theta1..theta7; a viscous friction on a model that fits its own viscous coefficients is that
    coefficient). Terms with internal states (lag, delay) change the dynamics' order and are never
    absorbed.

    `sensitivities`: `sampled_sensitivities(family, n_points, seed)` when already computed (the
    three structural tests of a diagnosis share them).

    **Returns:** a bool per candidate.

    ??? cite

        E. Walter and L. Pronzato, *Identification of Parametric Models from Experimental Data*,
        Springer 1997, ch. 2 (structural identifiability; local rank test of the sensitivity matrix).
    """
    refit = np.asarray(refit) > 0
    J_nom, J_c = sensitivities or sampled_sensitivities(family, n_points, seed)
    A = J_nom[:, refit]
    out = []
    for k, term in enumerate(family.model.terms):
        b = J_c[:, k]
        if input_dynamics(term, family.model.system):
            out.append(False)
        elif np.linalg.norm(b) == 0:
            out.append(True)
        else:
            out.append(_in_span(A, b, _structural_tol(tol)))
    return np.asarray(out)


def _in_span(basis, b, tol) -> bool:
    """Whether `b` is a linear combination of `basis`'s columns, to `tol` relative to its norm."""
    if basis.shape[1] == 0 or not (np.all(np.isfinite(basis)) and np.all(np.isfinite(b))):
        return False  # no structure read through a non-finite derivative (`sampled_sensitivities` warns)
    coef, *_ = np.linalg.lstsq(basis, b, rcond=None)
    return bool(np.linalg.norm(b - basis @ coef) <= tol * np.linalg.norm(b))


def structurally_equivalent(
    family, refit, among, *, n_points: int = 64, seed: int = 0, tol: float = 1e-7, sensitivities=None
) -> dict[int, list[int]]:
    r"""Pairs of candidates that are one model once the nominal parameters are refitted.

    Candidate $k$ is equivalent to candidate $l$ when the derivative of the vector field with
    respect to $k$'s coefficient lies in the span of the derivatives with respect to the refitted
    nominal parameters (`refit`, a 0/1 mask) and $l$'s coefficient, and the other way round (at
    random states and inputs, as in `structurally_absorbed`). A gain on one motor's torque of the
    double pendulum is then a gain on the other's: scaling every torque-side parameter and both
    gains by one factor leaves the motion unchanged, so a refit determines only their ratio. Data
    cannot tell such a pair apart, so each is the other's look-alike. Only candidates in `among` (not
    absorbed alone) and without internal states are compared.

    **Returns:** `{k: [l, ...]}` for the candidates that have an equivalent.
    """
    refit = np.asarray(refit) > 0
    J_nom, J_c = sensitivities or sampled_sensitivities(family, n_points, seed)
    A = J_nom[:, refit]
    terms = family.model.terms
    ks = [k for k in among if not input_dynamics(terms[k], family.model.system)]

    def in_span(k, *others):
        return _in_span(np.concatenate([A, J_c[:, list(others)]], axis=1), J_c[:, k], _structural_tol(tol))

    ks = [k for k in ks if not in_span(k)]  # one the refit reproduces alone is absorbed, not equivalent
    out: dict[int, list[int]] = {}
    for i, k in enumerate(ks):
        for l in ks[i + 1 :]:
            if np.linalg.norm(J_c[:, k]) and np.linalg.norm(J_c[:, l]) and in_span(k, l) and in_span(l, k):
                out.setdefault(k, []).append(l)
                out.setdefault(l, []).append(k)
    return out


def held_partners(
    family, held, *, n_points: int = 64, seed: int = 0, tol: float = 1e-7, sensitivities=None
) -> list[tuple[int, float] | None]:
    r"""For each candidate of `family`, the nominal parameter it adds to among those `held` (not refitted), if any.

    A candidate adds to nominal parameter $i$ when the derivative of the vector field with
    respect to its coefficient is $\alpha$ times the derivative with respect to $\theta_i$ (at
    random states and inputs, as in `structurally_absorbed`): a viscous friction candidate at a
    joint adds to the nominal model's own viscous coefficient there. The two are then one physical
    coefficient, $\theta_i + \alpha c$, and its consistency bound (`base_parameter_kinds`) is the
    candidate's: a candidate may lower a held viscous coefficient, not below zero.

    **Returns:** per candidate `(i, alpha)` or `None`.
    """
    J_nom, J_c = sensitivities or sampled_sensitivities(family, n_points, seed)
    out: list[tuple[int, float] | None] = []
    for k in range(J_c.shape[1]):
        b, partner = J_c[:, k], None
        for i in np.flatnonzero(np.asarray(held) > 0):
            a = J_nom[:, i]
            if np.linalg.norm(a) == 0 or np.linalg.norm(b) == 0:
                continue
            alpha = float(a @ b / (a @ a))
            if np.linalg.norm(b - alpha * a) <= _structural_tol(tol) * np.linalg.norm(b):
                partner = (int(i), alpha)
                break
        out.append(partner)
    return out


def sampled_sensitivities(family, n_points: int = 64, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of the vector field with respect to the nominal parameters and the candidates'
    coefficients (at neutral), stacked over random states and inputs: `(rows, n_nominal)`, `(rows, n_candidates)`."""
    system = family.model.system
    rng = np.random.default_rng(seed)
    n_x, n_u = system.n_states, system.n_inputs
    xs = rng.uniform(-1.0, 1.0, (n_points, n_x)) * np.where(np.arange(n_x) < n_x // 2, 2.0, 3.0)
    us = rng.normal(0.0, 1.0, (n_points, n_u))
    values = jnp.asarray(nominal_values(system, family.names), float)
    J_nom, J_c = _sensitivities(family, values, family.neutral, jnp.asarray(xs), jnp.asarray(us))
    J_nom = np.asarray(J_nom, dtype=np.float64).reshape(-1, len(family.names))  # host least squares in float64
    J_c = np.asarray(J_c, dtype=np.float64).reshape(-1, len(family.model.terms))
    for J, of in ((J_nom, family.names), (J_c, [t.label(system) for t in family.model.terms])):
        bad = np.flatnonzero(~np.all(np.isfinite(J), axis=0))
        if bad.size:
            warnings.warn(
                f"dynax: the derivative of the vector field with respect to {', '.join(of[i] for i in bad)} is not "
                f"finite at sampled states and inputs ({jnp.zeros(()).dtype}); the structural tests read no "
                "structure through them (no candidate is set aside as absorbed or equivalent on their account)",
                RuntimeWarning,
                stacklevel=2,
            )
    return J_nom, J_c


def _structural_tol(tol: float) -> float:
    """`tol`, or 100 times the machine epsilon of JAX's float where that is larger: derivatives computed in float32
    (JAX's float64 mode off) carry relative rounding of some 1e-7, which a test at 1e-7 would read as structure."""
    return max(tol, 100 * float(jnp.finfo(jnp.zeros(()).dtype).eps))


@eqx.filter_jit
def _sensitivities(family, values, coefficients, xs, us):
    n = family.model.system.n_states

    def field(v, c, x, u):
        model = family.build(v, c)
        return model.vector_field(0.0, model.initial_state(x, u), u)[:n]

    jac = jax.jacfwd(field, argnums=(0, 1))
    return jax.vmap(lambda x, u: jac(values, coefficients, x, u))(xs, us)


def candidate_scales(system, candidates, trajectories) -> tuple[np.ndarray, np.ndarray]:
    """Typical size and start value of each candidate's coefficient, from the data's spread.

    A friction or drag term of typical size produces a tenth of the RMS input force; inertia a
    tenth of the nominal diagonal inertia; delays and lags start at two sample intervals (a
    zero delay has no gradient). On a helicopter, a body bias or a quadratic drag of typical size
    is a tenth of the spread of the body-axis accelerations, a wind 1 m/s. A stiction starts at the largest
    force the records show held at rest (`rests_under_load`).
    """
    xs = np.concatenate([np.asarray(t.xs) for t in trajectories])
    us = np.concatenate([np.asarray(t.us) for t in trajectories])
    dt = float(np.median(np.concatenate([np.diff(np.asarray(t.ts)) for t in trajectories])))
    force = max(float(np.sqrt(np.mean(us**2))), 1e-6)
    scales, inits = [], []
    rests = rests_under_load(system, trajectories) if any(t.cause == "stiction" for t in candidates) else ()
    for term in candidates:
        init = term.neutral
        if isinstance(term, AbstractInputTerm):
            rms_u = max(float(np.sqrt(np.mean(us[:, term.input] ** 2))), 1e-6)
            if input_dynamics(term, system):
                scale = init = 2.0 * dt
            elif term.cause == "input_gain":
                scale = 0.1
            else:
                scale = 0.1 * rms_u
        elif isinstance(term, AbstractVehicleTerm):
            body = xs[:, BODY.start : BODY.stop]
            accel = np.gradient(body, dt, axis=0).std(axis=0)
            size = max(0.1 * float(accel[term.axis]), 1e-3)
            if term.cause == "quadratic_drag":
                scale = size / max(float(np.mean(body[:, term.axis] ** 2)), 1e-2)
            elif term.cause == "rotor_drag":
                scale = size / max(float(np.sqrt(np.mean(body[:, term.axis] ** 2))), 1e-1)
            elif term.cause == "wind":
                scale = 1.0
            else:
                scale = size
        else:
            j, n = term.joint, system.n_joints
            rms_q = max(float(np.sqrt(np.mean(xs[:, j] ** 2))), 1e-6)
            rms_dq = max(float(np.sqrt(np.mean(xs[:, n + j] ** 2))), 1e-6)
            if term.cause == "stiction" and rests:
                # A data-based start: the static level is at least the largest force held at rest (at zero the
                # level's derivative is a tie of the clipping, half what it is above zero).
                init = max(rests[j].held, 1e-3 * force)
            scale = {
                "coulomb_friction": 0.1 * force,
                "stiction": 0.1 * force,
                "viscous_friction": 0.1 * force / rms_dq,
                "quadratic_drag": 0.1 * force / rms_dq**2,
                "rotor_inertia": 0.1 * float(system.mass_matrix(jnp.zeros(n))[j, j]),
            }.get(term.cause, 0.1 * force / rms_q)
        scales.append(scale)
        inits.append(init)
    return np.asarray(scales, float), np.asarray(inits, float)
