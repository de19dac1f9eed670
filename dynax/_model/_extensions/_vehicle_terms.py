r"""Model extensions for the helicopter: per-axis quadratic drag, wind, and a body-fixed bias.

They compose with a `Helicopter` through `Extended`, like the joint terms compose with a manipulator:

$$\dot\nu, \dot\omega = \text{body\_model}\big(q, (\nu, \omega), u;\ \text{air} = (\nu - R(q)^\top w, \omega)\big)
    + \sum_k a_k(q, \nu_\text{air}, \omega, u),$$

where $w$ is the sum of the `Wind` terms' world-frame components, the body model's aerodynamic
features see the air-relative velocity (its known part, gravity and $-\omega\times\nu$, the inertial
one), and every other vehicle term adds a body-frame acceleration $a_k$. The position and attitude
kinematics are unchanged. Every term is at its neutral value (zero) the nominal helicopter.

The look-alikes `Wind` and `BodyBias` differ in the frame they are fixed in: a steady wind is fixed
in the world, so the force it causes in the body frame turns with the heading and attitude
($-D\,R(q)^\top w$ for a drag matrix $D$); a body bias (a trim offset, a mis-mounted sensor, a rotor
mast tilt) turns with the body and stays the same on the body axes. Only data with heading or
attitude changes tell them apart.

??? cite

    P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to modeling
    helicopters", NIPS 18, 2005 (the acceleration model these terms extend).
    B. Etkin and L. D. Reid, *Dynamics of Flight: Stability and Control*, 3rd ed., Wiley 1996,
    ch. 4 and 9 (air-relative velocity in a steady wind; aerodynamic forces on the body axes).
"""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._errors import UsageError
from .._helicopter import (
    BODY,
    Helicopter,
    QUATERNION,
    quaternion_to_rotation,
    rigid_body_kinematics,
)
from ._terms import AbstractTerm, float_scalar

WORLD_AXES = ("n", "e", "d")
MULTIROTOR_MOTORS = ("m1", "m2", "m3", "m4")


class AbstractVehicleTerm(AbstractTerm):
    """A term acting on a `Helicopter`'s body-frame accelerations (see the module docs).

    **Fields:** `axis`, the 0-based body axis (`u, v, w, p, q, r`) or, for `Wind`, world axis
    (north, east, down) the coefficient belongs to (static).
    """

    axis: eqx.AbstractVar[int]
    n_axes: ClassVar[int] = 6

    def __check_init__(self):
        if not isinstance(self.axis, int) or not 0 <= self.axis < self.n_axes:
            raise UsageError(f"{type(self).__name__}: `axis` must be an int in [0, {self.n_axes}), got {self.axis!r}")

    def check_system(self, system) -> None:
        if not system.body_axes:
            raise UsageError(
                f"{type(self).__name__} acts on a helicopter's body axes, but {type(system).__name__} is not "
                "a Helicopter"
            )

    def where(self, system) -> str:
        self.check_system(system)
        return system.body_axes[self.axis]

    @staticmethod
    def extended_vector_field(
        system: Helicopter,
        terms: tuple["AbstractVehicleTerm", ...],
        x: Float[Array, " 13"],
        u: Float[Array, " n_inputs"],
        hidden: tuple[Float[Array, " _"], ...] | None = None,
    ) -> Float[Array, " 13"]:
        """The helicopter's vector field with vehicle terms added (see the module docs; used by `Extended`).
        `hidden`: each term's internal states (`AbstractTerm.hidden_names`), in order (default none)."""
        if hidden is None:
            hidden = tuple(x[:0] for _ in terms)
        quat, s = x[QUATERNION], x[BODY]
        wind = sum((t.wind(z) for t, z in zip(terms, hidden, strict=True)), jnp.zeros(3, x.dtype)).astype(x.dtype)
        air = s.at[:3].add(-quaternion_to_rotation(quat).T @ wind)
        dpos, dquat = rigid_body_kinematics(x, system.normalisation_gain)
        dbody = system.body_model(quat, s, u, air=air)
        scaling = tuple((t, z) for t, z in zip(terms, hidden) if t.scales_rotors)
        if scaling:
            # The rotors' part of the body model: what it gives minus what it gives with the motors off.
            idle = u.at[: len(MULTIROTOR_MOTORS)].set(0.0)
            rotors = dbody - system.body_model(quat, s, idle, air=air)
            gain = sum((t.rotor_gain(x, u, z) for t, z in scaling), jnp.zeros((), x.dtype))
            dbody = dbody + gain.astype(x.dtype) * rotors
        for term, z in zip(terms, hidden):
            dbody = dbody + term.acceleration(quat, air, u, z).astype(x.dtype)
        return jnp.concatenate([dpos, dquat, dbody])

    # The term scales the rotors' forces and moments (`rotor_gain`) rather than adding an acceleration.
    scales_rotors: ClassVar[bool] = False

    def rotor_gain(
        self, x: Float[Array, " 13"], u: Float[Array, " n_inputs"], z: Float[Array, " n_hidden"] | None = None
    ) -> Float[Array, ""]:
        r"""The relative change $g$ of every rotor force and moment the term makes: the body model's rotor
        part (its output less its output with the motors off) is multiplied by $1 + \sum g$ (default none).
        `z`: the term's internal states (`hidden_names`), here and in `wind` and `acceleration`."""
        return jnp.zeros((), self.coefficient.dtype)

    def wind(self, z: Float[Array, " n_hidden"] | None = None) -> Float[Array, "3"]:
        """The world-frame wind [m/s] the term contributes (default none)."""
        return jnp.zeros(3, self.coefficient.dtype)

    def acceleration(
        self,
        quat: Float[Array, "4"],
        air: Float[Array, "6"],
        u: Float[Array, " n_inputs"],
        z: Float[Array, " n_hidden"] | None = None,
    ) -> Float[Array, "6"]:
        """The body-frame acceleration `(du, dv, dw, dp, dq, dr)` the term adds, at the air-relative body state
        `air`."""
        return jnp.zeros_like(air)


