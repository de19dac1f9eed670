r"""Linear-in-parameter regressors of the rigid-body models: dynamic, energy and power.

Every model here is linear in its parameter vector $\theta$, so its regressor is the Jacobian of the
model with respect to $\theta$. Nothing is expanded by hand: the dynamic regressor is the
Jacobian (`jax.jacrev`: a model has fewer outputs than parameters) of the inverse dynamics $M(q)\ddot q + h(q, \dot q) +
F(\dot q)$, the energy regressor is `jax.grad` of the total energy $H(q, \dot q)$ (linear in $\theta_1..\theta_5$), and
the friction columns are the Jacobian of the friction force. What differs per system (its base parameters, its
inverse dynamics and energy, its Coulomb friction) are methods of the system, named in the
contract's names:

- `Acrobot`, `DoublePendulum`: `theta1..theta7` (viscous friction), plus `fc1`, `fc2` with Coulomb
  friction $f_{ci} \operatorname{sign}(\dot q_i)$.
- `LinearAxis`: `mass`, `viscous`, `offset`, plus `coulomb` with Coulomb friction (the EMPS model
  $F = M \ddot q + F_v \dot q + F_c \operatorname{sign}(\dot q) + F_0$).
"""

from typing import cast, Literal, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._errors import UsageError
from .._model._extensions import CoulombFriction, Extended, JointSpring, RotorInertia
from .._model._extensions._terms import AbstractJointTerm
from .._model._linear_in_parameters import least_squares_system
from .._model._system import AbstractManipulator, AbstractSystem

Friction = Literal["viscous", "coulomb"]

# Joint terms that store energy (the rest dissipate it).
_CONSERVATIVE_TERMS = (RotorInertia, JointSpring)


def _check_friction(friction):
    if friction not in ("viscous", "coulomb"):
        raise UsageError(f"`friction` must be 'viscous' or 'coulomb', got {friction!r}")


def split_terms(system):
    """`(nominal system, joint terms)`; refuses what the linear models cannot express."""
    if isinstance(system, Extended):
        base, terms = system.system, system.terms
    else:
        base, terms = system, ()
    base = least_squares_system(base, tuple(terms))
    if any(not isinstance(t, AbstractJointTerm) for t in terms):
        raise UsageError(
            "least-squares identification takes joint terms (friction, drag, rotor inertia, springs) on a two-link "
            "arm; input terms (gain, offset, lag, delay) are not linear in the data: use SimulationFit()"
        )
    return base, tuple(terms)


def with_friction(system: AbstractSystem, friction: Friction = "viscous") -> AbstractSystem:
    """The model `identify` fits: with `friction="coulomb"`, `system` extended with the system's
    `coulomb_friction_terms()` at every joint that has none (for a two-link arm `CoulombFriction`,
    coefficients `fc1`, `fc2`; a linear axis's Coulomb friction is a base parameter)."""
    _check_friction(friction)
    base, terms = split_terms(system)
    if friction == "viscous":
        return system
    have = {t.joint for t in terms if isinstance(t, CoulombFriction)}
    extra = tuple(t for t in base.coulomb_friction_terms() if t.joint not in have)
    return Extended(base, terms + extra) if extra else system


def parameter_names(system: AbstractSystem, friction: Friction = "viscous") -> tuple[str, ...]:
    """The names of the regressor's columns (the identified parameters), in the contract's names.

    **Arguments:**

    - `system`: an `Acrobot`, `DoublePendulum` or `LinearAxis`, or a two-link arm `Extended` with
      joint terms (whose coefficients are then identified too, e.g. `Ir2` for `RotorInertia(1)`).
    - `friction`: `"viscous"` or `"coulomb"` (adds the Coulomb columns).

    **Returns:** a tuple of names, e.g. `("theta1", ..., "theta7", "fc1", "fc2")`.
    """
    system = with_friction(system, friction)
    base, terms = split_terms(system)
    return base.base_parameter_names(friction) + tuple(t.parameter_name(base) for t in terms)


