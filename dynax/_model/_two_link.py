r"""The Spong / Drake two-link arm: `Acrobot` (elbow driven) and `DoublePendulum` (both driven).

Both are written in the seven base parameters of the data contract, which is the minimal set the
dynamics depend on (I1, I2 about the pivots):

$$\theta_1 = I_1 + m_2 l_1^2,\ \theta_2 = I_2,\ \theta_3 = m_2 l_1 l_{c2},\ \theta_4 = g(m_1 l_{c1} + m_2 l_1),\
\theta_5 = g m_2 l_{c2},\ \theta_6 = b_1,\ \theta_7 = b_2.$$

q1 is measured from hanging straight down, q2 relative to link 1.
"""

from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float
import numpy as np

from .._errors import UsageError
from ._extensions._terms import CoulombFriction, RotorInertia
from ._linear_in_parameters import AbstractLinearInParameters
from ._system import AbstractManipulator

BASE_PARAMETER_NAMES = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7")
ENERGY_PARAMETER_NAMES = BASE_PARAMETER_NAMES[:5]  # theta6, theta7 (viscous friction) only dissipate

# Drake's AcrobotParams defaults (drake/examples/acrobot/acrobot_params.h).
DRAKE_DEFAULTS = dict(m1=1.0, m2=1.0, l1=1.0, lc1=0.5, lc2=1.0, Ic1=0.083, Ic2=0.33, b1=0.1, b2=0.1, g=9.81)


# Physical parameters and the bound each must meet: masses, the first link's length and gravity are
# positive; centre-of-mass distances, inertias and viscous friction cannot be negative.
_PHYSICAL_BOUNDS = dict(
    m1="positive",
    m2="positive",
    l1="positive",
    g="positive",
    lc1="nonnegative",
    lc2="nonnegative",
    Ic1="nonnegative",
    Ic2="nonnegative",
    I1="positive",
    I2="positive",
    b1="nonnegative",
    b2="nonnegative",
)


def _check_physical(**values):
    """Refuse physically impossible parameters by name: `UsageError` (a `ValueError`) for concrete values (the usual
    call), an `eqx.error_if` runtime error for traced ones (inside `jit`, `vmap` or `grad`)."""
    from jax.core import Tracer

    traced = []
    for name, value in values.items():
        if value is None:
            continue
        positive = _PHYSICAL_BOUNDS[name] == "positive"
        kind = getattr(value, "dtype", None)
        if (
            isinstance(value, str | bool | np.bool_)
            or (kind is None and not isinstance(value, int | float | np.number))
            or (kind is not None and not (np.issubdtype(kind, np.floating) or np.issubdtype(kind, np.integer)))
        ):  # NumPy would read "1" as 1.0, and the formulas then fail on the string itself
            raise UsageError(f"from_physical: `{name}` must be a real number, got {value!r}")
        message = (
            f"`{name}` is not a physical value; it must be {'positive' if positive else 'non-negative'} and finite"
        )
        if isinstance(value, Tracer):
            bad = ~jnp.isfinite(value) | ((value <= 0) if positive else (value < 0))
            traced.append((jnp.any(bad), "from_physical: " + message))
            continue
        # Concrete values are checked with NumPy: no JAX computation, so importing dynax (which builds the
        # Drake defaults through here) leaves the backend uninitialised for `jax.distributed.initialize`.
        v = np.asarray(value, dtype=float)
        bad = ~np.isfinite(v) | ((v <= 0) if positive else (v < 0))
        if bool(np.any(bad)):
            shown = value if isinstance(value, (int, float)) else (float(v) if v.ndim == 0 else v)
            raise UsageError(
                f"from_physical: `{name}` = {shown} is not a physical value; it must be "
                f"{'positive' if positive else 'non-negative'} and finite"
            )
    return traced


PHYSICAL_REQUIRED = ("m1", "m2", "l1", "lc1", "lc2", "b1", "b2")
PHYSICAL_OPTIONAL = ("Ic1", "Ic2", "I1", "I2", "g")


