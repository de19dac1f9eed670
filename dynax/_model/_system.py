"""The system abstraction: an `eqx.Module` whose dynamics is `vector_field(t, x, u)`."""

import abc
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, ArrayLike, PyTree


class AbstractSystem(eqx.Module):
    r"""A continuous-time controlled system $\dot x = f(t, x, u)$.

    Subclasses are final `eqx.Module`s whose array fields are the (physical or base) parameters.
    The state and input orders are the column orders of the data contract, named by
    `state_names` and `input_names`.
    """

    state_names: eqx.AbstractClassVar[tuple[str, ...]]
    input_names: eqx.AbstractClassVar[tuple[str, ...]]

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
    def bias_force(
        self, q: Float[Array, " n_joints"], dq: Float[Array, " n_joints"]
    ) -> Float[Array, " n_joints"]:
        r"""$h(q, \dot q) = C(q, \dot q)\dot q - \tau_g(q) + D \dot q$: everything but inertia and input."""

    @abc.abstractmethod
    def input_matrix(self) -> Float[Array, "n_joints n_inputs"]:
        """$B$, mapping the input vector to generalised forces."""

    @property
    def position_indices(self) -> tuple[int, ...]:
        return tuple(range(self.n_joints))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.state_names[: self.n_joints])

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        return tuple(range(self.n_joints, 2 * self.n_joints))

    def vector_field(self, t, x, u):
        n = self.n_joints
        q, dq = x[:n], x[n:]
        rhs = self.input_matrix() @ u - self.bias_force(q, dq)
        ddq = _solve_spd(self.mass_matrix(q), rhs)
        return jnp.concatenate([dq, ddq])


def _solve_spd(m, b):
    if m.shape == (2, 2):
        # Closed-form 2x2 inverse: much cheaper than a LU call inside a vmapped scan.
        det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        return jnp.stack([m[1, 1] * b[0] - m[0, 1] * b[1], m[0, 0] * b[1] - m[1, 0] * b[0]]) / det
    return jnp.linalg.solve(m, b)
