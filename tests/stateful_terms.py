"""Terms with internal states written for the tests only: dynax's model and diagnosis know them through the term
protocol (`AbstractTerm.hidden_names`, `initial_hidden`, `hidden_vector_field`) and nothing else."""

from typing import ClassVar

import equinox as eqx
import jax

from dynax import AbstractJointTerm


class LaggedDamping(AbstractJointTerm):
    """Damping on a lagged speed, $-b z$ with $\\tau \\dot z = \\dot q_j - z$: a joint term with an internal state of
    its own."""

    joint: int = eqx.field(static=True)
    coefficient: jax.Array
    time_constant: float = eqx.field(static=True)
    cause: ClassVar[str] = "lagged_damping"
    prefix: ClassVar[str] = "bl"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def hidden_names(self, system):
        return (f"{self.parameter_name(system)}_speed",)

    def initial_hidden(self, system, x, a):  # the lag at rest: it follows a speed held long
        return x[system.velocity_indices[self.joint]][None]

    def hidden_vector_field(self, system, x, a, z):
        return (x[system.velocity_indices[self.joint]] - z) / self.time_constant

    def joint_force(self, q, dq, a, z=None):
        assert z is not None
        return -self.coefficient * z[0]