def base_parameters_from_physical(physical: Mapping[str, ArrayLike]) -> dict[str, ArrayLike]:
    r"""Map physical parameters to the base parameters theta1..theta7.

    **Arguments:** `physical`, a mapping (a dict, or a lab's parameter file as read) of: masses
    `m1`, `m2` [kg]; length of link 1 `l1` [m]; centre-of-mass distances `lc1`, `lc2` [m]; inertias
    `Ic1`, `Ic2` about the centres of mass [kg m^2], or instead `I1`, `I2` about the pivots (as the
    DFKI lab's parameter files give them); viscous friction `b1`, `b2` [N m s/rad]; gravity `g`
    [m/s^2] (default 9.81). For example Drake's acrobot: `base_parameters_from_physical(dict(m1=1.0,
    m2=1.0, l1=1.0, lc1=0.5, lc2=1.0, Ic1=0.083, Ic2=0.33, b1=0.1, b2=0.1))`.

    **Returns:** a dict `theta1..theta7`.

    Not every physical parameter can be recovered from the base ones: the seven base parameters
    are what the equations of motion depend on, while (m1, lc1, Ic1) enter only through
    $I_1 = I_{c1} + m_1 l_{c1}^2$ and $m_1 l_{c1}$, and $(m_2, l_{c2}, I_{c2})$ only through
    $m_2 l_{c2}$, $I_2$ and $m_2$ (the latter in combination with $l_1$). `l2` does not enter at all.

    **Raises:** `ValueError` naming the parameter for a physically impossible value: a mass, `l1`,
    `g`, `I1` or `I2` that is not positive, a centre-of-mass distance, `Ic1`, `Ic2` or viscous
    friction that is negative, or any non-finite value; and for a name missing or not among these.
    Traced values (inside `jit`, `vmap`, `grad`) are checked by `eqx.error_if` at run time instead.
    """
    unknown = sorted(set(physical) - set(PHYSICAL_REQUIRED + PHYSICAL_OPTIONAL))
    missing = [name for name in PHYSICAL_REQUIRED if name not in physical]
    if unknown or missing:
        found = f"unknown parameter(s) {unknown}" if unknown else f"missing parameter(s) {missing}"
        raise ValueError(
            f"base_parameters_from_physical: {found}; expected {list(PHYSICAL_REQUIRED)} "
            f"and some of {list(PHYSICAL_OPTIONAL)}"
        )
    values = {"Ic1": None, "Ic2": None, "I1": None, "I2": None, "g": 9.81, **physical}
    m1, m2, l1, lc1, lc2, b1, b2, g = (values[name] for name in ("m1", "m2", "l1", "lc1", "lc2", "b1", "b2", "g"))
    Ic1, Ic2, I1, I2 = (values[name] for name in ("Ic1", "Ic2", "I1", "I2"))
    traced = _check_physical(m1=m1, m2=m2, l1=l1, lc1=lc1, lc2=lc2, Ic1=Ic1, Ic2=Ic2, b1=b1, b2=b2, g=g, I1=I1, I2=I2)
    if (Ic1 is None) == (I1 is None) or (Ic2 is None) == (I2 is None):
        raise ValueError(
            "base_parameters_from_physical: give each link's inertia once, either `Ic1`/`Ic2` "
            "(about the centre of mass) or `I1`/`I2` (about the pivot)"
        )
    I1 = Ic1 + m1 * lc1**2 if I1 is None else I1
    I2 = Ic2 + m2 * lc2**2 if I2 is None else I2
    base = dict(
        theta1=I1 + m2 * l1**2,
        theta2=I2,
        theta3=m2 * l1 * lc2,
        theta4=g * (m1 * lc1 + m2 * l1),
        theta5=g * m2 * lc2,
        theta6=b1,
        theta7=b2,
    )
    for bad, message in traced:  # inside jit/vmap/grad: a runtime error naming the parameter, whichever is used
        base = {k: eqx.error_if(jnp.asarray(v), bad, message) for k, v in base.items()}
    return base


DRAKE_BASE_PARAMETERS = base_parameters_from_physical(DRAKE_DEFAULTS)


def _field(name):
    # Converted on construction, so a Python float or a NumPy scalar is stored as the array the annotation says.
    return eqx.field(converter=jnp.asarray, default_factory=lambda: jnp.asarray(DRAKE_BASE_PARAMETERS[name]))


def _mass_matrix(p, q):
    c2 = jnp.cos(q[1])
    m12 = p.theta2 + p.theta3 * c2
    return jnp.stack(
        [jnp.stack([p.theta1 + p.theta2 + 2 * p.theta3 * c2, m12]), jnp.stack([m12, p.theta2 * jnp.ones_like(c2)])]
    )


def _bias_force(p, q, dq):
    s1, s2, s12 = jnp.sin(q[0]), jnp.sin(q[1]), jnp.sin(q[0] + q[1])
    coriolis = jnp.stack([-2 * p.theta3 * s2 * dq[1] * dq[0] - p.theta3 * s2 * dq[1] ** 2, p.theta3 * s2 * dq[0] ** 2])
    gravity = jnp.stack([-p.theta4 * s1 - p.theta5 * s12, -p.theta5 * s12])  # tau_g
    damping = jnp.stack([p.theta6 * dq[0], p.theta7 * dq[1]])
    return coriolis - gravity + damping


def _energy(p, x):
    q, dq = x[:2], x[2:]
    kinetic = 0.5 * dq @ _mass_matrix(p, q) @ dq
    potential = -p.theta4 * jnp.cos(q[0]) - p.theta5 * jnp.cos(q[0] + q[1])
    return kinetic + potential


