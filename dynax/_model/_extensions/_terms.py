"""Candidate model extensions: small Modules, each one physical effect with its own parameter.

Every term has a `coefficient` field and a `neutral` value at which it has no effect (zero friction,
zero inertia, unit gain, zero delay...), so `Extended(system, terms)` with all terms at their
neutral values *is* the nominal system. The diagnosis relies on this to refit many candidates in a
single `vmap` (see `dynax.diagnose`).
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._errors import UsageError
from .._system import solve_spd


def float_scalar(value) -> Array:
    return jnp.asarray(value, dtype=jnp.result_type(float))


class AbstractTerm(eqx.Module):
    r"""A model extension: one physical effect with one fitted `coefficient`.

    **Class attributes:**

    - `cause`: the contract's cause name (`"coulomb_friction"`, ...).
    - `prefix`: the parameter's short name in reports (`"fc"` for Coulomb friction, ...).
    - `neutral`: the coefficient value at which the term does nothing.
    - `sign`: +1 when only deviations above `neutral` are physical (friction, inertia, delay),
      0 when both signs are.

    **Internal states.** A term may carry states of its own (a memory of rest, a filter, a
    temperature), which `Extended` appends to the nominal state: `hidden_names` names them,
    `initial_hidden` completes a measured state with them and `hidden_vector_field` is their
    $\dot z$; the term's force reads them as its last argument (`AbstractJointTerm.joint_force`,
    `AbstractVehicleTerm.acceleration`, ...). Input terms (`AbstractInputTerm`) carry theirs through
    the input chain instead (`applied`, `hidden_derivative`, `steady_state`): they move with the
    recorded input alone, and come first in the state.

    **In the diagnosis** (`dynax.diagnose`) whether a term has states, and how it is screened, follows from
    `hidden_names` and `smooth_at_neutral` alone. An input term with states has a time for its coefficient and no
    derivative at zero (the input passes through): it is screened through its first-order effect on the input (a
    lag or dead time also at finite sizes). Any other term's states are integrated along the measured states
    (`hidden_vector_field`): for the one-step screening from `initial_hidden` at a record's first sample, and for
    the windowed rollouts (the refit, the held-out score) from `initial_hidden` at the first sample of the half
    second of history before each window, so that a window starts them where the record puts them. A state that
    forgets its start (a lag, `Stiction`'s memory of rest) has forgotten `initial_hidden`'s guess by then; one that
    keeps it (an integral of the speed) keeps the guess's error. A term that is not `smooth_at_neutral` is screened
    on the secant to its start value. Neither of these two kinds is ranked by the first Gauss-Newton step of its
    refit, which reads the derivative at neutral.
    """

    coefficient: eqx.AbstractVar[Float[Array, ""]]
    cause: eqx.AbstractClassVar[str]
    prefix: eqx.AbstractClassVar[str]
    neutral: eqx.AbstractClassVar[float]
    sign: eqx.AbstractClassVar[int]
    # The term's effect is differentiable in its coefficient at `neutral`, so that the derivative there shows it
    # (not `Stiction`'s: at zero its level sits on a tie of its clipping, where the derivative is half the one above).
    smooth_at_neutral: ClassVar[bool] = True

    def check_system(self, system) -> None:
        """Raise a `ValueError` naming the term and the system if the term cannot act on `system`
        (`Extended` calls it for every term). Default: a term acts on any system."""

    @abc.abstractmethod
    def where(self, system) -> str:
        """The coordinate or input the term acts on, by its contract name (`"q2"`, `"tau2"`)."""

    def parameter_name(self, system) -> str:
        """The coefficient's name in reports, e.g. `fc2` for Coulomb friction at `q2`."""
        where = self.where(system)
        if where.startswith("q") and (where[1:].isdigit() or where == "q"):
            return f"{self.prefix}{where[1:]}"
        return f"{self.prefix}_{where}"

    def label(self, system) -> str:
        """`cause@where`, e.g. `coulomb_friction@q2` (the contract's `extended.terms` entries)."""
        return f"{self.cause}@{self.where(system)}"

    def shortest_resolved(self, step: float) -> float:
        """The smallest coefficient a fixed-step rollout with steps of `step` seconds simulates faithfully; 0 where
        any is (a dead time is: the windowed rollouts shift the input by it exactly, `InputDelay.shift`)."""
        return 0.0

    def parameters(self, system) -> dict[str, Array]:
        """The term's coefficients by report name (one for a named cause; several for a `Discovered` term)."""
        return {self.parameter_name(system): self.coefficient}

    def hidden_names(self, system) -> tuple[str, ...]:
        """The names of the term's internal states, its part of `Extended.state_names` (default none)."""
        return ()

    def initial_hidden(
        self, system, x: Float[Array, " n_measured"], a: Float[Array, " n_inputs"]
    ) -> Float[Array, " n_hidden"]:
        """The internal states a rollout from the measured nominal state `x` starts with, under the applied
        input `a` (`Extended.initial_state`; default zero)."""
        return jnp.zeros((len(self.hidden_names(system)),), x.dtype)

    def hidden_vector_field(
        self, system, x: Float[Array, " n_measured"], a: Float[Array, " n_inputs"], z: Float[Array, " n_hidden"]
    ) -> Float[Array, " n_hidden"]:
        r"""$\dot z$ of the internal states `z` at the nominal state `x` under the applied input `a` (default zero)."""
        return jnp.zeros_like(z)

    def parameter_filter(self):
        """What a fit of an `Extended` model moves in this term (a filter for `dynax.Parameters`):
        every inexact array leaf. Terms with settings held as arrays (so that a new value does not
        recompile, e.g. a friction's smoothing speed) leave those out."""
        return jax.tree.map(eqx.is_inexact_array, self)


class AbstractJointTerm(AbstractTerm):
    r"""A term acting on one generalised coordinate of a manipulator $M(q)\ddot q + h = B u$.

    It adds a generalised force `force(q_j, dq_j)` to the right-hand side and an inertia
    `inertia()` to the diagonal entry $M_{jj}$.

    **Fields:** `joint`, the 0-based index of the coordinate (static).
    """

    joint: eqx.AbstractVar[int]
    # A friction law of the joint's speed (a sticking term replaces their sum in its band).
    friction: ClassVar[bool] = False
    # The term holds its joint at rest (`Stiction`): the model adds its `holding_force` (no diagnosis reads it).
    holds_at_rest: ClassVar[bool] = False

    def __check_init__(self):
        if not isinstance(self.joint, int) or self.joint < 0:
            raise UsageError(f"{type(self).__name__}: `joint` must be a non-negative int index, got {self.joint!r}")

    def check_system(self, system) -> None:
        if not system.joint_names:
            raise UsageError(
                f"{type(self).__name__} acts on a joint, but {type(system).__name__} is not a manipulator "
                "(it has no mass matrix and bias force to extend)"
            )

    def where(self, system) -> str:
        self.check_system(system)
        joints = system.joint_names
        if self.joint >= len(joints):
            raise UsageError(
                f"{type(self).__name__}: `joint={self.joint}` but {type(system).__name__} has {len(joints)} joint(s)"
            )
        return joints[self.joint]

    @staticmethod
    def extended_vector_field(
        system,
        terms: tuple["AbstractJointTerm", ...],
        x: Float[Array, " n_states"],
        a: Float[Array, " n_inputs"],
        hidden: tuple[Float[Array, " _"], ...] | None = None,
    ) -> Float[Array, " n_states"]:
        r"""The manipulator's $\dot x$ with joint terms acting on its pieces (used by `Extended`):
        $\big(M(q) + \operatorname{diag}(I_r)\big)\ddot q + h(q, \dot q) = B\,a + \sum_k f_k(q, \dot q, z_k)$.
        `hidden`: each term's internal states `z_k` (`AbstractTerm.hidden_names`), in order (default none)."""
        k = system.n_joints
        q, dq = x[:k], x[k:]
        if hidden is None:
            hidden = tuple(x[:0] for _ in terms)
        force = system.input_matrix() @ a - system.bias_force(q, dq)
        inertia = jnp.zeros(k, force.dtype)
        for term, z in zip(terms, hidden, strict=True):
            force = force.at[term.joint].add(term.joint_force(q, dq, a, z))
            inertia = inertia.at[term.joint].add(term.inertia())
        mass = system.mass_matrix(q) + jnp.diag(inertia)
        holding = tuple((t, z) for t, z in zip(terms, hidden) if t.holds_at_rest)
        if holding:
            terms_held, hidden_held = zip(*holding)
            force = force + type(terms_held[0]).holding_force(terms_held, terms, mass, force, q, dq, hidden_held)
        ddq = solve_spd(mass, force)
        return jnp.concatenate([dq, ddq])

    @staticmethod
    def holding_force(holding, terms, mass, force, q, dq, hidden=None) -> Float[Array, " n_joints"]:
        """What the terms that hold their joints at rest (`holds_at_rest`, e.g. `Stiction`) add to the generalised
        force `force`, given all terms, the mass matrix and the holding terms' internal states (default none)."""
        return jnp.zeros_like(force)

    def force(self, q: Float[Array, ""], dq: Float[Array, ""]) -> Float[Array, ""]:
        """Generalised force the term adds at its joint (default none)."""
        return jnp.zeros_like(dq)

    def joint_force(
        self,
        q: Float[Array, " n_joints"],
        dq: Float[Array, " n_joints"],
        a: Float[Array, " n_inputs"],
        z: Float[Array, " n_hidden"] | None = None,
    ) -> Float[Array, ""]:
        """Generalised force at its joint from the whole state, the applied input and the term's internal states
        `z` (`hidden_names`; default `force(q_j, dq_j)`)."""
        return self.force(q[self.joint], dq[self.joint])

    def inertia(self) -> Float[Array, ""]:
        """Inertia the term adds to $M_{jj}$ (default none)."""
        return jnp.zeros_like(self.coefficient)


class CoulombFriction(AbstractJointTerm):
    r"""Coulomb (dry) friction $-f_c \operatorname{sign}(\dot q_j)$ at one joint.

    The sign is smoothed as $\tanh(\dot q_j / v_s)$ with `velocity_scale` $v_s$ (default
    0.01 rad/s, as `atan(100 dq)` in the DFKI lab's model) so that fixed-step integrators stay
    accurate and the force is differentiable in $f_c$.

    **Arguments:** `joint` (0-based), `fc` the friction torque or force [N m or N],
    `velocity_scale` [rad/s or m/s].

    ??? cite

        B. Armstrong-Hélouvry, P. Dupont, C. Canudas de Wit, "A survey of models, analysis tools
        and compensation methods for the control of machines with friction", Automatica 30(7), 1994.
    """

    joint: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    # An array leaf, not a static field: the diagnosis sets it from each record's speeds, and a
    # static float would compile every diagnosis anew. Not fitted (see `parameter_filter`).
    velocity_scale: Float[Array, ""]
    cause: ClassVar[str] = "coulomb_friction"
    prefix: ClassVar[str] = "fc"
    friction: ClassVar[bool] = True
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, joint: int, fc: ArrayLike = 0.0, *, velocity_scale: float = 0.01):
        self.joint = joint
        self.coefficient = float_scalar(fc)
        self.velocity_scale = float_scalar(velocity_scale)

    def parameter_filter(self):
        return eqx.tree_at(lambda t: t.velocity_scale, super().parameter_filter(), False)

    def force(self, q, dq):
        return -self.coefficient * jnp.tanh(dq / self.velocity_scale)


