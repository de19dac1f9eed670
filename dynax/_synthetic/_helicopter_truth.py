r"""A higher-fidelity helicopter simulator: the truth that dynax's helicopter learning data is flown on.

The Stanford helicopter logs of Abbeel, Ganapathi and Ng (2005) are not public, so dynax generates
its vehicle-learning data with `HelicopterTruth`, a model deliberately *richer* than the
acceleration model (which therefore cannot be exactly right):

- **rotor flapping lag** on the cyclic: the tip-path plane tilts $(a_1, b_1)$ follow the cyclic
  inputs, the body rates (rotor gyroscopic precession) and the air-relative velocity (flap-back)
  through a first-order lag $\tau_f$; the rotor moments are $(h T + K_\beta)(b_1, a_1)$ and the thrust
  vector tilts with the disc;
- **thrust from inflow and climb rate**: blade-element thrust $C_T = \frac{\sigma a}{2}(\frac{\theta_0}{3}
  - \frac{\lambda}{2})$ with the inflow $\lambda = (v_i - w_\text{air})/\Omega R$ and the induced
  velocity $v_i$ from Glauert's momentum theory $v_i = T / (2\rho A \sqrt{\mu^2 + (v_i - w)^2})$,
  solved by fixed-point iteration; rotor torque $Q = (T(v_i - w) + P_0)/\Omega$ reacts on the yaw axis;
- **quadratic fuselage drag** $-\frac12\rho S_i |\nu_i| \nu_i$ on the air-relative body velocity;
- **gyroscopic coupling** of the rigid body, $-\omega \times I\omega$ with unequal inertias, and
  the roll moment of the tail rotor (mounted above the centre of mass);
- **gust noise**: a world-frame wind (an Ornstein-Uhlenbeck process) entering every aerodynamic
  force through the air-relative velocity.

The parameters are those of a ~8 kg aerobatic model helicopter, chosen so that the hover
linearisation is close to the published XCell Tempest model (roll and pitch damping, cyclic,
tail and collective sensitivities; see `docs/helicopter.md`).

The closed-loop flights that record data from it are in `dynax._synthetic._flight`
(`generate_helicopter_flight`, `helicopter_flight`), flown by `FlightController`.

??? cite "References"

    P. Abbeel, V. Ganapathi and A. Y. Ng, "Learning vehicular dynamics, with application to modeling
    helicopters", NIPS 18, 2005.

    V. Gavrilets, B. Mettler and E. Feron, "Dynamic model for a miniature aerobatic helicopter",
    MIT LIDS report P-2580, 2003 (the structure of the rotor, fuselage and tail models).

    J. G. Leishman, *Principles of Helicopter Aerodynamics*, 2nd ed., Cambridge, 2006 (blade-element
    momentum theory, Glauert inflow).
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array
import numpy as np

from .._model._helicopter import (
    ANGULAR_RATE,
    HELICOPTER_INPUT_NAMES,
    HELICOPTER_STATE_NAMES,
    QUATERNION,
    quaternion_to_rotation,
    rigid_body_kinematics,
    VELOCITY,
)
from .._model._system import AbstractSystem
from ._flight_controller import FlightController

WIND_NAMES = ("wind_n", "wind_e", "wind_d")


class HelicopterTruth(AbstractSystem):
    r"""The higher-fidelity truth model (see the module docstring for the physics).

    State: the 13 contract states followed by the flapping angles `a1` (longitudinal, back
    positive) and `b1` (lateral, right positive) [rad]. Inputs: `u1..u4` followed by the world
    wind `wind_n, wind_e, wind_d` [m/s] (zero-order hold). Only the first 13 states are ever
    recorded in a data file.

    All fields are plain floats (static): the truth is not learned.
    """

    mass: float = eqx.field(static=True, default=8.0)
    inertia: tuple[float, float, float] = eqx.field(static=True, default=(0.235, 0.296, 0.25))
    gravity: float = eqx.field(static=True, default=9.81)
    air_density: float = eqx.field(static=True, default=1.225)
    # Main rotor.
    rotor_radius: float = eqx.field(static=True, default=0.8)
    rotor_speed: float = eqx.field(static=True, default=157.0)  # rad/s (1500 rpm)
    solidity: float = eqx.field(static=True, default=0.06)
    lift_slope: float = eqx.field(static=True, default=5.7)
    profile_drag: float = eqx.field(static=True, default=0.01)
    collective_offset: float = eqx.field(static=True, default=0.0254)  # rad at u4 = 0
    collective_gain: float = eqx.field(static=True, default=0.255)  # rad per unit u4
    hub_height: float = eqx.field(static=True, default=0.2)  # m above the centre of mass
    hub_stiffness: float = eqx.field(static=True, default=44.0)  # N m / rad
    flap_time_constant: float = eqx.field(static=True, default=0.05)  # s
    lateral_cyclic_gain: float = eqx.field(static=True, default=0.194)  # rad per unit u1
    longitudinal_cyclic_gain: float = eqx.field(static=True, default=-0.248)  # rad per unit u2
    flap_back: float = eqx.field(static=True, default=0.01)  # rad per m/s of air-relative speed
    # Tail rotor.
    tail_arm: float = eqx.field(static=True, default=0.9)  # m behind the centre of mass
    tail_height: float = eqx.field(static=True, default=0.1)  # m above the centre of mass
    tail_gain: float = eqx.field(static=True, default=19.6)  # N per unit u3
    tail_offset: float = eqx.field(static=True, default=0.243)  # u3 equivalent of the trim pitch
    tail_damping: float = eqx.field(static=True, default=2.5)  # N per m/s of lateral tail velocity
    # Fuselage.
    drag_areas: tuple[float, float, float] = eqx.field(static=True, default=(0.1, 0.25, 0.3))  # m^2
    inflow_iterations: int = eqx.field(static=True, default=8)

    state_names: ClassVar[tuple[str, ...]] = (*HELICOPTER_STATE_NAMES, "a1", "b1")
    input_names: ClassVar[tuple[str, ...]] = (*HELICOPTER_INPUT_NAMES, *WIND_NAMES)

    def hover_derivatives(self, collective: float | None = None) -> tuple[Array, Array]:
        r"""The quasi-steady stability and control derivatives about level hover in still air.

        The vector field is linearised (autodiff) at the level hover state with zero flapping and
        the inputs `(0, 0, 0, collective)` (default: `FlightController().hover_collective`); the
        fast flapping states are then eliminated quasi-statically,
        $A = A_{ss} - A_{sf}A_{ff}^{-1}A_{fs}$, $B = B_s - A_{sf}A_{ff}^{-1}B_f$. These are the
        derivatives a hover model without rotor states should find (e.g. $L_v = A_{pv}$ and
        $M_u = A_{qu}$, the speed stability from flap-back).

        **Returns:** `(A, B)`: `A` (6, 6) rows and columns $(u, v, w, p, q, r)$, `B` (6, 4) columns
        `u1..u4`; per second and per unit input.
        """
        if collective is None:
            collective = FlightController().hover_collective
        dtype = jnp.result_type(float)
        x0 = jnp.zeros(self.n_states, dtype).at[3].set(1.0)  # level, at rest, flapping zero
        u0 = jnp.zeros(7, dtype).at[3].set(collective)
        a = np.asarray(jax.jacfwd(lambda x: self.vector_field(0.0, x, u0))(x0))
        b = np.asarray(jax.jacfwd(lambda u: self.vector_field(0.0, x0, u))(u0))[:, :4]
        body, flap = np.arange(7, 13), np.arange(13, self.n_states)
        eliminate = a[np.ix_(body, flap)] @ np.linalg.inv(a[np.ix_(flap, flap)])
        a_red = a[np.ix_(body, body)] - eliminate @ a[np.ix_(flap, body)]
        b_red = b[body] - eliminate @ b[flap]
        return jnp.asarray(a_red, dtype), jnp.asarray(b_red, dtype)

    def rotor_thrust(self, collective_pitch, w_air, edgewise_speed_sq):
        """Thrust [N] and induced velocity [m/s] from blade-element momentum theory (Glauert inflow).

        `edgewise_speed_sq` is the squared air speed in the rotor plane [m^2/s^2].
        """
        area = jnp.pi * self.rotor_radius**2
        tip = self.rotor_speed * self.rotor_radius
        k = self.air_density * area * tip**2 * self.solidity * self.lift_slope / 2

        def thrust_of(v_i):
            lam = (v_i - w_air) / tip
            return k * (collective_pitch / 3 - lam / 2)

        def update(_, v_i):
            thrust = thrust_of(v_i)
            # A 1 m/s floor under the through-flow keeps the vortex-ring singularity away.
            v_new = thrust / (2 * self.air_density * area * jnp.sqrt(edgewise_speed_sq + (v_i - w_air) ** 2 + 1.0))
            return 0.5 * v_i + 0.5 * v_new

        v_hover = jnp.sqrt(self.mass * self.gravity / (2 * self.air_density * area))
        v_i = jax.lax.fori_loop(0, self.inflow_iterations, update, v_hover * jnp.ones_like(w_air))
        return thrust_of(v_i), v_i

    def vector_field(self, t, x, u):
        dtype = x.dtype
        quat = x[QUATERNION]
        nu, omega = x[VELOCITY], x[ANGULAR_RATE]
        a1, b1 = x[13], x[14]
        controls, wind = jnp.clip(u[:4], -1.0, 1.0), u[4:7]
        rotation = quaternion_to_rotation(quat)
        nu_air = nu - rotation.T @ wind
        ua, va, wa = nu_air[0], nu_air[1], nu_air[2]
        p, q, r = omega[0], omega[1], omega[2]

        # Main rotor: thrust from collective, climb rate and inflow; tilt from flapping.
        pitch = self.collective_offset + self.collective_gain * controls[3]
        thrust, v_i = self.rotor_thrust(pitch, wa, ua**2 + va**2)
        disc_normal = jnp.stack([-jnp.sin(a1) * jnp.cos(b1), jnp.sin(b1), -jnp.cos(a1) * jnp.cos(b1)])
        rotor_force = thrust * disc_normal
        flap_moment = self.hub_height * thrust + self.hub_stiffness
        tip = self.rotor_speed * self.rotor_radius
        area = jnp.pi * self.rotor_radius**2
        profile_power = self.air_density * area * tip**3 * self.solidity * self.profile_drag / 8
        torque = (thrust * (v_i - wa) + profile_power) / self.rotor_speed
        # The rotor turns clockwise seen from above: its reaction yaws the fuselage nose-left.
        rotor_moment = jnp.stack([flap_moment * jnp.sin(b1), flap_moment * jnp.sin(a1), -torque])

        # Tail rotor: thrust along body y, damped by the lateral air velocity at the tail.
        tail_velocity = va - self.tail_arm * r
        tail_force = -self.tail_gain * (controls[2] + self.tail_offset) - self.tail_damping * tail_velocity
        tail_moment = jnp.stack([self.tail_height * tail_force, jnp.zeros((), dtype), -self.tail_arm * tail_force])

        # Fuselage: quadratic drag.
        areas = jnp.asarray(self.drag_areas, dtype)
        drag = -0.5 * self.air_density * areas * jnp.abs(nu_air) * nu_air

        force = rotor_force + jnp.stack([jnp.zeros((), dtype), tail_force, jnp.zeros((), dtype)]) + drag
        moment = rotor_moment + tail_moment
        inertia = jnp.asarray(self.inertia, dtype)
        g_body = rotation.T @ jnp.array([0.0, 0.0, self.gravity], dtype)
        dnu = force / self.mass - jnp.cross(omega, nu) + g_body
        domega = (moment - jnp.cross(omega, inertia * omega)) / inertia

        # Flapping: first-order lag to cyclic, rate (gyroscopic precession) and flap-back.
        tau = self.flap_time_constant
        da1 = (-a1 - tau * q + self.longitudinal_cyclic_gain * controls[1] + self.flap_back * ua) / tau
        db1 = (-b1 - tau * p + self.lateral_cyclic_gain * controls[0] - self.flap_back * va) / tau

        dpos, dquat = rigid_body_kinematics(x[:13])
        return jnp.concatenate([dpos, dquat, dnu, domega, jnp.stack([da1, db1])])