class BodyQuadraticDrag(AbstractVehicleTerm):
    r"""Quadratic aerodynamic drag $-c\,|\nu_i|\,\nu_i$ on one translational body axis ($u$, $v$ or $w$).

    $\nu_i$ is the air-relative velocity on the axis (the ground velocity in still air); $c$ is per
    unit mass, $\tfrac12 \rho C_D A / m$ [1/m].

    **Arguments:** `axis` (0 `u`, 1 `v`, 2 `w`), `c` [1/m].
    """

    axis: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    n_axes: ClassVar[int] = 3
    cause: ClassVar[str] = "quadratic_drag"
    prefix: ClassVar[str] = "cd"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, axis: int, c: ArrayLike = 0.0):
        self.axis = axis
        self.coefficient = float_scalar(c)

    def acceleration(self, quat, air, u, z=None):
        v = air[self.axis]
        return jnp.zeros_like(air).at[self.axis].set(-self.coefficient * jnp.abs(v) * v)


class BodyBias(AbstractVehicleTerm):
    r"""A constant force or moment fixed in the body frame: $b$ added to one body axis' acceleration.

    On `u, v, w` a specific force [m/s^2] (a rotor mast tilt, a trim offset), on `p, q, r` an
    angular acceleration [rad/s^2] (an unbalanced moment). It turns with the body, unlike `Wind`.

    **Arguments:** `axis` (0..5 for `u, v, w, p, q, r`), `b`.
    """

    axis: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "body_bias"
    prefix: ClassVar[str] = "bias"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, axis: int, b: ArrayLike = 0.0):
        self.axis = axis
        self.coefficient = float_scalar(b)

    def acceleration(self, quat, air, u, z=None):
        return jnp.zeros_like(air).at[self.axis].set(self.coefficient)


class RotorDrag(AbstractVehicleTerm):
    r"""Rotor drag: a body-frame force or moment linear in the velocity on one body axis, $-d\,s_i$.

    A spinning rotor moving edgewise through the air tilts its thrust back (blade flapping) and
    its advancing blade meets more air than the retreating one: the net in-plane force opposes
    the body velocity and is, to first order, proportional to it (the "rotor drag" of multirotor
    models, a diagonal $-D\nu$). A body rotating about a horizontal axis moves one rotor up and the
    other down through the air, which raises the thrust of the one and lowers the other's: a moment
    opposing the rate, to first order proportional to it (the rotors' damping of rotation, $-D_\omega
    \omega$; about the vertical axis the rotors' drag torque does the same). On `u, v, w`, $s_i$ is the
    air-relative velocity and $d$ is per unit mass [1/s]; on `p, q, r`, $s_i$ is the body rate and $d$ per
    unit inertia [1/s]. On a helicopter it adds to a learned derivative (`Xu`, ..., `Lp`, ...); on a
    quadrotor's rigid-body model, which has none, it is the drag the rigid body lacks.

    **Arguments:** `axis` (0..5 for `u, v, w, p, q, r`), `d` [1/s].

    ??? cite

        R. Mahony, V. Kumar and P. Corke, "Multirotor aerial vehicles: modeling, estimation, and
        control of quadrotor", IEEE Robotics & Automation Magazine 19(3), 2012 (rotor drag).
    """

    axis: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "rotor_drag"
    prefix: ClassVar[str] = "drag"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, axis: int, d: ArrayLike = 0.0):
        self.axis = axis
        self.coefficient = float_scalar(d)

    def acceleration(self, quat, air, u, z=None):
        return jnp.zeros_like(air).at[self.axis].set(-self.coefficient * air[self.axis])


