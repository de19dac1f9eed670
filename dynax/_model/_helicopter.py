r"""`Helicopter`: 6-DOF rigid-body kinematics with a pluggable, learnable body-frame model.

State (the data contract's order) `x, y, z, qw, qx, qy, qz, u, v, w, p, q, r`:

- $(x, y, z)$ world position in a north-east-down (NED) frame, $z$ down [m];
- $(q_w, q_x, q_y, q_z)$ the unit quaternion rotating body vectors into the world frame,
  $v_\text{world} = R(q)\, v_\text{body}$ (Hamilton convention);
- $(u, v, w)$ body-frame velocity (forward, right, down) [m/s];
- $(p, q, r)$ body-frame angular rates (roll, pitch, yaw) [rad/s].

Inputs `u1, u2, u3, u4` in $[-1, 1]$: roll cyclic, pitch cyclic, tail rotor, collective.

The kinematics are exact and never learned:

$$\dot{\mathbf p} = R(q)\,\nu,\qquad \dot q = \tfrac12\, q \otimes (0, \omega),$$

where $\nu = (u, v, w)$ and $\omega = (p, q, r)$. A *body model* gives $(\dot\nu, \dot\omega)$. Every body
model here is linear in its parameters:

$$(\dot\nu, \dot\omega) = k(q, \nu, \omega, u) + (W \odot M)\, \phi(q, \nu, \omega, u),$$

with a known part $k$, a feature vector $\phi$, a weight matrix $W$ (6 rows, one per body axis) and a
fixed 0/1 mask $M$ choosing which features each axis uses. The learning criteria in
`dynax._identify._vehicle` fit `W[M]`.

- `AccelerationModel` (Abbeel, Ganapathi and Ng 2005): the features predict body-frame
  *accelerations*; gravity $R(q)^\top g$ and the rotating-frame term $-\omega\times\nu$ are the known
  part, from physics. `AccelerationModel.tempest()` is the published XCell Tempest hover model.
- `LinearVelocityModel` (the linear models of prior work): $(\dot\nu,\dot\omega)$ linear in the
  velocities, rates, roll and pitch angles and inputs; no known part, so gravity and frame rotation
  must be absorbed, linearly, by the weights.

??? cite "Reference"

    P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to modeling
    helicopters", NIPS 18, 2005.
"""

from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float
import numpy as np

from ._system import AbstractSystem

HELICOPTER_STATE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz", "u", "v", "w", "p", "q", "r")
HELICOPTER_INPUT_NAMES = ("u1", "u2", "u3", "u4")
BODY_AXES = ("u", "v", "w", "p", "q", "r")
STANDARD_GRAVITY = 9.81

# Slices of the 13-state vector.
POSITION = slice(0, 3)
QUATERNION = slice(3, 7)
VELOCITY = slice(7, 10)
ANGULAR_RATE = slice(10, 13)
BODY = slice(7, 13)


# --------------------------------------------------------------------------------------------------
# Quaternions (Hamilton convention, scalar first).


def quaternion_to_rotation(quat: Float[Array, "4"]) -> Float[Array, "3 3"]:
    r"""The rotation matrix $R(q)$ of a (not necessarily normalised) quaternion $(q_w, q_x, q_y, q_z)$.

    $R(q)$ maps body-frame vectors to the world frame. The quaternion is normalised first.
    """
    quat = quat / jnp.linalg.norm(quat)
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    return jnp.stack(
        [
            jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
            jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
            jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
        ]
    )


def quaternion_multiply(a: Float[Array, "4"], b: Float[Array, "4"]) -> Float[Array, "4"]:
    r"""The Hamilton product $a \otimes b$ (scalar first)."""
    aw, av = a[0], a[1:]
    bw, bv = b[0], b[1:]
    return jnp.concatenate([(aw * bw - av @ bv)[None], aw * bv + bw * av + jnp.cross(av, bv)])


