"""`FlightController`: the cascaded position / attitude controller that flies the synthetic helicopter flights."""

import equinox as eqx
import jax.numpy as jnp

from .._model._helicopter import (
    ANGULAR_RATE,
    QUATERNION,
    quaternion_conjugate,
    quaternion_multiply,
    quaternion_to_rotation,
    TEMPEST_COEFFICIENTS,
    VELOCITY,
)


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
        quat_hold = quaternion_from_rotation(jnp.stack([x_body, y_body, z_body], axis=1))
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


def quaternion_from_rotation(m):
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