class AbstractTwoLink(AbstractManipulator, AbstractLinearInParameters):
    """Shared dynamics of `Acrobot` and `DoublePendulum`, in base parameters theta1..theta7."""

    theta1: Float[Array, ""] = _field("theta1")
    theta2: Float[Array, ""] = _field("theta2")
    theta3: Float[Array, ""] = _field("theta3")
    theta4: Float[Array, ""] = _field("theta4")
    theta5: Float[Array, ""] = _field("theta5")
    theta6: Float[Array, ""] = _field("theta6")
    theta7: Float[Array, ""] = _field("theta7")

    state_names: ClassVar[tuple[str, ...]] = ("q1", "q2", "dq1", "dq2")
    n_joints: ClassVar[int] = 2

    def __check_init__(self):
        for name in BASE_PARAMETER_NAMES:
            if jnp.shape(getattr(self, name)) != ():
                raise ValueError(
                    f"{type(self).__name__}: `{name}` must be a scalar, got shape {jnp.shape(getattr(self, name))}"
                )

    @classmethod
    def from_physical(cls, **physical):
        """Build from physical parameters (see `base_parameters_from_physical`); missing ones take Drake's defaults.

        For example the DFKI lab's rigid-body model (inertias about the pivots):
        `DoublePendulum.from_physical(m1=0.642, m2=0.564, l1=0.2, lc1=0.2, lc2=0.321, I1=0.0267,
        I2=0.0539, b1=0.001, b2=0.001)`.
        """
        allowed = set(DRAKE_DEFAULTS) | {"I1", "I2"}
        unknown = set(physical) - allowed
        if unknown:
            raise UsageError(
                f"{cls.__name__}.from_physical: unknown parameter(s) {sorted(unknown)}; expected {sorted(allowed)}"
            )
        defaults = dict(DRAKE_DEFAULTS)
        for pivot, centre in (("I1", "Ic1"), ("I2", "Ic2")):
            if pivot in physical:
                defaults.pop(centre)
        base = base_parameters_from_physical({**defaults, **physical})
        return cls(**{k: jnp.asarray(v) for k, v in base.items()})

    @classmethod
    def from_base_parameters(cls, parameters: dict[str, ArrayLike]):
        """Build from a dict of base parameters (the contract's `theta1..theta7`); missing ones take Drake's values."""
        unknown = set(parameters) - set(BASE_PARAMETER_NAMES)
        if unknown:
            raise ValueError(f"{cls.__name__}: unknown base parameter(s) {sorted(unknown)}; expected theta1..theta7")
        return cls(**{k: jnp.asarray(v) for k, v in parameters.items()})

    @property
    def base_parameters(self) -> dict[str, Array]:
        """The seven base parameters `theta1..theta7` as a dict."""
        return {k: getattr(self, k) for k in BASE_PARAMETER_NAMES}

    def mass_matrix(self, q):
        return _mass_matrix(self, q)

    def bias_force(self, q, dq):
        return _bias_force(self, q, dq)

    def energy(self, x: Float[Array, " 4"]) -> Float[Array, ""]:
        """Total mechanical energy (zero potential at the pivot height), linear in theta1..theta5."""
        return _energy(self, x)

    # Least-squares identification: the arm is linear in theta1..theta7 and in its joint terms'
    # coefficients; Coulomb friction is a `CoulombFriction` term per joint.

    def check_least_squares(self, terms=()):
        """Accepts the arm with any joint terms (their coefficients are identified too)."""

    def base_parameter_names(self, friction="viscous"):
        """`theta1..theta7`, whatever the friction model (Coulomb friction is a joint term, `fc1`, `fc2`)."""
        return BASE_PARAMETER_NAMES

    def energy_parameter_names(self):
        """`theta1..theta5` (inertia and gravity)."""
        return ENERGY_PARAMETER_NAMES

    def coulomb_friction_terms(self):
        """`CoulombFriction` at every joint, at zero."""
        dtype = jnp.result_type(self.theta1)
        return tuple(CoulombFriction(j, jnp.zeros((), dtype)) for j in range(self.n_joints))

    def base_parameter_kinds(self):
        r"""$\theta_1 \ge \theta_3^2/\theta_2$; $\theta_2, \theta_4, \theta_5 > 0$; $\theta_3, \theta_6, \theta_7 \ge 0$
        (see `dynax.internal.consistency_conditions`)."""
        return dict(
            theta1="inertia1",
            theta2="positive",
            theta3="nonnegative",
            theta4="positive",
            theta5="positive",
            theta6="nonnegative",
            theta7="nonnegative",
        )

    def upright_zero_signs(self):
        r"""$q_1 + \pi$ flips $\sin q_1$ and $\sin(q_1 + q_2)$ ($\theta_4$, $\theta_5$); $q_2 + \pi$ flips
        $\cos q_2$ and $\sin(q_1 + q_2)$ ($\theta_3$, $\theta_5$); both flip $\sin q_1$ and $\cos q_2$
        ($\theta_3$, $\theta_4$). Mass matrix, Coriolis and gravity are otherwise unchanged."""
        return {("q1",): ("theta4", "theta5"), ("q2",): ("theta3", "theta5"), ("q1", "q2"): ("theta3", "theta4")}

    def refinement_terms(self):
        r"""The elbow motor's rotor inertia, `RotorInertia(1)` at zero: with the base parameters it is
        the whole of a geared motor's effect, diagonal and the off-diagonal coupling $-g_r I_r$."""
        return (RotorInertia(1, jnp.zeros((), jnp.result_type(self.theta1))),)

    def mass_check_configurations(self, qs):
        r"""Two configurations: the elbow angles of the smallest and the largest $\cos q_2$ in `qs`.

        $M(q) = A + B\cos q_2$ is affine in $c = \cos q_2$ (constant rotor inertias add to $A$),
        and the smallest eigenvalue of a symmetric matrix affine in $c$ is concave in $c$, so its
        minimum over the data lies at an end of the data's range of $c$. (Built from the range's
        ends by `arccos`, not picked by `argmin`: XLA's CPU argmin over 100,000 samples costs
        more than the whole check.)"""
        c2 = jnp.cos(qs[:, 1])
        ends = jnp.arccos(jnp.clip(jnp.stack([jnp.min(c2), jnp.max(c2)]), -1.0, 1.0))
        return jnp.stack([jnp.zeros_like(ends), ends], axis=1)

    def base_parameter_meanings(self):
        """The groups (rigid-body inertia, gravity, geometry, friction) and meanings of the bounds."""
        rest = "hanging straight down is the stable rest"
        return dict(
            theta2=("rigid-body inertia", "I2, the inertia of link 2 about the elbow"),
            theta3=("geometry", "g theta3 / theta5 is the length of link 1"),
            theta4=("gravity", rest),
            theta5=("gravity", rest),
            theta6=("friction", "viscous, at the shoulder"),
            theta7=("friction", "viscous, at the elbow"),
        )

    def base_parameter_conditions(self, parameters):
        r"""Rigid-body inertia ($\theta_2 > 0$, $\theta_1\theta_2 \ge \theta_3^2$), gravity
        ($\theta_4, \theta_5 > 0$), geometry ($\theta_3 \ge 0$) and viscous friction
        ($\theta_6, \theta_7 \ge 0$, where given): the sign bounds of `base_parameter_kinds`, and the
        Schur complement, which couples three parameters; `theta1..theta5` must be given."""
        t1, t2, t3 = (parameters[f"theta{i}"] for i in range(1, 4))
        out = list(super().base_parameter_conditions(parameters))
        if t2 > 0 and not t1 * t2 >= t3**2:
            out.insert(
                0,
                f"rigid-body inertia: theta1 * theta2 = {t1 * t2:.4g} must be at least theta3^2 = {t3**2:.4g} "
                "(else the mass matrix is singular or indefinite at some elbow angle)",
            )
        return tuple(out)