def energy_parameter_names(system: AbstractSystem, friction: Friction = "viscous") -> tuple[str, ...]:
    """The parameters the stored energy depends on (the rest enter through dissipation only)."""
    system = with_friction(system, friction)
    base, terms = split_terms(system)
    return base.energy_parameter_names() + tuple(
        t.parameter_name(base) for t in terms if isinstance(t, _CONSERVATIVE_TERMS)
    )


def parameter_vector(system: AbstractSystem, friction: Friction = "viscous") -> Float[Array, " n_params"]:
    """The system's current parameter values as a vector, in the order of `parameter_names`."""
    system = with_friction(system, friction)
    base, terms = split_terms(system)
    names = parameter_names(system, friction)
    values = {n: getattr(base, n) for n in names if hasattr(base, n)}
    values.update({t.parameter_name(base): t.coefficient for t in terms})
    dtype = jnp.result_type(*values.values(), float)
    return jnp.stack([jnp.asarray(values[n], dtype) for n in names])


def with_parameters(system: AbstractSystem, names: tuple[str, ...], theta: Float[Array, " n_params"]) -> AbstractSystem:
    """`system` with the parameters `names` set to `theta`: fields of the nominal system (through its
    `with_base_parameters`, which says what the base parameters not named become) and coefficients
    of its joint terms."""
    base, terms = split_terms(system)
    if isinstance(theta, jax.Array) and theta.ndim == 1:
        theta = _entries(theta)  # one call instead of one indexing operation per parameter
    fields = [n for n in names if hasattr(base, n) and not isinstance(getattr(type(base), n, None), property)]
    new_base = base.with_base_parameters({n: theta[names.index(n)] for n in fields})
    if not isinstance(system, Extended):
        return new_base
    new_terms = tuple(
        eqx.tree_at(lambda t: t.coefficient, t, theta[names.index(t.parameter_name(base))])
        if t.parameter_name(base) in names
        else t
        for t in terms
    )
    return Extended(new_base, new_terms)


@jax.jit
def _entries(theta):
    return tuple(theta[i] for i in range(theta.shape[0]))


def _inverse_dynamics(system, names, theta, q, dq, ddq):
    """Generalised force that produces `ddq` at `(q, dq)`; linear in `theta`."""
    base, terms = split_terms(with_parameters(system, names, theta))
    force = base.inverse_dynamics(q, dq, ddq)
    for t in terms:
        j = t.joint
        force = force.at[j].add(t.inertia() * ddq[j] - t.force(q[j], dq[j]))
    return force


def _energy(system, names, theta, q, dq):
    base, terms = split_terms(with_parameters(system, names, theta))
    energy = base.energy(jnp.concatenate([q, dq]))
    for t in terms:
        if isinstance(t, RotorInertia):
            energy = energy + 0.5 * t.coefficient * dq[t.joint] ** 2
        elif isinstance(t, JointSpring):
            energy = energy + 0.5 * t.coefficient * q[t.joint] ** 2
    return energy


def positions_and_velocities(system, xs):
    base, _ = split_terms(system)
    n = len(base.joints)
    return xs[..., :n], xs[..., n : 2 * n]


_Rows = TypeVar("_Rows", Array, np.ndarray)


def row_dot(a: _Rows, b: _Rows) -> _Rows:
    """`sum(a * b, axis=-1)` for a short last axis (joints, inputs), written out term by term.

    XLA's CPU backend reduces a minor axis of two or three entries far slower than it adds the
    terms: on 100,000 samples of two joints the work integrand took 2.8 ms as a `jnp.sum` and 0.2 ms
    written out. `a` and `b` of shape `(..., n)`, the result `(...)`: JAX arrays in, JAX out; numpy in, numpy
    out (`applied_force`)."""
    out = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        out = out + a[..., k] * b[..., k]
    return out


