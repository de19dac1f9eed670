"""`LinearAxis`: one prismatic or rotary axis driven by a force (the EMPS benchmark's structure)."""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._errors import UsageError
from ._linear_in_parameters import AbstractLinearInParameters
from ._system import AbstractManipulator

LINEAR_AXIS_PARAMETER_NAMES = ("mass", "viscous", "coulomb", "offset")


class LinearAxis(AbstractManipulator, AbstractLinearInParameters):
    r"""One axis: $m \ddot q = F - F_v \dot q - F_c \operatorname{sign}(\dot q) - F_0$.

    This is the EMPS reference model `force = M q'' + Fv q' + Fc sign(q') + offset`
    (Janot, Gautier and Brunot 2019). In simulation the sign is smoothed as
    $\tanh(\dot q / v_s)$ with `coulomb_velocity` $v_s$ (default 1e-3 m/s) so that fixed-step
    integrators stay accurate; identification uses the exact sign.

    State `(q, dq)`, input `(force,)`. Defaults are the published EMPS values.
    """

    mass: Float[Array, ""] = eqx.field(converter=jnp.asarray, default_factory=lambda: jnp.asarray(95.1089))
    viscous: Float[Array, ""] = eqx.field(converter=jnp.asarray, default_factory=lambda: jnp.asarray(203.5034))
    coulomb: Float[Array, ""] = eqx.field(converter=jnp.asarray, default_factory=lambda: jnp.asarray(20.3935))
    offset: Float[Array, ""] = eqx.field(converter=jnp.asarray, default_factory=lambda: jnp.asarray(-3.1648))
    coulomb_velocity: float = eqx.field(static=True, default=1e-3)

    state_names: ClassVar[tuple[str, ...]] = ("q", "dq")
    n_joints: ClassVar[int] = 1
    input_names: ClassVar[tuple[str, ...]] = ("force",)

    @property
    def angle_indices(self) -> tuple[int, ...]:
        return ()  # the EMPS axis is prismatic; a rotary axis' angle is not treated as periodic either

    def __check_init__(self):
        if self.coulomb_velocity <= 0:
            raise ValueError(f"LinearAxis: `coulomb_velocity` must be positive, got {self.coulomb_velocity}")

    @property
    def parameters(self) -> dict[str, Array]:
        """`mass`, `viscous`, `coulomb`, `offset` as a dict (the contract's names)."""
        return {k: getattr(self, k) for k in LINEAR_AXIS_PARAMETER_NAMES}

    def mass_matrix(self, q):
        return jnp.reshape(self.mass, (1, 1))

    def mass_check_configurations(self, qs):
        """One configuration: the mass matrix is the constant mass."""
        return qs[:1]

    def bias_force(self, q, dq):
        friction = self.viscous * dq + self.coulomb * jnp.tanh(dq / self.coulomb_velocity) + self.offset
        return jnp.reshape(friction, (1,))

    def input_matrix(self):
        return jnp.ones((1, 1), jnp.result_type(self.mass))

    def inverse_dynamics(self, q, dq, ddq):
        r"""$M \ddot q + F_v \dot q + F_c \operatorname{sign}(\dot q) + F_0$, with the exact sign (the EMPS model)."""
        return self.mass * ddq + self.viscous * dq + self.coulomb * jnp.sign(dq) + self.offset

    def energy(self, x: Float[Array, " 2"]) -> Float[Array, ""]:
        r"""Kinetic energy $\tfrac12 M \dot q^2$ (a constant force such as the axis's weight is in the offset)."""
        return 0.5 * self.mass * x[1] ** 2

    # Least-squares identification: the axis is linear in mass, viscous, coulomb and offset, which
    # already hold its friction and offset, so it takes no joint terms.

    def check_least_squares(self, terms=()):
        """Refuses joint terms (friction and offset are base parameters already)."""
        if terms:
            raise UsageError(
                "least-squares identification takes no joint terms on a LinearAxis: its viscous and Coulomb "
                "friction and its offset are base parameters already; use SimulationFit() to fit it with terms"
            )

    def base_parameter_names(self, friction="viscous"):
        """`mass`, `viscous`, `offset`, and `coulomb` (before `offset`) with `friction="coulomb"`."""
        return ("mass", "viscous") + (("coulomb",) if friction == "coulomb" else ()) + ("offset",)

    def energy_parameter_names(self):
        """`mass`."""
        return ("mass",)

    def coulomb_friction_terms(self):
        """None: Coulomb friction is the base parameter `coulomb`."""
        return ()

    def with_base_parameters(self, parameters):
        """Parameters not given keep their values, except `coulomb`, which is zero: a model identified
        with viscous friction only has no Coulomb force."""
        return super().with_base_parameters({"coulomb": jnp.zeros_like(self.coulomb), **parameters})

    def base_parameter_kinds(self):
        """`mass` positive, `viscous` and `coulomb` non-negative, `offset` free."""
        return dict(mass="positive", viscous="nonnegative", coulomb="nonnegative", offset="free")

    def base_parameter_meanings(self):
        """`mass` an inertia, `viscous` and `coulomb` friction."""
        return dict(mass=("inertia", ""), viscous=("friction", ""), coulomb=("friction", ""))

    def vector_field(self, t, x, u):
        dq = x[1]
        friction = self.viscous * dq + self.coulomb * jnp.tanh(dq / self.coulomb_velocity) + self.offset
        return jnp.stack([dq, (u[0] - friction) / self.mass])