class PlanarRotorDrag(RotorDrag):
    r"""Rotor drag in the rotor plane: one coefficient on both horizontal body axes, $-d\,(u, v)$.

    The rotors of a multirotor turn in its body's $x$-$y$ plane, and the drag that blade flapping and the
    advancing blade make is, to first order, the body velocity in that plane times a drag matrix
    (Faessler, Franchi and Scaramuzza 2018: $D = \mathrm{diag}(d_x, d_y, d_z)$); a vehicle symmetric in
    $x$ and $y$ (an X or + quadrotor) has $d_x = d_y$ (Förster 2015 measures 9.2e-7 and 9.2e-7 kg/rad on the
    Crazyflie 2.0 (10.3e-7 on $z$)). A motion that mixes forward and sideways flight shows this drag on both
    axes at once, each of which alone explains only its part: the term tests them as one cause, named
    `rotor_drag` at `u+v` (its coefficient `drag_uv`, per unit mass [1/s]).

    **Arguments:** `d` [1/s].

    ??? cite

        M. Faessler, A. Franchi and D. Scaramuzza, "Differential flatness of quadrotor dynamics subject to
        rotor drag for accurate tracking of high-speed trajectories", IEEE Robotics and Automation Letters
        3(2), 2018. J. Förster, "System identification of the Crazyflie 2.0 nano quadrocopter", ETH Zurich
        bachelor's thesis, 2015.
    """

    def __init__(self, d: ArrayLike = 0.0):
        super().__init__(0, d)  # `axis` 0: the data-based scale of a candidate reads the `u` axis

    def where(self, system) -> str:
        self.check_system(system)
        return "u+v"

    def parameter_name(self, system) -> str:
        """`drag_uv`."""
        self.check_system(system)
        return f"{self.prefix}_uv"

    def acceleration(self, quat, air, u, z=None):
        return jnp.zeros_like(air).at[:2].set(-self.coefficient * air[:2])


class Wind(AbstractVehicleTerm):
    r"""One world-frame component of a steady wind: the air moves at $w$ in the world (NED) frame.

    The body model's aerodynamic features (and `BodyQuadraticDrag`) act on the air-relative
    body velocity $\nu - R(q)^\top w$; the kinematics use the ground velocity. Its effect on the
    body axes turns with the attitude, which tells it apart from a `BodyBias`. A wind with several
    components is several `Wind` terms (`Wind(0, 3.0), Wind(1, -1.0)`); their `where` is `world`.

    **Arguments:** `axis` (0 north, 1 east, 2 down), `speed` [m/s].
    """

    axis: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    n_axes: ClassVar[int] = 3
    cause: ClassVar[str] = "wind"
    prefix: ClassVar[str] = "wind"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, axis: int, speed: ArrayLike = 0.0):
        self.axis = axis
        self.coefficient = float_scalar(speed)

    def where(self, system) -> str:
        super().where(system)  # checks the system
        return "world"

    def parameter_name(self, system) -> str:
        """`wind_n`, `wind_e` or `wind_d`."""
        return f"{self.prefix}_{WORLD_AXES[self.axis]}"

    def wind(self, z=None):
        return jnp.zeros(3, self.coefficient.dtype).at[self.axis].set(self.coefficient)


class _AbstractRotorTerm(AbstractVehicleTerm):
    """A term on a multirotor's rotors (inputs `m1..m4` first): it scales their forces and moments."""

    scales_rotors: ClassVar[bool] = True
    n_axes: ClassVar[int] = 1

    def check_system(self, system) -> None:
        super().check_system(system)
        if tuple(system.input_names[:4]) != MULTIROTOR_MOTORS:
            raise UsageError(
                f"{type(self).__name__} acts on a multirotor's rotors (inputs m1..m4), but "
                f"{type(system).__name__}'s inputs are {tuple(system.input_names)}"
            )


