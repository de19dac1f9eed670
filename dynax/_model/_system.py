"""The system abstraction: an `eqx.Module` whose dynamics is `vector_field(t, x, u)`."""

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree
import numpy as np


class AbstractSystem(eqx.Module):
    r"""A continuous-time controlled system $\dot x = f(t, x, u)$.

    Subclasses are final `eqx.Module`s whose array fields are the (physical or base) parameters.
    The state and input orders are the column orders of the data contract, named by
    `state_names` and `input_names`.

    Every system is simulated, fitted by `SimulationFit` and diagnosed; one whose inverse dynamics is
    linear in named base parameters also subclasses `dynax.internal.AbstractLinearInParameters`, whose
    hooks the least-squares methods call.
    """

    state_names: eqx.AbstractClassVar[tuple[str, ...]]
    input_names: eqx.AbstractClassVar[tuple[str, ...]]
    #: The last of `input_names` that a record may leave out (a quadrotor's `vbat`, read only by a
    #: model whose features use it): `identify` takes records with or without them.
    optional_inputs: ClassVar[tuple[str, ...]] = ()

    @abc.abstractmethod
    def vector_field(
        self, t: Float[ArrayLike, ""], x: Float[Array, " n_states"], u: Float[Array, " n_inputs"]
    ) -> Float[Array, " n_states"]:
        r"""The time derivative $\dot x = f(t, x, u)$, in diffrax argument order.

        **Arguments:**

        - `t`: time [s].
        - `x`: state, ordered as `state_names`.
        - `u`: input, ordered as `input_names`.

        **Returns:**

        $\dot x$, same shape as `x`.
        """

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    # What differs per system is a method here, so that generic layers (identification, diagnosis,
    # simulation error) never need to check a concrete class.

    def parameter_filter(self) -> PyTree[Any]:
        """What a fit moves by default (a filter for `dynax.Parameters`): every inexact array leaf."""
        return jax.tree.map(eqx.is_inexact_array, self)

    def parameter_labels(self) -> tuple[str, ...] | None:
        """Readable names of the `parameter_filter()` elements, in order; `None` uses the tree paths."""
        return None

    def state_error(
        self, simulated: Float[Array, "*batch n_measured"], measured: Float[Array, "*batch n_measured"]
    ) -> Float[Array, "*batch n_measured"]:
        """Simulated minus measured states, for the measured (leading) states. Systems whose state
        has a symmetry (a unit quaternion's sign) override this."""
        return simulated - measured

    @property
    def position_indices(self) -> tuple[int, ...]:
        """The states that are positions (or angles): the headline of simulation errors. Default:
        the names not starting with `d`."""
        return tuple(i for i, s in enumerate(self.state_names) if not s.startswith("d"))

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """The states whose time derivatives the residual analysis reads (a manipulator's joint
        velocities). Default: every state."""
        return tuple(range(self.n_states))

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The generalised coordinates joint terms (friction, rotor inertia, springs) can act on:
        a manipulator's `q1, q2, ...`. Default: none (no mass matrix and bias force to extend)."""
        return ()

    @property
    def body_axes(self) -> tuple[str, ...]:
        """The body axes vehicle terms (drag, wind, body bias) can act on: a rigid-body vehicle's
        `u, v, w, p, q, r`. Default: none."""
        return ()

    # What the discrepancy diagnosis (`dynax.diagnose`) needs to know about a system. Additive:
    # every default below describes a system with no joints, no body axes and no angles.

    @property
    def joints(self) -> tuple[int, ...]:
        """The joints that joint-space model extensions (`CoulombFriction`, `RotorInertia`, ...) act on.
        Default: none (only a manipulator has a mass matrix and bias force to extend)."""
        return ()

    @property
    def angle_indices(self) -> tuple[int, ...]:
        """The position states that are angles (periodic features `sin q`, `cos q` make sense for them).
        Default: none."""
        return ()

    def residual_features(
        self, xs: Float[np.ndarray, "time n_states"], accelerations: Float[np.ndarray, "time n_velocities"]
    ) -> tuple[list[np.ndarray], list[str]]:
        """Columns a probe of one-step residuals regresses on: functions of the (smoothed) state in
        which a missing force would show, and the model's own accelerations (`accelerations`, one
        column per `velocity_indices`). Returns `(columns, names)`.

        Default: each state $x$, $|x|x$ and a smoothed sign; manipulators and the helicopter
        give their own (see `dynax.internal.structure_test`).
        """
        names, cols = [], []
        for j, c in enumerate(self.state_names):
            x = xs[:, j]
            cols += [x, np.abs(x) * x, np.tanh(x / max(0.05 * float(np.std(x)), 1e-6))]
            names += [c, f"|{c}|{c}", f"sign({c})"]
        return cols, names