class Acrobot(AbstractTwoLink):
    r"""The Spong acrobot: two links, only the elbow driven (input `tau2`).

    State `(q1, q2, dq1, dq2)`, input `(tau2,)`. The defaults are Drake's `AcrobotParams`
    (m1 = m2 = 1, l1 = 1, l2 = 2, lc1 = 0.5, lc2 = 1, Ic1 = 0.083, Ic2 = 0.33, b1 = b2 = 0.1,
    g = 9.81). Build from physical parameters with `Acrobot.from_physical(...)`, or pass base
    parameters `theta1..theta7` as keywords.

    ??? cite

        M. W. Spong, "The swing up control problem for the Acrobot", IEEE Control Systems
        Magazine 15(1), 1995; R. Tedrake, *Underactuated Robotics*, ch. 3.
    """

    input_names: ClassVar[tuple[str, ...]] = ("tau2",)

    def input_matrix(self):
        return jnp.array([[0.0], [1.0]], dtype=jnp.result_type(self.theta1))


class DoublePendulum(AbstractTwoLink):
    r"""The two-link arm with both joints driven (inputs `tau1`, `tau2`).

    Same geometry, parameters and defaults as `Acrobot`; the acrobot is this system with
    `tau1 = 0`.
    """

    input_names: ClassVar[tuple[str, ...]] = ("tau1", "tau2")

    def input_matrix(self):
        return jnp.eye(2, dtype=jnp.result_type(self.theta1))