class ViscousFriction(AbstractJointTerm):
    r"""Viscous friction $-b \dot q_j$ at one joint (missing, or added to the nominal model's own).

    **Arguments:** `joint` (0-based), `b` [N m s/rad or N s/m].
    """

    joint: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "viscous_friction"
    prefix: ClassVar[str] = "b"
    friction: ClassVar[bool] = True
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, joint: int, b: ArrayLike = 0.0):
        self.joint = joint
        self.coefficient = float_scalar(b)

    def force(self, q, dq):
        return -self.coefficient * dq


class QuadraticDrag(AbstractJointTerm):
    r"""Quadratic (aerodynamic or fluid) drag $-c\,|\dot q_j|\,\dot q_j$ at one joint.

    **Arguments:** `joint` (0-based), `c` [N m s^2/rad^2 or N s^2/m^2].
    """

    joint: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "quadratic_drag"
    prefix: ClassVar[str] = "cd"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, joint: int, c: ArrayLike = 0.0):
        self.joint = joint
        self.coefficient = float_scalar(c)

    def force(self, q, dq):
        return -self.coefficient * jnp.abs(dq) * dq


class RotorInertia(AbstractJointTerm):
    r"""Reflected rotor inertia $I_r$ of the actuator at one joint, added to $M_{jj}$.

    For a motor with rotor inertia $J$ behind a gear ratio $n$, $I_r = n^2 J$. (The coupling
    term $n J$ of a motor carried on a moving link is neglected; it is small against $n^2 J$.)

    **Arguments:** `joint` (0-based), `inertia` $I_r$ [kg m^2 or kg].

    ??? cite

        M. W. Spong, "Modeling and control of elastic joint robots", J. Dynamic Systems,
        Measurement and Control 109(4), 1987 (reflected rotor inertia).
    """

    joint: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "rotor_inertia"
    prefix: ClassVar[str] = "Ir"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, joint: int, inertia: ArrayLike = 0.0):
        self.joint = joint
        self.coefficient = float_scalar(inertia)

    def inertia(self):
        return self.coefficient


class JointSpring(AbstractJointTerm):
    r"""A linear spring $-k q_j$ at one joint (e.g. a cable or a compliant stop).

    Not in the diagnosis vocabulary: the tests hide it in data to check that the diagnosis says
    `unexplained` rather than naming a wrong cause.

    **Arguments:** `joint` (0-based), `k` [N m/rad or N/m].
    """

    joint: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "joint_spring"
    prefix: ClassVar[str] = "k"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, joint: int, k: ArrayLike = 0.0):
        self.joint = joint
        self.coefficient = float_scalar(k)

    def force(self, q, dq):
        return -self.coefficient * q
