r"""`Quadrotor`: a multirotor's 6-DOF rigid body with the helicopter's learnable body-frame model.

State (the data contract's order) `x, y, z, qw, qx, qy, qz, vx, vy, vz, p, q, r`:

- $(x, y, z)$ world position, $z$ up, as motion capture logs it [m];
- $(q_w, q_x, q_y, q_z)$ the unit quaternion rotating body vectors into the world frame;
- $(v_x, v_y, v_z)$ world-frame velocity [m/s];
- $(p, q, r)$ body-frame angular rates [rad/s].

Inputs `m1..m4` (the motor inputs as logged: PWM commands, normalised commands or measured rotor
speeds) and `vbat` (battery voltage [V], optional). The model divides each input by its
`input_scale` (the median in flight of the training data, `Quadrotor.from_flights`), so that the
features are of order one whatever the logger's units.

The dynamics are the `Helicopter`'s in other coordinates: with body velocity $\nu = R^\top v$,

$$\dot{\mathbf p} = v,\quad \dot q = \tfrac12 q\otimes(0,\omega),\quad
\dot v = R\,(\dot\nu + \omega\times\nu),\quad (\dot\nu, \dot\omega) = \text{body\_model}(q, \nu, \omega, u/s),$$

so every body model and learning criterion of the helicopter applies unchanged: `as_helicopter`
and `to_body_frame` give the body-frame system and data the criteria fit. With an
`AccelerationModel` of gravity $-g$ (world $z$ up) the known part $R^\top g - \omega\times\nu$ makes
$\dot v = g + R\,W_\nu\phi$: gravity and the rotating frame are physics, only forces and moments
per unit mass and inertia are learned.

Model families (`Quadrotor.from_flights`):

- `nominal`: the rigid body. Thrust along the body $z$ axis and the three body moments are a
  learned linear map of the motor features $m_i^2, m_i$ (with `battery`, $(v_b m_i)^2, v_b m_i$),
  and the moments carry the gyroscopic products $qr, pr, pq$ of Euler's equations (their
  coefficients are the inertia ratios). No geometry is given: arm length, X or + frame and the
  rotor constants are all in the learned map.
- `acceleration`: the nominal body plus what a real multirotor adds: rotor drag (body-frame
  force linear in velocity and in velocity times the summed motor inputs), quadratic drag, a
  constant body force and moment (centre-of-mass or IMU offset) and rate damping.
- `linear`: the linear velocity-prediction baseline (`LinearVelocityModel`): body velocity and rate
  derivatives linear in velocities, rates, roll, pitch, motor inputs and a constant.

??? cite "References"

    P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to
    modeling helicopters", NIPS 18, 2005.

    R. Mahony, V. Kumar and P. Corke, "Multirotor aerial vehicles: modeling, estimation, and control
    of quadrotor", IEEE Robotics & Automation Magazine 19(3), 2012 (rotor drag, Section "Rotor
    drag").
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._data._trajectory import Trajectory
from .._errors import UsageError
from ._helicopter import (
    AbstractBodyModel,
    AccelerationModel,
    ANGULAR_RATE,
    BODY_AXES,
    Helicopter,
    HELICOPTER_STATE_NAMES,
    LinearVelocityModel,
    QUATERNION,
    quaternion_multiply,
    quaternion_to_rotation,
    STANDARD_GRAVITY,
)
from ._system import AbstractSystem

QUADROTOR_STATE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "p", "q", "r")
QUADROTOR_INPUT_NAMES = ("m1", "m2", "m3", "m4", "vbat")
WORLD_VELOCITY = slice(7, 10)
MOTORS = tuple(f"m{i}" for i in range(1, 5))

#: The model families of `Quadrotor.from_flights` (`MODEL.json`'s "family", the CLI's `--model`).
QUADROTOR_MODELS = ("nominal", "acceleration", "linear")


def motor_features(battery: bool) -> tuple[str, ...]:
    """The rotor force and moment features: $m_i^2, m_i$, or with `battery` $(v_b m_i)^2, v_b m_i$."""
    if battery:
        return (*(f"(vbat {m})^2" for m in MOTORS), *(f"vbat {m}" for m in MOTORS))
    return (*(f"{m}^2" for m in MOTORS), *MOTORS)


def nominal_features(battery: bool) -> dict[str, tuple[str, ...]]:
    """The rigid body's features per body axis: thrust on $w$, moments and gyroscopic products on $p, q, r$."""
    motors = motor_features(battery)
    return {"u": (), "v": (), "w": motors, "p": (*motors, "qr"), "q": (*motors, "pr"), "r": (*motors, "pq")}


