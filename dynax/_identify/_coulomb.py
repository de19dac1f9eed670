"""`WithCoulombFriction`: a manipulator with Coulomb friction torques added at its joints."""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._model._system import AbstractManipulator


class WithCoulombFriction(AbstractManipulator):
    r"""`system` plus Coulomb friction $f_{c,i} \operatorname{sign}(\dot q_i)$ at every joint.

    In simulation the sign is smoothed as $\tanh(\dot q_i / v_s)$ with `velocity_scale` $v_s$
    (default 0.01 rad/s), so fixed-step integrators stay accurate; least-squares identification
    uses the exact sign. This is the model `identify(..., friction="coulomb")` returns for the
    two-link arms (parameters `fc1`, `fc2`).

    **Arguments:**

    - `system`: the manipulator (e.g. `DoublePendulum`).
    - `coulomb`: friction torques, shape `(n_joints,)` [N m].
    - `velocity_scale`: smoothing velocity of the sign (static).
    """

    system: AbstractManipulator
    coulomb: Float[Array, " n_joints"]
    velocity_scale: float = eqx.field(static=True, default=1e-2)

    def __check_init__(self):
        if jnp.shape(self.coulomb) != (self.system.n_joints,):
            raise ValueError(
                f"WithCoulombFriction: `coulomb` must have shape ({self.system.n_joints},), got {jnp.shape(self.coulomb)}"
            )
        if not self.velocity_scale > 0:
            raise ValueError(f"WithCoulombFriction: `velocity_scale` must be positive, got {self.velocity_scale}")

    @property
    def state_names(self):  # type: ignore[override]
        return self.system.state_names

    @property
    def input_names(self):  # type: ignore[override]
        return self.system.input_names

    @property
    def n_joints(self):  # type: ignore[override]
        return self.system.n_joints

    def mass_matrix(self, q):
        return self.system.mass_matrix(q)

    def bias_force(self, q, dq):
        return self.system.bias_force(q, dq) + self.coulomb * jnp.tanh(dq / self.velocity_scale)

    def input_matrix(self):
        return self.system.input_matrix()

    def energy(self, x):
        return self.system.energy(x)