def quaternion_conjugate(quat: Float[Array, "4"]) -> Float[Array, "4"]:
    """The conjugate (the inverse of a unit quaternion)."""
    return quat * jnp.array([1.0, -1.0, -1.0, -1.0], quat.dtype)


def quaternion_angle(a: Float[Array, "4"], b: Float[Array, "4"]) -> Float[Array, ""]:
    r"""The rotation angle in $[0, \pi]$ between the attitudes $a$ and $b$ (unit quaternions).

    $2\arccos|\langle a, b\rangle|$, computed as $2\,\mathrm{atan2}(\|\cdot\|, |\cdot|)$ of the relative
    quaternion for accuracy near zero. Sign-invariant: $q$ and $-q$ are the same attitude.
    """
    a = a / jnp.linalg.norm(a)
    b = b / jnp.linalg.norm(b)
    rel = quaternion_multiply(quaternion_conjugate(a), b)
    return 2 * jnp.arctan2(jnp.linalg.norm(rel[1:]), jnp.abs(rel[0]))


def quaternion_from_euler(roll, pitch, yaw) -> Float[Array, "4"]:
    """The body-to-world quaternion of Z-Y-X (yaw, pitch, roll) Euler angles [rad]."""
    cr, sr = jnp.cos(roll / 2), jnp.sin(roll / 2)
    cp, sp = jnp.cos(pitch / 2), jnp.sin(pitch / 2)
    cy, sy = jnp.cos(yaw / 2), jnp.sin(yaw / 2)
    return jnp.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def euler_from_quaternion(quat: Float[Array, "4"]) -> Float[Array, "3"]:
    """Z-Y-X Euler angles `(roll, pitch, yaw)` [rad] of a body-to-world quaternion."""
    quat = quat / jnp.linalg.norm(quat)
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    roll = jnp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jnp.arcsin(jnp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = jnp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return jnp.stack([roll, pitch, yaw])


def rigid_body_kinematics(
    x: Float[Array, " 13"], normalisation_gain: float = 1.0
) -> tuple[Float[Array, "3"], Float[Array, "4"]]:
    r"""Position and quaternion derivatives: $\dot{\mathbf p} = R(q)\nu$, $\dot q = \frac12 q\otimes(0,\omega)$.

    A Baumgarte term $\lambda (1 - \|q\|^2) q$ (gain `normalisation_gain` [1/s]) holds the quaternion
    on the unit sphere against integration drift; it vanishes on exact solutions.
    """
    quat = x[QUATERNION]
    omega = x[ANGULAR_RATE]
    dpos = quaternion_to_rotation(quat) @ x[VELOCITY]
    dquat = 0.5 * quaternion_multiply(quat, jnp.concatenate([jnp.zeros((1,), x.dtype), omega]))
    dquat = dquat + normalisation_gain * (1 - quat @ quat) * quat
    return dpos, dquat


# --------------------------------------------------------------------------------------------------
# Features.


def _abs_times(i):
    return lambda quat, s, u: jnp.abs(s[i]) * s[i]


def _euler(i):
    return lambda quat, s, u: euler_from_quaternion(quat)[i]


def _motor(i):
    return lambda quat, s, u: u[i]


def _motor_squared(i):
    return lambda quat, s, u: u[i] ** 2


def _battery_motor(i):
    return lambda quat, s, u: u[4] * u[i]


def _battery_motor_squared(i):
    return lambda quat, s, u: (u[4] * u[i]) ** 2


def _rotor_drag(i):
    return lambda quat, s, u: s[i] * jnp.sum(u[:4])


FeatureFunction = Callable[[Array, Array, Array], Array]

#: The feature library: name -> function of (quaternion, body state (u, v, w, p, q, r), inputs).
FEATURES: dict[str, FeatureFunction] = {
    **{name: (lambda i: lambda quat, s, u: s[i])(i) for i, name in enumerate(BODY_AXES)},
    **{name: (lambda i: lambda quat, s, u: u[i])(i) for i, name in enumerate(HELICOPTER_INPUT_NAMES)},
    "1": lambda quat, s, u: jnp.ones((), s.dtype),
    "|u|u": _abs_times(0),
    "|v|v": _abs_times(1),
    "|w|w": _abs_times(2),
    "qr": lambda quat, s, u: s[4] * s[5],
    "pr": lambda quat, s, u: s[3] * s[5],
    "pq": lambda quat, s, u: s[3] * s[4],
    "roll": _euler(0),
    "pitch": _euler(1),
    # Multirotor motor inputs `m1..m4` (normalised, see `dynax.Quadrotor`) and the battery voltage
    # `vbat` (the fifth input): rotor thrust and torque grow like the square of rotor speed, and a
    # brushed motor's speed like the voltage across it (command times battery voltage).
    **{f"m{i + 1}": _motor(i) for i in range(4)},
    **{f"m{i + 1}^2": _motor_squared(i) for i in range(4)},
    **{f"vbat m{i + 1}": _battery_motor(i) for i in range(4)},
    **{f"(vbat m{i + 1})^2": _battery_motor_squared(i) for i in range(4)},
    # Rotor drag: a force against the body velocity that grows with rotor speed (blade flapping
    # and induced drag), linear in velocity times the summed motor inputs.
    **{f"{c} sum(m)": _rotor_drag(i) for i, c in enumerate(BODY_AXES[:3])},
}


def _check_features(cls, feature_names, mask, weights):
    unknown = [f for f in feature_names if f not in FEATURES]
    if unknown:
        raise ValueError(f"{cls}: unknown features {unknown}; known: {sorted(FEATURES)}")
    if len(mask) != 6 or any(len(row) != len(feature_names) for row in mask):
        raise ValueError(f"{cls}: `mask` must be 6 rows (axes {BODY_AXES}) of {len(feature_names)} booleans")
    if weights.shape != (6, len(feature_names)):
        raise ValueError(f"{cls}: `weights` must have shape (6, {len(feature_names)}), got {weights.shape}")


class AbstractBodyModel(eqx.Module):
    r"""A body-frame model $(\dot\nu, \dot\omega) = k + (W\odot M)\,\phi$, linear in the weights $W$.

    Concrete models give the known part `known(quat, s, u)` and fix the feature names; the
    learning criteria fit the masked weights `W[M]` (see `parameter_vector`).
    """

    weights: eqx.AbstractVar[Float[Array, "6 n_features"]]
    feature_names: eqx.AbstractVar[tuple[str, ...]]
    mask: eqx.AbstractVar[tuple[tuple[bool, ...], ...]]
    # The contract's name of the model (`MODEL.json`'s "model", the CLI's `--model`).
    kind: eqx.AbstractClassVar[str]

    def known(self, quat: Float[Array, "4"], s: Float[Array, "6"], u: Float[Array, " n_inputs"]) -> Float[Array, "6"]:
        """The part of $(\\dot\\nu, \\dot\\omega)$ fixed by physics (zero unless overridden)."""
        return jnp.zeros_like(s)

    def features(
        self, quat: Float[Array, "4"], s: Float[Array, "6"], u: Float[Array, " n_inputs"]
    ) -> Float[Array, " n_features"]:
        r"""The feature vector $\phi(q, \nu, \omega, u)$, ordered as `feature_names`."""
        return jnp.stack([FEATURES[name](quat, s, u).astype(s.dtype) for name in self.feature_names])

    def masked_weights(self) -> Float[Array, "6 n_features"]:
        return self.weights * jnp.asarray(np.asarray(self.mask, dtype=float), self.weights.dtype)

    def __call__(self, quat, s, u, air=None) -> Float[Array, "6"]:
        r"""$(\dot\nu, \dot\omega)$ at body state `s = (u, v, w, p, q, r)`, attitude `quat` and inputs `u`.

        `air` (optional, default `s`) is the body state relative to the air, $(\nu - R(q)^\top
        w_\text{world}, \omega)$ in a wind $w_\text{world}$: the learned (aerodynamic) features are
        evaluated at it, the known part (gravity, the rotating-frame term) at the inertial `s`.
        """
        air = s if air is None else air
        return self.known(quat, s, u) + self.masked_weights() @ self.features(quat, air, u)

    # Parameter bookkeeping for the learning criteria.

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names `d<axis>/<feature>` of the free weights, in `parameter_vector` order (row-major)."""
        return tuple(
            f"d{axis}/{name}"
            for axis, row in zip(BODY_AXES, self.mask)
            for name, used in zip(self.feature_names, row)
            if used
        )

    def parameter_vector(self) -> Float[Array, " n_parameters"]:
        """The free weights `W[M]`, row-major."""
        return self.weights[np.asarray(self.mask, dtype=bool)]

    def with_parameter_vector(self, theta: Float[Array, " n_parameters"]) -> "AbstractBodyModel":
        """A copy with the free weights replaced by `theta` (masked-out weights are zero)."""
        index = np.nonzero(np.asarray(self.mask, dtype=bool))
        weights = jnp.zeros(self.weights.shape, jnp.result_type(theta)).at[index].set(theta)
        return eqx.tree_at(lambda m: m.weights, self, weights)

    @property
    def parameters(self) -> dict[str, Array]:
        """The free weights as a dict keyed by `parameter_names`."""
        return dict(zip(self.parameter_names, self.parameter_vector()))


def _mask_from_axes(feature_names, axes: dict[str, tuple[str, ...]]):
    return tuple(tuple(name in axes.get(axis, ()) for name in feature_names) for axis in BODY_AXES)


# The published XCell Tempest hover model (Abbeel, Ganapathi and Ng 2005, Section 5).
TEMPEST_COEFFICIENTS = dict(
    Ax=-0.18, Ay=-0.43, Az=-0.49, Bx=-12.78, By=-10.12, Bz=-8.16, C1=33.04, C2=-33.32, C3=70.54, C4=-42.15, Dv=-0.54
)
TEMPEST_FEATURES: dict[str, tuple[str, ...]] = {
    "u": ("u",),
    "v": ("v", "1"),
    "w": ("w", "u4"),
    "p": ("p", "u1"),
    "q": ("q", "u2"),
    "r": ("r", "u3"),
}
#: A richer feature set: a bias on every axis, quadratic drag, rotor-tilt couplings (rates and
#: cyclic on the translational axes, velocities on the rates), the rotor-torque coupling of the
#: collective and the tail, weathercock stability (v on r) and the gyroscopic products on the rates.
RICH_FEATURES: dict[str, tuple[str, ...]] = {
    "u": ("u", "|u|u", "q", "u2", "u4", "1"),
    "v": ("v", "|v|v", "p", "r", "u1", "u3", "u4", "1"),
    "w": ("w", "|w|w", "u4", "1"),
    "p": ("p", "v", "r", "u1", "u3", "u4", "qr", "1"),
    "q": ("q", "u", "u2", "pr", "1"),
    "r": ("r", "v", "w", "u3", "u4", "pq", "1"),
}
ACCELERATION_FEATURE_NAMES = (
    "u",
    "v",
    "w",
    "p",
    "q",
    "r",
    "u1",
    "u2",
    "u3",
    "u4",
    "1",
    "|u|u",
    "|v|v",
    "|w|w",
    "qr",
    "pr",
    "pq",
)
LINEAR_FEATURE_NAMES = ("u", "v", "w", "p", "q", "r", "roll", "pitch", "u1", "u2", "u3", "u4", "1")


def _tempest_weights(dtype=None):
    c = TEMPEST_COEFFICIENTS
    names = ACCELERATION_FEATURE_NAMES
    w = np.zeros((6, len(names)))
    entries = {
        ("u", "u"): c["Ax"],
        ("v", "v"): c["Ay"],
        ("v", "1"): c["Dv"],
        ("w", "w"): c["Az"],
        ("w", "u4"): c["C4"],
        ("p", "p"): c["Bx"],
        ("p", "u1"): c["C1"],
        ("q", "q"): c["By"],
        ("q", "u2"): c["C2"],
        ("r", "r"): c["Bz"],
        ("r", "u3"): c["C3"],
    }
    for (axis, name), value in entries.items():
        w[BODY_AXES.index(axis), names.index(name)] = value
    return jnp.asarray(w, dtype)


class AccelerationModel(AbstractBodyModel):
    r"""The acceleration model: body-frame accelerations linear in a few features per axis.

    $$\dot\nu = -\omega\times\nu + R(q)^\top g + W_\nu\phi,\qquad \dot\omega = W_\omega\phi,$$

    with $g = (0, 0, g)$ in NED. Gravity is rotated in exactly and the rotating-frame term is
    physics, so the learned part only describes aerodynamic and rotor forces and moments per unit
    mass and inertia. `AccelerationModel.tempest()` (the default) is the published XCell Tempest
    hover model: $\dot u = A_x u$, $\dot v = A_y v + D_v$, $\dot w = A_z w + C_4 u_4$,
    $\dot p = B_x p + C_1 u_1$, $\dot q = B_y q + C_2 u_2$, $\dot r = B_z r + C_3 u_3$ (plus gravity
    and $-\omega\times\nu$). `AccelerationModel.with_features(RICH_FEATURES)` adds biases, quadratic
    drag, cross-couplings and gyroscopic products.

    **Fields:**

    - `weights`: $W$, shape `(6, n_features)`; rows are the axes `u, v, w, p, q, r`.
    - `feature_names`: the features (keys of `FEATURES`), static.
    - `mask`: which weights are free, 6 rows of booleans, static.
    - `gravity`: $g$ [m/s^2].

    ??? cite "Reference"

        P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
        modeling helicopters", NIPS 18, 2005.
    """

    weights: Float[Array, "6 n_features"] = eqx.field(default_factory=_tempest_weights)
    feature_names: tuple[str, ...] = eqx.field(static=True, default=ACCELERATION_FEATURE_NAMES)
    mask: tuple[tuple[bool, ...], ...] = eqx.field(
        static=True, default=_mask_from_axes(ACCELERATION_FEATURE_NAMES, TEMPEST_FEATURES)
    )
    gravity: float = eqx.field(static=True, default=STANDARD_GRAVITY)
    kind: ClassVar[str] = "acceleration"

    def __check_init__(self):
        _check_features("AccelerationModel", self.feature_names, self.mask, self.weights)

    @classmethod
    def tempest(cls) -> "AccelerationModel":
        """The published XCell Tempest hover model (the default)."""
        return cls()

    @classmethod
    def with_features(cls, axes: dict[str, tuple[str, ...]], weights=None) -> "AccelerationModel":
        """An acceleration model using, per body axis, the named features (zero weights by default)."""
        names = tuple(dict.fromkeys(name for axis in BODY_AXES for name in axes.get(axis, ())))
        if weights is None:
            weights = jnp.zeros((6, len(names)))
        return cls(weights=weights, feature_names=names, mask=_mask_from_axes(names, axes))

    def known(self, quat, s, u):
        nu, omega = s[:3], s[3:]
        g_body = quaternion_to_rotation(quat).T @ jnp.array([0.0, 0.0, self.gravity], s.dtype)
        return jnp.concatenate([-jnp.cross(omega, nu) + g_body, jnp.zeros(3, s.dtype)])


class LinearVelocityModel(AbstractBodyModel):
    r"""The linear model of prior work: $(\dot\nu, \dot\omega) = W\,(\nu, \omega, \phi_r, \theta_p, u, 1)$.

    Body velocities and rates evolve linearly in themselves, the roll and pitch angles
    $\phi_r, \theta_p$ (Z-Y-X Euler angles of the attitude) and the inputs, with a constant. Gravity
    and the rotating-frame terms are not modelled: their hover linearisation
    ($\dot u \approx -g\theta_p$, $\dot v \approx g\phi_r$) is left to the weights. Position and
    orientation are integrated exactly from the predicted velocities and rates. Fitted one step
    ahead, this is the regression of the next-step velocities on the present state and inputs.

    **Fields:** `weights` (shape `(6, 13)`), `feature_names`, `mask` (all free by default).

    ??? cite "Reference"

        B. Mettler, M. B. Tischler and T. Kanade, "System identification modeling of a small-scale
        unmanned rotorcraft for flight control design", Journal of the American Helicopter
        Society 47(1), 2002.
    """

    weights: Float[Array, "6 n_features"] = eqx.field(default_factory=lambda: _linear_hover_weights())
    feature_names: tuple[str, ...] = eqx.field(static=True, default=LINEAR_FEATURE_NAMES)
    mask: tuple[tuple[bool, ...], ...] = eqx.field(
        static=True, default=tuple(tuple(True for _ in LINEAR_FEATURE_NAMES) for _ in BODY_AXES)
    )
    kind: ClassVar[str] = "linear"

    def __check_init__(self):
        _check_features("LinearVelocityModel", self.feature_names, self.mask, self.weights)


def _linear_hover_weights():
    """The Tempest model linearised about level hover: a sensible starting point."""
    c = TEMPEST_COEFFICIENTS
    names = LINEAR_FEATURE_NAMES
    g = STANDARD_GRAVITY
    w = np.zeros((6, len(names)))
    entries = {
        ("u", "u"): c["Ax"],
        ("u", "pitch"): -g,
        ("v", "v"): c["Ay"],
        ("v", "roll"): g,
        ("v", "1"): c["Dv"],
        ("w", "w"): c["Az"],
        ("w", "u4"): c["C4"],
        ("w", "1"): g,
        ("p", "p"): c["Bx"],
        ("p", "u1"): c["C1"],
        ("q", "q"): c["By"],
        ("q", "u2"): c["C2"],
        ("r", "r"): c["Bz"],
        ("r", "u3"): c["C3"],
    }
    for (axis, name), value in entries.items():
        w[BODY_AXES.index(axis), names.index(name)] = value
    return jnp.asarray(w)


class Helicopter(AbstractSystem):
    r"""A helicopter: exact 6-DOF rigid-body kinematics and a learnable body-frame model.

    $$\dot{\mathbf p} = R(q)\nu,\quad \dot q = \tfrac12 q\otimes(0,\omega),\quad
    (\dot\nu, \dot\omega) = \text{body\_model}(q, \nu, \omega, u).$$

    State `x, y, z, qw, qx, qy, qz, u, v, w, p, q, r` (NED world position, body-to-world unit
    quaternion, body velocity, body rates), inputs `u1..u4` (roll cyclic, pitch cyclic, tail rotor,
    collective, normalised to $[-1, 1]$).

    **Fields:**

    - `body_model`: an `AccelerationModel` (default: the XCell Tempest hover model) or a
      `LinearVelocityModel`.
    - `normalisation_gain`: the gain [1/s] of the term holding the quaternion at unit norm (static).

    **Example:**

    ```python
    heli = dynax.Helicopter()                                 # Tempest acceleration model
    linear = dynax.Helicopter(dynax.LinearVelocityModel())    # linear velocity model
    ```
    """

    body_model: AbstractBodyModel = eqx.field(default_factory=AccelerationModel)
    normalisation_gain: float = eqx.field(static=True, default=1.0)

    state_names: ClassVar[tuple[str, ...]] = HELICOPTER_STATE_NAMES
    input_names: ClassVar[tuple[str, ...]] = HELICOPTER_INPUT_NAMES

    def __check_init__(self):
        if not isinstance(self.body_model, AbstractBodyModel):
            raise ValueError(
                f"Helicopter: `body_model` must be an AccelerationModel or LinearVelocityModel, "
                f"got {type(self.body_model).__name__}"
            )

    def parameter_filter(self):
        """The body model's free weights (its feature `mask`); gravity and the frame are physics."""
        spec = jax.tree.map(lambda _: False, self)
        return eqx.tree_at(lambda h: h.body_model.weights, spec, np.asarray(self.body_model.mask, dtype=bool))

    def parameter_labels(self) -> tuple[str, ...]:
        return tuple(self.body_model.parameter_names)

    # The vehicle protocol the vehicle criteria (`OneStep`, `Lagged`, ...) fit through: the system in
    # body-frame coordinates, a record in them, and the system with a fitted body model.
    def as_helicopter(self) -> "Helicopter":
        """The form the vehicle criteria fit: the helicopter itself (`Quadrotor.as_helicopter`)."""
        return self

    def body_frame(self, record):
        """A record in the coordinates `as_helicopter()` is fitted in: a helicopter's record as it is."""
        return record

    def with_body_model(self, body_model: AbstractBodyModel) -> "Helicopter":
        """The same helicopter with `body_model` (a fitted one)."""
        return eqx.tree_at(lambda h: h.body_model, self, body_model)

    def state_error(self, simulated, measured):
        """Simulated minus measured, with the simulated quaternion taken on the measured one's
        hemisphere: $q$ and $-q$ are one attitude."""
        quat = simulated[..., QUATERNION]
        sign = jnp.where(jnp.sum(quat * measured[..., QUATERNION], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        return simulated.at[..., QUATERNION].set(sign * quat) - measured

    @property
    def position_indices(self) -> tuple[int, ...]:
        return (0, 1, 2)  # world position x, y, z [m]

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        return tuple(range(BODY.start, BODY.stop))  # body velocities and rates u, v, w, p, q, r

    @property
    def body_axes(self) -> tuple[str, ...]:
        return BODY_AXES

    def residual_features(self, xs, accelerations):
        """Body velocities and rates with their signs and squares and the model's accelerations, and
        the world's axes seen in the body frame (gravity's direction, and north and east: what a
        world-fixed effect such as wind turns with)."""
        names, cols = [], []
        rotations = np.asarray(jax.vmap(quaternion_to_rotation)(jnp.asarray(xs[:, QUATERNION])))
        for i, c in zip(range(BODY.start, BODY.stop), BODY_AXES):
            x = xs[:, i]
            cols += [
                x,
                np.abs(x) * x,
                np.tanh(x / max(0.05 * float(np.std(x)), 1e-6)),
                accelerations[:, i - BODY.start],
            ]
            names += [c, f"|{c}|{c}", f"sign({c})", f"model acceleration d{c}/dt"]
        for a, world in enumerate(("north", "east", "down")):
            for b, body in enumerate(("u", "v", "w")):
                cols.append(rotations[:, a, b])
                names.append(f"{world} on body {body}")
        return cols, names

    def vector_field(self, t, x, u):
        dpos, dquat = rigid_body_kinematics(x, self.normalisation_gain)
        dbody = self.body_model(x[QUATERNION], x[BODY], u)
        return jnp.concatenate([dpos, dquat, dbody])


def hover_state(position: Float[ArrayLike, "3"] = (0.0, 0.0, 0.0), yaw: float = 0.0, dtype=None) -> Float[Array, " 13"]:
    """A state at rest at `position` (NED) with level attitude and heading `yaw` [rad]."""
    dtype = jnp.result_type(float) if dtype is None else dtype
    quat = quaternion_from_euler(jnp.asarray(0.0, dtype), jnp.asarray(0.0, dtype), jnp.asarray(yaw, dtype))
    return jnp.concatenate([jnp.asarray(position, dtype), quat, jnp.zeros(6, dtype)])