def acceleration_features(battery: bool) -> dict[str, tuple[str, ...]]:
    """The nominal features plus rotor drag, quadratic drag, body biases and rate damping."""
    nominal = nominal_features(battery)
    extra = {
        "u": ("u", "u sum(m)", "|u|u", "1"),
        "v": ("v", "v sum(m)", "|v|v", "1"),
        "w": ("w", "w sum(m)", "|w|w", "1"),
        "p": ("p", "v", "1"),
        "q": ("q", "u", "1"),
        "r": ("r", "1"),
    }
    return {axis: (*nominal[axis], *extra[axis]) for axis in BODY_AXES}


QUADROTOR_LINEAR_FEATURES = ("u", "v", "w", "p", "q", "r", "roll", "pitch", *MOTORS, "1")


def _rotation_and_body(x):
    rotation = quaternion_to_rotation(x[QUATERNION])
    return rotation, rotation.T @ x[WORLD_VELOCITY]


class Quadrotor(AbstractSystem):
    r"""A quadrotor (any multirotor): exact 6-DOF kinematics in the world frame and a learnable
    body-frame model (see the module docstring).

    **Fields:**

    - `body_model`: an `AccelerationModel` (gravity $-g$: world $z$ up) or a `LinearVelocityModel`
      over the motor-input features.
    - `input_scale`: the divisor of each input `m1..m4, vbat` before the features (static).
    - `normalisation_gain`: the gain [1/s] holding the quaternion at unit norm (static).

    **Example:**

    ```python
    flights = [dynax.load_flight(path, mapping=NANOBENCH_MAP)[0] for path in paths]
    quad = dynax.Quadrotor.from_flights("acceleration", flights)
    solution = dynax.fit_quadrotor(quad, flights, dynax.OneStep())
    ```
    """

    body_model: AbstractBodyModel
    input_scale: tuple[float, ...] = eqx.field(static=True, default=(1.0,) * 5)
    normalisation_gain: float = eqx.field(static=True, default=1.0)

    state_names: ClassVar[tuple[str, ...]] = QUADROTOR_STATE_NAMES
    input_names: ClassVar[tuple[str, ...]] = QUADROTOR_INPUT_NAMES
    optional_inputs: ClassVar[tuple[str, ...]] = ("vbat",)

    def __check_init__(self):
        if not isinstance(self.body_model, AbstractBodyModel):
            raise ValueError(
                f"Quadrotor: `body_model` must be an AccelerationModel or LinearVelocityModel, "
                f"got {type(self.body_model).__name__}"
            )
        if len(self.input_scale) != len(QUADROTOR_INPUT_NAMES) or not all(
            np.isfinite(s) and s > 0 for s in self.input_scale
        ):
            raise ValueError(
                f"Quadrotor: `input_scale` must be {len(QUADROTOR_INPUT_NAMES)} positive numbers "
                f"(inputs {QUADROTOR_INPUT_NAMES}), got {self.input_scale}"
            )

    @classmethod
    def from_flights(cls, model: str, flights, *, battery: bool | None = None) -> "Quadrotor":
        """The starting `Quadrotor` of a model family, its input scales taken from the flights.

        **Arguments:**

        - `model`: `"nominal"`, `"acceleration"` or `"linear"` (see the module docstring).
        - `flights`: the training records (`Trajectory`s with the `quadrotor` columns); each input's
          scale is the median of its magnitude over them (motors: over the samples where it runs).
        - `battery`: scale the motor features by `vbat` (default: when every flight has `vbat`).

        **Returns:** a `Quadrotor` with zero weights.
        """
        flights = list(flights)
        if not flights:
            raise UsageError("Quadrotor.from_flights: no flights given")
        for f in flights:
            _check_quadrotor_data(f, "Quadrotor.from_flights")
        has_battery = all(len(f.input_names) == 5 for f in flights)
        if battery is None:
            battery = has_battery
        if battery and not has_battery:
            raise UsageError("Quadrotor.from_flights: `battery=True` needs `vbat` in every flight")
        us = np.concatenate([np.abs(np.asarray(f.us[:, :4])) for f in flights])
        running = us[us > 0]
        m_scale = float(np.median(running)) if running.size else 1.0
        v_scale = float(np.median(np.concatenate([np.asarray(f.us[:, 4]) for f in flights]))) if has_battery else 1.0
        scale = (m_scale,) * 4 + ((v_scale if v_scale > 0 else 1.0),)
        if model == "linear":
            names = QUADROTOR_LINEAR_FEATURES
            body = LinearVelocityModel(
                weights=jnp.zeros((6, len(names))),
                feature_names=names,
                mask=tuple(tuple(True for _ in names) for _ in BODY_AXES),
            )
        elif model in ("nominal", "acceleration"):
            axes = nominal_features(battery) if model == "nominal" else acceleration_features(battery)
            template = AccelerationModel.with_features(axes)
            body = AccelerationModel(
                weights=template.weights,
                feature_names=template.feature_names,
                mask=template.mask,
                gravity=-STANDARD_GRAVITY,
            )
        else:
            raise UsageError(f"Quadrotor.from_flights: unknown model {model!r}; expected one of {QUADROTOR_MODELS}")
        return cls(body, scale)

    @property
    def uses_battery(self) -> bool:
        """Whether the body model reads `vbat` (then the data must have it)."""
        return any("vbat" in name for name in self.body_model.feature_names)

    def scaled_inputs(self, u: Float[Array | np.ndarray, "... n_inputs"]) -> Float[Array, "... n_inputs"]:
        """The inputs divided by `input_scale` (the first `u.shape[-1]` of it: `vbat` may be absent)."""
        dtype = jax.dtypes.canonicalize_dtype(u.dtype)  # float32 where JAX's float64 mode is off, silently
        return jnp.asarray(u) / jnp.broadcast_to(jnp.asarray(self.input_scale[: u.shape[-1]], dtype), u.shape)

    def as_helicopter(self) -> Helicopter:
        """The same dynamics in body-frame coordinates on scaled inputs: what the criteria fit."""
        return Helicopter(self.body_model, self.normalisation_gain)

    def body_frame(self, record: Trajectory) -> Trajectory:
        """A flight in the coordinates `as_helicopter()` is fitted in (`to_body_frame`); refused where the
        model's features read `vbat` and the flight has none."""
        if self.uses_battery and "vbat" not in record.input_names:
            raise UsageError("the model's features use `vbat`, which the flights do not have")
        return to_body_frame(self, record)

    def with_body_model(self, body_model: AbstractBodyModel) -> "Quadrotor":
        """The same quadrotor (input scales, normalisation) with `body_model` (a fitted one)."""
        return Quadrotor(body_model, self.input_scale, self.normalisation_gain)

    def parameter_filter(self):
        """The body model's free weights (its feature `mask`); gravity and the frame are physics."""
        spec = jax.tree.map(lambda _: False, self)
        return eqx.tree_at(lambda h: h.body_model.weights, spec, np.asarray(self.body_model.mask, dtype=bool))

    def parameter_labels(self) -> tuple[str, ...]:
        return tuple(self.body_model.parameter_names)

    def state_error(self, simulated, measured):
        """Simulated minus measured, the simulated quaternion on the measured one's hemisphere."""
        quat = simulated[..., QUATERNION]
        sign = jnp.where(jnp.sum(quat * measured[..., QUATERNION], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        return simulated.at[..., QUATERNION].set(sign * quat) - measured

    @property
    def position_indices(self) -> tuple[int, ...]:
        return (0, 1, 2)

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        return tuple(range(7, 13))  # world velocity and body rates

    def vector_field(self, t, x, u):
        rotation, nu = _rotation_and_body(x)
        omega = x[ANGULAR_RATE]
        quat = x[QUATERNION]
        d = self.body_model(quat, jnp.concatenate([nu, omega]), self.scaled_inputs(u))
        dvel = rotation @ (d[:3] + jnp.cross(omega, nu))
        dquat = 0.5 * quaternion_multiply(quat, jnp.concatenate([jnp.zeros((1,), x.dtype), omega]))
        dquat = dquat + self.normalisation_gain * (1 - quat @ quat) * quat
        return jnp.concatenate([x[WORLD_VELOCITY], dquat, dvel, d[3:]])


class ConstantVelocity(AbstractSystem):
    r"""The constant-velocity baseline of flight prediction: world velocity and body rates held.

    $\dot{\mathbf p} = v$, $\dot q = \frac12 q\otimes(0,\omega)$, $\dot v = 0$, $\dot\omega = 0$ on the
    `quadrotor` state; the inputs are ignored. Nothing to fit.
    """

    state_names: ClassVar[tuple[str, ...]] = QUADROTOR_STATE_NAMES
    input_names: ClassVar[tuple[str, ...]] = QUADROTOR_INPUT_NAMES

    def state_error(self, simulated, measured):
        quat = simulated[..., QUATERNION]
        sign = jnp.where(jnp.sum(quat * measured[..., QUATERNION], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        return simulated.at[..., QUATERNION].set(sign * quat) - measured

    def vector_field(self, t, x, u):
        quat, omega = x[QUATERNION], x[ANGULAR_RATE]
        dquat = 0.5 * quaternion_multiply(quat, jnp.concatenate([jnp.zeros((1,), x.dtype), omega]))
        return jnp.concatenate([x[WORLD_VELOCITY], dquat, jnp.zeros(6, x.dtype)])


def _check_quadrotor_data(trajectory: Trajectory, where: str):
    if tuple(trajectory.state_names) != QUADROTOR_STATE_NAMES:
        raise UsageError(
            f"{where}: the trajectory must have the quadrotor states {QUADROTOR_STATE_NAMES}, "
            f"got {tuple(trajectory.state_names)}"
        )
    if tuple(trajectory.input_names) not in (QUADROTOR_INPUT_NAMES, QUADROTOR_INPUT_NAMES[:4]):
        raise UsageError(
            f"{where}: the trajectory's inputs must be {QUADROTOR_INPUT_NAMES} (vbat optional), "
            f"got {tuple(trajectory.input_names)}"
        )


def to_body_frame(system: Quadrotor, trajectory: Trajectory) -> Trajectory:
    """A quadrotor record in the helicopter's coordinates: body velocity $R^\\top v$ in place of $v$,
    inputs divided by `input_scale` (the data `system.as_helicopter()` is fitted to)."""
    _check_quadrotor_data(trajectory, "to_body_frame")
    xs = jnp.asarray(trajectory.xs)  # a record read into numpy arrays too
    body = jax.vmap(lambda x: _rotation_and_body(x)[1])(xs)
    xs = xs.at[:, WORLD_VELOCITY].set(body)
    return Trajectory(
        trajectory.ts,
        xs,
        system.scaled_inputs(trajectory.us),
        HELICOPTER_STATE_NAMES,
        trajectory.input_names,
        "helicopter",
        trajectory.source,
    )