class BatterySag(_AbstractRotorTerm):
    r"""Battery sag: the rotors' thrust and moments per command change with the battery voltage.

    A brushed or an ESC-driven motor turns at a speed about proportional to the voltage across it,
    the command times the battery voltage $v_b$, and a rotor's thrust and drag torque grow like the
    square of its speed: at one command the thrust falls as the battery discharges (about
    $(v_b / \bar v_b)^2$). A model whose motor map does not read `vbat` carries this as a thrust
    error that drifts over the flight. The term multiplies the model's rotor forces and moments by
    $1 + s\,(v_b / \bar v_b - 1)$, $\bar v_b$ the model's scale of `vbat` (the training flights'
    median, `Quadrotor.input_scale`): $s = 2$ for a model that ignores the voltage, $s = 0$ for one
    that has the square law already. Needs `vbat` among the inputs (the fifth).

    **Arguments:** `s`, the exponent's linear part (dimensionless).

    ??? cite

        M. Bangura and R. Mahony, "Thrust control for multirotor aerial vehicles", IEEE Transactions
        on Robotics 33(2), 2017 (rotor speed, battery voltage and thrust).
    """

    axis: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "battery_sag"
    prefix: ClassVar[str] = "sag"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, s: ArrayLike = 0.0):
        self.axis = 0
        self.coefficient = float_scalar(s)

    def check_system(self, system) -> None:
        super().check_system(system)
        if len(system.input_names) < 5 or system.input_names[4] != "vbat":
            raise UsageError(f"BatterySag needs `vbat` as the fifth input; {type(system).__name__} has none")

    def where(self, system) -> str:
        self.check_system(system)
        return "vbat"

    def rotor_gain(self, x, u, z=None):
        return self.coefficient * (u[4] - 1.0)


class GroundEffect(_AbstractRotorTerm):
    r"""Ground effect: the rotors' thrust rises near the floor.

    A rotor at a height $z$ of a few radii $R$ over the ground pushes against its own wake: at one
    rotor speed its thrust is $T/(1 - (R/4z)^2)$ of the thrust far from the ground (Cheeseman and
    Bennett's image-rotor model). The term multiplies the rotor forces and moments by that law,
    $1/(1 - r)$ with $r = c / (h + h_0)^2$, $h$ the vehicle's height over `floor` (world `z` up, as
    motion capture logs it) and $h_0$ the rotor plane's height over the floor when the vehicle stands
    on it; $c$ [m^2] is $R^2 / 16$. The image-rotor model holds down to about one rotor radius; $r$ is
    held at 3/4 at most (four times the thrust), where the law itself has long stopped holding, so
    that a fit cannot cross its pole.

    **Arguments:** `c` [m^2]; `floor`, the floor's height in the records' frame [m] (the rest height
    of the vehicle with its motors off); `rotor_height` $h_0$ [m] (default 0.02, a nano quadrotor's).

    ??? cite

        I. C. Cheeseman and W. E. Bennett, "The effect of the ground on a helicopter rotor in forward
        flight", Aeronautical Research Council R&M 3021, 1955.
    """

    axis: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    # Settings held as arrays (set from the data without recompiling); not fitted.
    floor: Float[Array, ""]
    rotor_height: Float[Array, ""]
    cause: ClassVar[str] = "ground_effect"
    prefix: ClassVar[str] = "ground"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1

    def __init__(self, c: ArrayLike = 0.0, *, floor: ArrayLike = 0.0, rotor_height: ArrayLike = 0.02):
        if isinstance(rotor_height, (int, float)) and not rotor_height > 0:
            raise UsageError(f"GroundEffect: `rotor_height` must be positive, got {rotor_height}")
        self.axis = 0
        self.coefficient = float_scalar(c)
        self.floor = float_scalar(floor)
        self.rotor_height = float_scalar(rotor_height)

    def parameter_filter(self):
        return eqx.tree_at(lambda t: (t.floor, t.rotor_height), super().parameter_filter(), (False, False))

    def where(self, system) -> str:
        self.check_system(system)
        return "z"

    def rotor_gain(self, x, u, z=None):
        height = jnp.maximum(x[2] - self.floor, 0.0) + self.rotor_height
        ratio = jnp.minimum(self.coefficient / height**2, 0.75)
        return ratio / (1.0 - ratio)