def generalised_force(
    system: AbstractSystem, us: Float[Array | np.ndarray, "time n_inputs"]
) -> Float[Array, "time n_joints"]:
    r"""The measured generalised forces $B u$, one entry per joint (the acrobot's `tau1` is 0)."""
    base, _ = split_terms(system)
    b = base.input_matrix().astype(us.dtype)  # (joints, inputs); written out, not a batched dot
    return jnp.stack([row_dot(jnp.asarray(us), b[j]) for j in range(b.shape[0])], axis=-1)


def applied_force(system: AbstractSystem, us) -> np.ndarray:
    """`generalised_force` on the host, in float: `row_dot` on numpy arrays does the same products and sums in the
    same order, each a rounded IEEE operation as in JAX, so the same numbers, without compiling each small JAX
    operation for the record's length."""
    base = cast(AbstractManipulator, split_terms(system)[0])  # the linear models are manipulators
    us = np.asarray(us)
    b = np.asarray(base.input_matrix()).astype(us.dtype)
    return np.stack([row_dot(us, b[j]) for j in range(b.shape[0])], axis=-1).astype(float)


def dynamic_regressor(
    system: AbstractSystem,
    xs: Float[Array | np.ndarray, "time n_states"],
    ddq: Float[Array | np.ndarray, "time n_joints"],
    friction: Friction = "viscous",
) -> Float[Array, "time n_joints n_params"]:
    r"""The inverse-dynamics regressor $Y(q, \dot q, \ddot q)$ with $Y\theta = M\ddot q + h + F = B u$.

    One row per joint and sample: both equations of motion are kept (never summed), and for the
    acrobot the unactuated shoulder gives the row $Y_1 \theta = 0$.

    **Arguments:**

    - `system`: the model (its parameter values are irrelevant: the model is linear in them).
    - `xs`: states `(q, dq)`, shape `(time, n_states)`.
    - `ddq`: joint accelerations, shape `(time, n_joints)`.
    - `friction`: `"viscous"` or `"coulomb"`.

    **Returns:** shape `(time, n_joints, n_params)`, columns named by `parameter_names`.

    ??? cite

        M. Gautier and W. Khalil, "Direct calculation of minimum set of inertial parameters of
        serial robots", IEEE Transactions on Robotics and Automation 6(3), 1990.
    """
    # One compiled program per shape, whoever calls: `filter_jit` keys its cache on how the arguments are spelled
    # (`friction` always by position here) and on whether each array is weakly typed (a model made from Python
    # floats has weak parameters, a fitted one strong). Where every array is of one dtype, weak or strong gives the
    # same types throughout, so the same program.
    return _dynamic_regressor(_strongly_typed(system, xs.dtype), xs, ddq, friction)


def _strongly_typed(tree, dtype):
    """`tree` with its weakly typed arrays of `dtype` strongly typed (through the host: no compiled conversion)."""

    def strong(a):
        return jax.device_put(np.asarray(a)) if isinstance(a, jax.Array) and a.weak_type and a.dtype == dtype else a

    return jax.tree.map(strong, tree)


@eqx.filter_jit
def _dynamic_regressor(system, xs, ddq, friction):
    system = with_friction(system, friction)
    names = parameter_names(system, friction)
    theta0 = jnp.zeros(len(names), xs.dtype)
    q, dq = positions_and_velocities(system, xs)

    def row(q, dq, ddq):
        return jax.jacrev(lambda th: _inverse_dynamics(system, names, th, q, dq, ddq))(theta0)

    return jax.vmap(row)(q, dq, ddq)


def _energy_row(system, names, theta0):
    """`(q, dq) -> w`: one sample's energy-regressor row, `jax.grad` of the energy (linear in theta)."""
    return lambda q, dq: jax.grad(lambda th: _energy(system, names, th, q, dq))(theta0)


def _friction_row(system, names, theta0, mask):
    """`(q, dq) -> row`: one sample's dissipated-power row (zero where `mask` is 0)."""

    def row(q, dq):
        # The power is a scalar linear in theta: one reverse pass gives the whole row.
        power = lambda th: row_dot(dq, _inverse_dynamics(system, names, th, q, dq, jnp.zeros_like(dq)))  # noqa: E731
        return jax.grad(power)(theta0) * mask

    return row


