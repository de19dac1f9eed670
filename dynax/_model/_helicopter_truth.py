r"""A higher-fidelity helicopter simulator and the closed-loop flights that generate learning data.

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

`fly` closes the loop with `FlightController` (cascaded position / attitude control built on the
nominal Tempest rate model, with low-pass filtered random excitation added to every input) and
`generate_helicopter_flight` produces the two data sets of the paper: `"hover"` (small
perturbations about hover, position waypoints) and `"aerobatic"` (rolls, flips and funnels at large
attitudes, between position-hold recoveries).

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
import numpy as np
from jaxtyping import Array, Float

from ._helicopter import (
    ANGULAR_RATE,
    BODY,
    HELICOPTER_INPUT_NAMES,
    HELICOPTER_STATE_NAMES,
    QUATERNION,
    rigid_body_kinematics,
    TEMPEST_COEFFICIENTS,
    VELOCITY,
    hover_state,
    quaternion_conjugate,
    quaternion_from_euler,
    quaternion_multiply,
    quaternion_to_rotation,
)
from ._system import AbstractSystem

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


# --------------------------------------------------------------------------------------------------
# Closed-loop flight.


class FlightController(eqx.Module):
    r"""A stabilising cascaded controller for the helicopter, built on the nominal Tempest rate model.

    - **Position hold** (outer loop): a PD law on the position error (clipped to `max_position_error`)
      gives a desired world acceleration; the desired thrust direction is the body $-z$ axis
      aligned with $a_d - g$, which with the desired yaw gives the attitude reference, and the
      collective follows the thrust magnitude through $C_4$.
    - **Manoeuvre** mode: the attitude, body-rate and collective references are given directly
      (rolls, flips, funnels).
    - **Attitude** (inner loop): with the quaternion error $e = 2\,\mathrm{sign}(\delta q_w)\,\delta q_{xyz}$,
      the desired angular acceleration $\alpha_d = -K_a e - K_\omega(\omega - \omega_d)$ is inverted
      through the nominal rate model $\dot\omega = B\omega + Cu$.

    **Fields:** gains `position_gain`, `velocity_gain` [1/s^2, 1/s], `attitude_gain`, `rate_gain`,
    `max_tilt` [rad], `max_position_error` [m], `hover_collective`.
    """

    position_gain: float = 1.0
    velocity_gain: float = 1.6
    attitude_gain: float = 36.0
    rate_gain: float = 10.0
    max_tilt: float = 0.5
    max_position_error: float = 3.0
    hover_collective: float = 0.223
    gravity: float = 9.81

    def __call__(self, x, reference):
        """Inputs `u1..u4` for state `x` (13 contract states) and a reference row (see `fly`)."""
        c = TEMPEST_COEFFICIENTS
        dtype = x.dtype
        position_ref, yaw_ref = reference[0:3], reference[3]
        quat_man, omega_man, collective_man, manoeuvre = reference[4:8], reference[8:11], reference[11], reference[12]
        quat = x[QUATERNION] / jnp.linalg.norm(x[QUATERNION])
        rotation = quaternion_to_rotation(quat)
        v_world = rotation @ x[VELOCITY]
        omega = x[ANGULAR_RATE]

        # Outer loop: desired acceleration -> thrust direction and magnitude.
        error = jnp.clip(position_ref - x[0:3], -self.max_position_error, self.max_position_error)
        accel = self.position_gain * error - self.velocity_gain * v_world
        g = jnp.array([0.0, 0.0, self.gravity], dtype)
        specific = accel - g  # the specific force the rotor must produce (points up: -z)
        horizontal = specific[:2]
        limit = self.gravity * jnp.tan(self.max_tilt)
        scale = jnp.minimum(1.0, limit / (jnp.linalg.norm(horizontal) + 1e-9))
        specific = jnp.concatenate([horizontal * scale, specific[2:]])
        z_body = -specific / jnp.linalg.norm(specific)
        x_heading = jnp.array([jnp.cos(yaw_ref), jnp.sin(yaw_ref), 0.0], dtype)
        y_body = jnp.cross(z_body, x_heading)
        y_body = y_body / jnp.linalg.norm(y_body)
        x_body = jnp.cross(y_body, z_body)
        quat_hold = _quaternion_from_rotation(jnp.stack([x_body, y_body, z_body], axis=1))
        thrust_needed = specific @ (rotation @ jnp.array([0.0, 0.0, -1.0], dtype))  # per unit mass
        collective_hold = self.hover_collective + (thrust_needed - self.gravity) / (-c["C4"])

        in_manoeuvre = manoeuvre > 0.5
        quat_ref = jnp.where(in_manoeuvre, quat_man, quat_hold)
        omega_ref = jnp.where(in_manoeuvre, omega_man, jnp.zeros(3, dtype))
        collective = jnp.where(in_manoeuvre, collective_man, collective_hold)

        # Inner loop: quaternion attitude error -> desired angular acceleration -> cyclic and tail.
        delta = quaternion_multiply(quaternion_conjugate(quat_ref), quat)
        e = 2 * jnp.sign(delta[0] + 1e-12) * delta[1:]
        alpha = -self.attitude_gain * e - self.rate_gain * (omega - omega_ref)
        damping = jnp.array([c["Bx"], c["By"], c["Bz"]], dtype)
        sensitivity = jnp.array([c["C1"], c["C2"], c["C3"]], dtype)
        cyclic = (alpha - damping * omega) / sensitivity
        return jnp.clip(jnp.concatenate([cyclic, collective[None]]), -1.0, 1.0)


def _quaternion_from_rotation(m):
    """The unit quaternion of a rotation matrix (Shepperd's method, branch-free via the largest pivot)."""
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    candidates = jnp.stack(
        [
            jnp.stack([1 + trace, m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]),
            jnp.stack([m[2, 1] - m[1, 2], 1 + 2 * m[0, 0] - trace, m[0, 1] + m[1, 0], m[0, 2] + m[2, 0]]),
            jnp.stack([m[0, 2] - m[2, 0], m[0, 1] + m[1, 0], 1 + 2 * m[1, 1] - trace, m[1, 2] + m[2, 1]]),
            jnp.stack([m[1, 0] - m[0, 1], m[0, 2] + m[2, 0], m[1, 2] + m[2, 1], 1 + 2 * m[2, 2] - trace]),
        ]
    )
    pivots = jnp.stack([1 + trace, 1 + 2 * m[0, 0] - trace, 1 + 2 * m[1, 1] - trace, 1 + 2 * m[2, 2] - trace])
    q = candidates[jnp.argmax(pivots)]
    q = q / jnp.linalg.norm(q)
    return q * jnp.sign(q[0] + 1e-12)


def _rk4_interval(system, x, u, dt, substeps):
    h = dt / substeps

    def step(_, y):
        k1 = system.vector_field(0.0, y, u)
        k2 = system.vector_field(0.0, y + h / 2 * k1, u)
        k3 = system.vector_field(0.0, y + h / 2 * k2, u)
        k4 = system.vector_field(0.0, y + h * k3, u)
        return y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    return jax.lax.fori_loop(0, substeps, step, x)


@eqx.filter_jit
def fly(
    truth: AbstractSystem,
    controller: FlightController,
    x0: Float[Array, " 15"],
    dt: float,
    references: Float[Array, "time 13"],
    excitation: Float[Array, "time 4"],
    wind: Float[Array, "time 3"],
    substeps: int = 4,
) -> tuple[Float[Array, "time 15"], Float[Array, "time 4"]]:
    """Fly `truth` in closed loop with `controller` plus additive `excitation`, in `lax.scan`.

    `truth` is a `HelicopterTruth` or any system whose first 13 states and 4 inputs are the
    helicopter's (a `Helicopter` flies the same references in still air).

    At each sample the controller reads the state, the excitation is added and the inputs are
    clipped to $[-1, 1]$ and held over the interval, integrated by `substeps` RK4 steps. Reference
    rows are `(x, y, z, yaw, qw, qx, qy, qz, p, q, r, collective, manoeuvre)`: position and heading
    for position hold, or (when `manoeuvre > 0.5`) the attitude, body-rate and collective references.

    **Returns:** the states `(time, 15)` and the applied inputs `(time, 4)`.
    """

    def sample(x, row):
        reference, extra, gust = row
        u = jnp.clip(controller(x[:13], reference) + extra, -1.0, 1.0)
        # A system without wind inputs (e.g. a `Helicopter`) flies in still air.
        x_next = _rk4_interval(truth, x, jnp.concatenate([u, gust])[: truth.n_inputs], dt, substeps)
        return x_next, (x, u)

    _, (xs, us) = jax.lax.scan(sample, x0, (references, excitation, wind))
    return xs, us


# --------------------------------------------------------------------------------------------------
# Data sets.


def _filtered_noise(rng, n, dt, sigma, cutoff_hz):
    """First-order low-pass filtered Gaussian noise with stationary standard deviation `sigma`."""
    a = np.exp(-2 * np.pi * cutoff_hz * dt)
    white = rng.standard_normal((n, len(sigma))) * np.sqrt(1 - a**2) * np.asarray(sigma)
    out = np.zeros_like(white)
    state = rng.standard_normal(len(sigma)) * np.asarray(sigma)
    for k in range(n):
        state = a * state + white[k]
        out[k] = state
    return out


def _integrate_body_rates(quat0, omegas, dt):
    """Integrate a body-rate reference into an attitude reference (numpy, exact per step)."""
    quats = np.zeros((len(omegas), 4))
    q = np.asarray(quat0, float)
    for k, w in enumerate(omegas):
        quats[k] = q
        angle = np.linalg.norm(w) * dt
        axis = w / (np.linalg.norm(w) + 1e-15)
        dq = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
        q = _np_qmul(q, dq)
        q = q / np.linalg.norm(q)
    return quats


def _references(kind, n, dt, rng, hover_collective):
    """Reference rows for `fly`: waypoints in hover; rolls, flips and funnels in the aerobatic set."""
    refs = np.zeros((n, 13))
    refs[:, 4] = 1.0
    k = 0
    waypoint = np.zeros(3)
    yaw = 0.0
    manoeuvres = ("roll", "flip", "funnel", "roll_left", "flip_back")
    m = 0
    while k < n:
        if kind == "hover" or m % 2 == 0:
            # Position hold at a new waypoint (a few metres away) and heading.
            length = int(rng.uniform(3.0, 6.0) / dt) if kind == "hover" else int(rng.uniform(4.0, 5.0) / dt)
            waypoint = waypoint + rng.uniform(-1.5, 1.5, 3) * np.array([1, 1, 0.5])
            yaw = yaw + rng.uniform(-0.5, 0.5)
            seg = slice(k, min(n, k + length))
            refs[seg, 0:3] = waypoint
            refs[seg, 3] = yaw
            refs[seg, 12] = 0.0
            k += length
            m += 1
            continue
        name = manoeuvres[(m // 2) % len(manoeuvres)]
        m += 1
        quat0 = np.asarray(quaternion_from_euler(0.0, 0.0, yaw))
        if name in ("roll", "roll_left", "flip", "flip_back"):
            duration = rng.uniform(2.2, 2.8)
            length = int(duration / dt)
            axis = 0 if name.startswith("roll") else 1
            # Trapezoidal rate profile (0.4 s ramps) whose integral is one full turn.
            t = (np.arange(length) + 0.5) * dt
            shape = np.clip(np.minimum(t, duration - t) / 0.4, 0.0, 1.0)
            profile = shape * 2 * np.pi / (shape.sum() * dt) * (-1 if name in ("roll_left", "flip_back") else 1)
            omegas = np.zeros((length, 3))
            omegas[:, axis] = profile
            quats = _integrate_body_rates(quat0, omegas, dt)
            angle = np.cumsum(profile) * dt
            collective = hover_collective * np.cos(angle)
        else:  # funnel: tilted, yawing steadily, so the thrust vector sweeps a cone
            duration = rng.uniform(4.0, 6.0)
            length = int(duration / dt)
            tilt = rng.uniform(0.4, 0.6)
            yaw_rate = 2 * np.pi / 3.0
            t = np.arange(length) * dt
            ramp = np.clip(t / 0.5, 0, 1) * np.clip((duration - t) / 0.5, 0, 1)
            quats = np.asarray(jax.vmap(quaternion_from_euler)(jnp.asarray(tilt * ramp), jnp.zeros(length), jnp.asarray(yaw + yaw_rate * t)))
            qdot = np.gradient(quats, dt, axis=0)
            conj = quats * np.array([1, -1, -1, -1])
            omegas = 2 * _batch_qmul(conj, qdot)[:, 1:]
            collective = hover_collective + (9.81 / np.cos(tilt * ramp) - 9.81) / 42.15
            yaw = yaw + yaw_rate * duration
        seg = slice(k, min(n, k + length))
        size = seg.stop - seg.start
        refs[seg, 0:3] = waypoint
        refs[seg, 3] = yaw
        refs[seg, 4:8] = quats[:size]
        refs[seg, 8:11] = omegas[:size]
        refs[seg, 11] = collective[:size]
        refs[seg, 12] = 1.0
        k += length
    return refs


def generate_helicopter_flight(
    kind: str,
    duration: float,
    *,
    seed: int = 0,
    dt: float = 0.01,
    truth: AbstractSystem | None = None,
    controller: FlightController | None = None,
    measurement_noise: bool = True,
):
    r"""Fly the truth simulator and record a data set like the paper's.

    - `"hover"`: position hold around waypoints a few metres apart, excitation (low-pass filtered
      at 3 Hz) of standard deviation 0.06 on the cyclic and tail and 0.05 on the collective, gusts of
      0.3 m/s.
    - `"aerobatic"`: alternating position-hold recoveries and manoeuvres (full rolls and flips in
      both directions, funnels tilted 25 to 35 degrees), excitation 0.08, gusts of 0.5 m/s.

    The recorded states carry small measurement noise (`measurement_noise=True`): 5 mm in position,
    2 mrad in attitude, 0.02 m/s in velocity and 0.01 rad/s in rate, about what a state estimator
    on a model helicopter delivers.

    **Arguments:**

    - `kind`: `"hover"` or `"aerobatic"`.
    - `duration`: seconds of flight (the first 2 s settle from the start state and are kept).
    - `seed`: random seed of the excitation, gusts, manoeuvre schedule and noise.
    - `dt`: sample interval [s] (default 0.01, 100 Hz).
    - `truth`, `controller`: override the simulator (e.g. a `Helicopter` to fly a learned or the
      Tempest model itself) or the controller.
    - `measurement_noise`: whether to add the measurement noise above.

    **Returns:** a `dynax.Trajectory` with the contract's helicopter columns (float64 if enabled).
    """
    from .._data import Trajectory  # the data layer sits above the models

    if kind not in ("hover", "aerobatic"):
        raise ValueError(f"generate_helicopter_flight: `kind` must be 'hover' or 'aerobatic', got {kind!r}")
    if duration <= 10 * dt:
        raise ValueError(f"generate_helicopter_flight: `duration` must exceed 10 samples, got {duration}")
    truth = HelicopterTruth() if truth is None else truth
    controller = FlightController() if controller is None else controller
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt))
    dtype = jnp.result_type(float)
    aerobatic = kind == "aerobatic"
    sigma = [0.08] * 4 if aerobatic else [0.06, 0.06, 0.06, 0.05]
    excitation = _filtered_noise(rng, n, dt, sigma, cutoff_hz=3.0)
    gust_sigma = 0.5 if aerobatic else 0.3
    wind = _filtered_noise(rng, n, dt, [gust_sigma] * 3, cutoff_hz=1 / (2 * np.pi * 2.0))
    references = _references(kind, n, dt, rng, controller.hover_collective)
    x0 = jnp.concatenate([hover_state(dtype=dtype), jnp.zeros(truth.n_states - 13, dtype)])
    xs, us = fly(
        truth, controller, x0, dt,
        jnp.asarray(references, dtype), jnp.asarray(excitation, dtype), jnp.asarray(wind, dtype),
    )
    xs = np.array(xs[:, :13], float)
    if not np.all(np.isfinite(xs)) or np.abs(xs).max() > 1e4:
        raise RuntimeError("generate_helicopter_flight: the closed-loop flight diverged")
    xs[:, 3:7] *= np.sign(xs[:, 3:4] + 1e-12)  # hemisphere qw >= 0 (q and -q are one attitude)
    if measurement_noise:
        noise = rng.standard_normal((n, 13))
        xs[:, 0:3] += 0.005 * noise[:, 0:3]
        small = np.concatenate([np.ones((n, 1)), 0.5 * 0.002 * noise[:, 4:7]], axis=1)
        xs[:, 3:7] = _batch_qmul(xs[:, 3:7], small)
        xs[:, 3:7] /= np.linalg.norm(xs[:, 3:7], axis=1, keepdims=True)
        xs[:, 7:10] += 0.02 * noise[:, 7:10]
        xs[:, 10:13] += 0.01 * noise[:, 10:13]
    ts = np.arange(n) * dt
    return Trajectory(
        jnp.asarray(ts, dtype), jnp.asarray(xs, dtype), jnp.asarray(np.asarray(us), dtype),
        HELICOPTER_STATE_NAMES, HELICOPTER_INPUT_NAMES, "helicopter", f"dynax truth simulator ({kind}, seed {seed})",
    )


def _np_qmul(a, b):
    aw, av, bw, bv = a[0], a[1:], b[0], b[1:]
    return np.concatenate([[aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)])


def _batch_qmul(a, b):
    return np.asarray(jax.vmap(quaternion_multiply)(jnp.asarray(a), jnp.asarray(b)))