class AbstractManipulator(AbstractSystem):
    r"""A rigid-body system $M(q)\ddot q + h(q, \dot q) = B u$ with state $x = (q, \dot q)$.

    Concrete systems give the mass matrix $M$, the bias force $h$ (Coriolis, centrifugal,
    gravity and damping, all moved to the left-hand side) and the input matrix $B$. Model
    extensions (friction, rotor inertia, input dynamics; see `dynax.diagnose`) act on these
    pieces, so they compose with any manipulator.
    """

    n_joints: eqx.AbstractClassVar[int]

    @abc.abstractmethod
    def mass_matrix(self, q: Float[Array, " n_joints"]) -> Float[Array, "n_joints n_joints"]:
        """The joint-space mass (inertia) matrix $M(q)$, symmetric positive definite."""

    @abc.abstractmethod
    def bias_force(self, q: Float[Array, " n_joints"], dq: Float[Array, " n_joints"]) -> Float[Array, " n_joints"]:
        r"""$h(q, \dot q) = C(q, \dot q)\dot q - \tau_g(q) + D \dot q$: everything but inertia and input."""

    @abc.abstractmethod
    def input_matrix(self) -> Float[Array, "n_joints n_inputs"]:
        """$B$, mapping the input vector to generalised forces."""

    def mass_check_configurations(self, qs: Float[Array, "time n_joints"]) -> Float[Array, "k n_joints"]:
        r"""Configurations whose mass matrices include the one with the smallest eigenvalue of $M(q)$
        over all of `qs` (`dynax.internal.check_consistency` evaluates $M$ there only; an identification
        hook of `dynax.internal.AbstractLinearInParameters`, given here for every manipulator). Default: all
        of `qs`; a system whose mass matrix has known structure returns fewer (a two-link arm two,
        with the same $M$ as the samples at the ends of the data's range of $\cos q_2$)."""
        return qs

    @property
    def position_indices(self) -> tuple[int, ...]:
        return tuple(range(self.n_joints))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.state_names[: self.n_joints])

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        return tuple(range(self.n_joints, 2 * self.n_joints))

    @property
    def joints(self) -> tuple[int, ...]:
        return tuple(range(self.n_joints))

    @property
    def angle_indices(self) -> tuple[int, ...]:
        """Revolute joints: every joint (a prismatic axis overrides this)."""
        return tuple(range(self.n_joints))

    def residual_features(self, xs, accelerations):
        r"""Per joint: the smoothed sign of its velocity, the velocity, $|\dot q|\dot q$, $\sin q$,
        $\cos q$ and the model's acceleration."""
        names, cols = [], []
        n = self.n_joints
        for j in range(n):
            q, v = xs[:, j], xs[:, n + j]
            c = self.state_names[j]
            vs = max(0.05 * float(np.std(v)), 1e-6)
            cols += [np.tanh(v / vs), v, np.abs(v) * v, np.sin(q), np.cos(q), accelerations[:, j]]
            names += [f"sign(d{c})", f"d{c}", f"|d{c}|d{c}", f"sin({c})", f"cos({c})", f"model acceleration d{c}/dt"]
        return cols, names

    def inverse_dynamics(
        self, q: Float[Array, " n_joints"], dq: Float[Array, " n_joints"], ddq: Float[Array, " n_joints"]
    ) -> Float[Array, " n_joints"]:
        r"""The generalised force $M(q)\ddot q + h(q, \dot q)$ that produces `ddq` at `(q, dq)`:
        what the least-squares regressors differentiate with respect to the base parameters."""
        # Written out rather than `@` or a `jnp.sum`: under vmap a 2x2 matrix-vector product becomes a
        # batched dot, and a sum over a two-entry axis a minor-axis reduction, both of which XLA's CPU
        # backend runs several times slower than the same arithmetic fused.
        m = self.mass_matrix(q)
        inertial = m[:, 0] * ddq[0]
        for k in range(1, ddq.shape[0]):
            inertial = inertial + m[:, k] * ddq[k]
        return inertial + self.bias_force(q, dq)

    def vector_field(self, t, x, u):
        n = self.n_joints
        q, dq = x[:n], x[n:]
        rhs = self.input_matrix() @ u - self.bias_force(q, dq)
        ddq = solve_spd(self.mass_matrix(q), rhs)
        return jnp.concatenate([dq, ddq])


def solve_spd(m, b):
    if m.shape == (2, 2):
        # Closed-form 2x2 inverse: much cheaper than a LU call inside a vmapped scan.
        det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        return jnp.stack([m[1, 1] * b[0] - m[0, 1] * b[1], m[0, 0] * b[1] - m[1, 0] * b[0]]) / det
    return jnp.linalg.solve(m, b)