def column_kinds(system: AbstractSystem, friction: Friction = "viscous") -> tuple[tuple[int, ...], tuple[int, ...]]:
    """`(energy, dissipative)`: the regressor columns (indices) the stored energy depends on, and the rest.

    The energy rows are zero in the dissipative columns and the friction-power rows in the energy
    columns."""
    names = parameter_names(system, friction)
    energy = set(energy_parameter_names(system, friction))
    return (
        tuple(i for i, n in enumerate(names) if n in energy),
        tuple(i for i, n in enumerate(names) if n not in energy),
    )


def _rows_setup(system, xs, friction):
    """The model with its friction terms, its parameter names, theta = 0, and the friction columns' mask."""
    names = parameter_names(system, friction)
    dissipative = column_kinds(system, friction)[1]
    mask = jnp.asarray([i in dissipative for i in range(len(names))], xs.dtype)
    system = with_friction(system, friction)
    return system, names, jnp.zeros(len(names), xs.dtype), mask


@eqx.filter_jit
def energy_regressor(
    system: AbstractSystem, xs: Float[Array, "time n_states"], friction: Friction = "viscous"
) -> Float[Array, "time n_params"]:
    r"""The total-energy regressor $w(q, \dot q)$ with $H = w\,\theta$ (zero in the dissipative columns).

    Obtained as `jax.grad` of the energy with respect to the parameters: the energy is linear in
    $\theta_1..\theta_5$ (two-link) or in the mass (linear axis).

    **Arguments:** `system`; `xs` of shape `(time, n_states)`; `friction`.

    **Returns:** shape `(time, n_params)`.

    ??? cite

        M. Gautier and W. Khalil, "On the identification of the inertial parameters of robots",
        Proc. 27th IEEE Conference on Decision and Control, 1988.
    """
    system, names, theta0, _ = _rows_setup(system, xs, friction)
    return jax.vmap(_energy_row(system, names, theta0))(*positions_and_velocities(system, xs))


@eqx.filter_jit
def friction_power_regressor(
    system: AbstractSystem, xs: Float[Array, "time n_states"], friction: Friction = "viscous"
) -> Float[Array, "time n_params"]:
    r"""The dissipated power $\dot q^\top F(\dot q)$ as a regressor row (zero in the energy columns).

    $F$ is the non-conservative part of the inverse dynamics (viscous, Coulomb and, for the linear
    axis, the constant offset force), obtained as the inverse dynamics at $\ddot q = 0$ with the
    energy parameters masked out.

    **Arguments:** `system`; `xs` of shape `(time, n_states)`; `friction`.

    **Returns:** shape `(time, n_params)`.
    """
    system, names, theta0, mask = _rows_setup(system, xs, friction)
    return jax.vmap(_friction_row(system, names, theta0, mask))(*positions_and_velocities(system, xs))


def energy_and_friction_rows(system: AbstractSystem, xs: Float[Array, "time n_states"], friction: Friction = "viscous"):
    """`(energy_regressor, friction_power_regressor)` in one `vmap` over the samples (traced, not compiled here).

    One batched loop for both: as two `vmap`s in one compiled program, XLA's CPU backend ran the
    pair three times slower than either alone.
    """
    system, names, theta0, mask = _rows_setup(system, xs, friction)
    energy, dissipation = _energy_row(system, names, theta0), _friction_row(system, names, theta0, mask)
    return jax.vmap(lambda q, dq: (energy(q, dq), dissipation(q, dq)))(*positions_and_velocities(system, xs))


@eqx.filter_jit
def input_power(
    system: AbstractSystem, xs: Float[Array, "time n_states"], us: Float[Array, "time n_inputs"]
) -> Float[Array, " time"]:
    r"""The power delivered by the inputs, $\dot q^\top B u$."""
    _, dq = positions_and_velocities(system, xs)
    return row_dot(dq, generalised_force(system, us))
