r"""Friction at rest: a static (breakaway) level above the Coulomb level, and sticking.

A joint at rest under a net torque below its breakaway level stays at rest: the friction takes
whatever value, up to the static level $f_s$, holds it there. Once it moves, the friction falls
from $f_s$ to the Coulomb level $f_c$ within a few Stribeck velocities $v_{st}$ (the Stribeck
curve):

$$f(\dot q) = -\big[f_c + (f_s - f_c)\,e^{-(\dot q / v_{st})^2}\big]\operatorname{sign}(\dot q)$$

(Armstrong-Hélouvry, Dupont and Canudas de Wit 1994, sec. 2.1). A friction that is a function of
the velocity alone, however steep its smoothing, holds nothing at rest: under a constant net torque
$\tau < f_s$ it creeps at the speed where it balances $\tau$.

`Stiction` models both regimes with a right-hand side that is Lipschitz in the state, so that the
fixed-step and the adaptive integrators both handle it (Karnopp's model, smoothed). Inside a band
of speeds $|\dot q_j| \lesssim v_b$ (`velocity_scale`), the joint's total friction is replaced by
the force that stops the joint within `hold_time` $\tau_h$: with $\mathcal S$ the joints that stick,
it solves $\ddot q_{\mathcal S} = -\dot q_{\mathcal S} / \tau_h$ for their friction forces given all
other forces, and clips each to $\pm f_s$ (a force beyond it breaks the joint away) and to the side
that opposes the motion (`Stiction.dissipative_bounds`: friction does no positive work). Outside the
band the friction is the Stribeck curve above, the Coulomb part being the joint's `CoulombFriction`
term (smoothed as $\tanh(\dot q / v_c)$) and the static excess $\max(f_s - f_c, 0)$ this term's.
The two regimes are blended by a weight that is 1 in the band and
$e^{-((|\dot q| - v_b) / 2 v_b)^2}$ outside it (the fixed-step rollout at two steps per 5 ms sample
then agrees with the adaptive one to 2e-4 rad on a stick-slip record). A joint at rest under a torque
below $f_s$ holds to within $\tau_h$ times its initial speed, whatever the step size (tested
against an event-based stick-slip integrator, `tests/model/test_stiction.py`).

**Rising static friction** (`dwell_time`, opt-in). The static level a contact holds grows with the
time it has rested (Armstrong-Hélouvry et al. 1994, sec. 2.1.4: "rising static friction"): a joint
that passes through zero speed at a reversal, inside the band for milliseconds, has not built up the
level a joint resting for a second has. With `dwell_time` $T_d$ the term carries one internal state,
its memory of rest $m \in [0, 1]$, which scales everything it adds (the hold in the band and the
static excess in motion): with $w$ the band's weight below,

$$\dot m = w(\dot q)\,\frac{1 - m}{T_d} - \big(1 - w(\dot q)\big)\,\frac{|\dot q|\,m}{d_s + |\dot q|\,\tau_h},$$

so it builds over $T_d$ while the joint is in the band and is erased over a slip of $d_s$
(`slip_distance`) once it slides, and no faster than the hold time $\tau_h$ (so that a fast slip
does not make the state stiff for a fixed-step integrator): the contact's age, built at rest and
worn by sliding, as in the rate-and-state laws' ageing of contacts (Dieterich 1979; Ruina 1983),
with the level linear in it. At $m = 0$ the joint has the friction of its other terms alone (the
model without this term);
at $m = 1$ the term acts as without a dwell. A state measured at rest starts with its memory built
($m_0 = w(\dot q_0)$, `Extended.initial_state`): a joint whose start speed is in the band is taken
to have rested there for long (a window that starts at a reversal's turning point is taken for one
that starts at rest, as a speed alone cannot tell them apart). The memory forgets that start (it is built over
$T_d$ and erased over $d_s$), so the diagnosis's windowed rollouts start it half a second before each window
and integrate it along the measured speeds there (`dynax.internal.complete_state` with the states before the
window), which tells a turning point from a rest; `diagnose`'s own `stiction` candidate has no `dwell_time`, so
no state.

When several joints stick at once their holding forces are solved for jointly and clipped each
(a joint that breaks away while another sticks changes what the other needs by the difference
between its clipped and unclipped force; the next evaluations see the new motion).

??? cite

    B. Armstrong-Hélouvry, P. Dupont, C. Canudas de Wit, "A survey of models, analysis tools and
    compensation methods for the control of machines with friction", Automatica 30(7), 1994.

    J. H. Dieterich, "Modeling of rock friction: 1. Experimental results and constitutive equations",
    J. Geophysical Research 84(B5), 1979. A. Ruina, "Slip instability and state variable friction laws",
    J. Geophysical Research 88(B12), 1983.

    D. Karnopp, "Computer simulation of stick-slip friction in mechanical dynamic systems",
    J. Dynamic Systems, Measurement and Control 107(1), 1985.
"""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._errors import UsageError
from .._system import solve_spd
from ._terms import AbstractJointTerm, CoulombFriction, float_scalar


class Stiction(AbstractJointTerm):
    r"""Static friction at one joint: the joint sticks at rest until the net torque exceeds `fs`,
    and the friction falls from `fs` to the Coulomb level in motion (see the module for the model).

    With `fs = 0` (the neutral value) the term does nothing. `fs` below the joint's Coulomb level
    holds up to `fs` at rest and adds nothing in motion. The Coulomb level it builds on is the joint's
    `CoulombFriction` term; a Coulomb friction that is a parameter of the system itself (`LinearAxis`)
    is not seen, so there the excess in motion is `fs` on top of it.

    **Arguments:**

    - `joint`: 0-based joint index.
    - `fs`: the static (breakaway) friction level [N m or N], the largest torque the joint holds at rest.
    - `stribeck_velocity`: $v_{st}$, the speed over which the friction falls from `fs` to the Coulomb
      level [rad/s or m/s] (default 0.05).
    - `velocity_scale`: $v_b$, the band of speeds in which the joint sticks (default 0.01, the Coulomb
      friction's smoothing): the friction law's stick region. Keep it narrow: inside the band the
      friction is whatever stops the joint, up to `fs`, and the band's smooth edge reaches two to three
      times its width, so a wide band catches a joint that passes through zero speed at a reversal.
      The measured speed at rest is the start state's business, not the band's: there the true speed
      is zero and the record shows its sensor's noise (on the DFKI rig some 0.1 rad/s, ten times this
      band), so a window started from it starts the joint moving. `identify` keeps the default band
      and validates from windows that start at zero speed where a joint rests and its measured speed
      is within three times that record's own noise at rest (`dynax.internal.speeds_zeroed_at_rest`,
      `held_out_error(..., start_at_rest=True)`); its refinement starts from its own fit of the
      positions (the same rule there is `refine_by_simulation(..., rests=...)`, opt-in);
      `dynax.simulate` starts where it is told. `diagnose`'s `stiction` candidate, whose windows start from the
      measured state, widens the band to the speed noise at rest (`dynax.internal.speed_noise_at_rest`).
    - `hold_time`: $\tau_h$, the time in which a sticking joint's speed decays [s] (default 0.01);
      keep it above about two steps of a fixed-step integrator.
    - `dwell_time`: $T_d$, the time at rest over which the static level builds up [s] (default `None`:
      no dwell, the level is there at once). With it the term has one internal state, its memory of
      rest (named `fs{j}_rest`; see the module for the model), so a joint that only passes through
      zero speed at a reversal (inside the band for a few milliseconds) has little of it, and one
      that rests has it all. Choose it well above the time a reversal spends in the band and below the
      rests the records show (`identify` uses 0.1 s). A model with it has more states than those measured:
      complete a measured one with `Extended.initial_state` before `dynax.simulate`.
    - `slip_distance`: $d_s$, the slip over which sliding erases the memory of rest [rad or m] (default
      0.005; used with a `dwell_time` only). A time would erase it under any jolt past the band; a
      distance erases it once the joint has truly slid.
    - `held_force`, `held_position`: a rest the records show the joint holding, a lower bound on `fs`:
      the generalised force applied at the joint there [N m or N] and the joint positions, so that the
      torque held is `held_force` less the gravity at `held_position` of whatever rigid-body parameters
      a fit tries (`held`); without a position (default) `held_force` is the torque held itself (default 0:
      none known). They change no simulation; the output-error refinement keeps `fs` at or above the
      torque held (`dynax.internal.ConsistentParametrisation`).
    """

    joint: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    # Settings held as arrays (a new value does not recompile), not fitted (see `parameter_filter`).
    stribeck_velocity: Float[Array, ""]
    velocity_scale: Float[Array, ""]
    hold_time: Float[Array, ""]
    held_force: Float[Array, ""]
    held_position: Float[Array, " n_joints"] | None
    dwell_time: Float[Array, ""] | None
    slip_distance: Float[Array, ""]
    cause: ClassVar[str] = "stiction"
    prefix: ClassVar[str] = "fs"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1
    holds_at_rest: ClassVar[bool] = True
    smooth_at_neutral: ClassVar[bool] = False

    def __init__(
        self,
        joint: int,
        fs: ArrayLike = 0.0,
        *,
        stribeck_velocity: ArrayLike = 0.05,
        velocity_scale: ArrayLike = 0.01,
        hold_time: ArrayLike = 0.01,
        held_force: ArrayLike = 0.0,
        held_position: ArrayLike | tuple[float, ...] | None = None,
        dwell_time: ArrayLike | None = None,
        slip_distance: ArrayLike = 0.005,
    ):
        for name, value in (
            ("stribeck_velocity", stribeck_velocity),
            ("velocity_scale", velocity_scale),
            ("hold_time", hold_time),
            ("dwell_time", dwell_time),
            ("slip_distance", slip_distance),
        ):
            if isinstance(value, (int, float)) and not value > 0.0:
                raise UsageError(f"Stiction: `{name}` must be positive, got {value}")
        self.joint = joint
        self.coefficient = float_scalar(fs)
        self.stribeck_velocity = float_scalar(stribeck_velocity)
        self.velocity_scale = float_scalar(velocity_scale)
        self.hold_time = float_scalar(hold_time)
        self.held_force = float_scalar(held_force)
        self.held_position = None if held_position is None else jnp.asarray(held_position, self.held_force.dtype)
        self.dwell_time = None if dwell_time is None else float_scalar(dwell_time)
        self.slip_distance = float_scalar(slip_distance)

    def hidden_names(self, system) -> tuple[str, ...]:
        """The memory of rest's state name, `fs{j}_rest` (none without a `dwell_time`)."""
        return () if self.dwell_time is None else (f"{self.parameter_name(system)}_rest",)

    def initial_hidden(self, system, x, a):
        """The memory of rest of a joint measured at the state `x`: the band's weight at its speed (1 in the band: a
        joint measured at rest is taken to have rested long); none without a `dwell_time`."""
        if self.dwell_time is None:
            return x[:0]
        return jnp.atleast_1d(self.weight(x[system.velocity_indices[self.joint]]))

    def hidden_vector_field(self, system, x, a, z):
        """The memory of rest's rate (`memory_derivative`) at the joint's speed in `x`."""
        if self.dwell_time is None:
            return jnp.zeros_like(z)
        return jnp.atleast_1d(self.memory_derivative(x[system.velocity_indices[self.joint]], z[0]))

    def memory_derivative(self, dq: Float[Array, ""], memory: Float[Array, ""]) -> Float[Array, ""]:
        r"""$\dot m = w\,(1 - m) / T_d - (1 - w)\,|\dot q|\,m / (d_s + |\dot q|\,\tau_h)$: built in the band over
        the dwell time, erased over the slip distance in motion, and no faster than the hold time."""
        if self.dwell_time is None:
            raise UsageError("Stiction.memory_derivative: the term has no `dwell_time`")
        w = self.weight(dq)
        speed = jnp.abs(dq)
        wear = speed / (self.slip_distance + speed * self.hold_time)
        return w * (1.0 - memory) / self.dwell_time - (1.0 - w) * wear * memory

    def parameter_filter(self):
        spec = super().parameter_filter()
        spec = eqx.tree_at(
            lambda t: (t.stribeck_velocity, t.velocity_scale, t.hold_time, t.held_force, t.slip_distance),
            spec,
            (False, False, False, False, False),
        )
        if self.dwell_time is not None:
            spec = eqx.tree_at(lambda t: t.dwell_time, spec, False)
        if self.held_position is not None:
            spec = eqx.tree_at(lambda t: t.held_position, spec, False)
        return spec

    def held(self, system) -> Float[Array, ""]:
        """The torque the joint held at rest under `system`'s rigid body (its gravity at `held_position`,
        the speeds and accelerations zero): a lower bound on `fs`."""
        if self.held_position is None:
            return jnp.abs(self.held_force)
        zeros = jnp.zeros_like(self.held_position)
        return jnp.abs(self.held_force - system.inverse_dynamics(self.held_position, zeros, zeros)[self.joint])

    def slip_force(self, dq: Float[Array, ""], coulomb: Float[Array, ""]) -> Float[Array, ""]:
        r"""The friction in motion above the Coulomb level `coulomb`:
        $-\max(f_s - f_c, 0)\,e^{-(\dot q / v_{st})^2} \tanh(\dot q / v_c)$, $v_c$ = `velocity_scale`."""
        excess = jnp.maximum(self.coefficient - coulomb, 0.0)
        return -excess * jnp.exp(-((dq / self.stribeck_velocity) ** 2)) * jnp.tanh(dq / self.velocity_scale)

    def weight(self, dq: Float[Array, ""]) -> Float[Array, ""]:
        r"""How much the joint sticks at speed `dq`: 1 inside the band $|\dot q| \le v_b$, falling as
        $e^{-((|\dot q| - v_b) / 2 v_b)^2}$ outside it (1 in the band, so that the joint stops there and
        does not creep)."""
        outside = jnp.maximum(jnp.abs(dq) - self.velocity_scale, 0.0)
        return jnp.exp(-((outside / (2 * self.velocity_scale)) ** 2))

    @staticmethod
    def holding_force(
        holding: tuple["Stiction", ...],
        terms: tuple[AbstractJointTerm, ...],
        mass: Float[Array, "n n"],
        force: Float[Array, " n"],
        q: Float[Array, " n"],
        dq: Float[Array, " n"],
        hidden: tuple[Float[Array, " _"], ...] | None = None,
    ) -> Float[Array, " n"]:
        r"""What the sticking joints add to the generalised force `force` (all other terms included) for
        the mass matrix `mass` (rotor inertias included): each term's slip excess, and in its band the
        clipped holding force in place of the friction the joint has (both clipped to $\pm f_s$), each
        scaled by its term's memory of rest, its internal state in `hidden` (one per term in `holding`;
        1 for a term without a `dwell_time`; default none)."""
        memory = None
        remembered = [z for z in hidden or () if z.shape[0]]
        if remembered:
            ones = jnp.ones_like(remembered[0][0])
            memory = jnp.stack([z[0] if z.shape[0] else ones for z in hidden or ()])
        joints = [t.joint for t in holding]
        coulomb = {t.joint: t.coefficient for t in terms if isinstance(t, CoulombFriction)}
        # The friction each sticking joint has from its other friction terms, and this term's excess.
        friction = []
        slip = []
        for i, t in enumerate(holding):
            fc = coulomb.get(t.joint, jnp.zeros_like(t.coefficient))
            s = t.slip_force(dq[t.joint], fc)
            if memory is not None:
                s = memory[i] * s
            slip.append(s)
            own = sum(
                (u.force(q[u.joint], dq[u.joint]) for u in terms if u.joint == t.joint and u.friction),
                jnp.zeros_like(s),
            )
            friction.append(own + s)
        slip = jnp.stack(slip)
        friction = jnp.stack(friction)
        idx = jnp.asarray(joints)
        force = force.at[idx].add(slip)
        inverse = _inverse(mass)
        accel = inverse @ force
        target = -dq[idx] / jnp.stack([t.hold_time for t in holding])
        extra = solve_spd(inverse[idx][:, idx], target - accel[idx])
        level = jnp.stack([t.coefficient for t in holding])
        lower, upper = Stiction.dissipative_bounds(holding, level, dq[idx])
        held = jnp.clip(friction + extra, lower, upper)
        weight = jnp.stack([t.weight(dq[t.joint]) for t in holding])
        # Measured from the friction clipped to the same bounds: with `fs = 0` the term adds nothing.
        if memory is not None:
            weight = memory * weight
        added = slip + weight * (held - jnp.clip(friction, lower, upper))
        return jnp.zeros_like(force).at[idx].add(added)

    @staticmethod
    def dissipative_bounds(
        holding: tuple["Stiction", ...], level: Float[Array, " k"], dq: Float[Array, " k"]
    ) -> tuple[Float[Array, " k"], Float[Array, " k"]]:
        r"""The bounds on the sticking joints' friction: $\pm f_s$, and no push along the motion.

        Friction dissipates: $f\,\dot q \le 0$. The force that stops a joint within the hold time
        opposes its speed, but one that holds its *acceleration* to $-\dot q / \tau_h$ pushes along
        the motion wherever the other forces decelerate the joint faster than that: at every
        reversal, in the band before the joint turns. A friction of up to $f_s$ then drives the
        joint on towards its turning point, a force no friction has. So the bound on the side of the
        motion shrinks smoothly from $f_s$ at rest (where the sign of the speed is noise) to 0 beyond
        the band: $f \le f_s\,(1 - \max(\tanh(\dot q / v_b), 0))$ and
        $f \ge -f_s\,(1 + \min(\tanh(\dot q / v_b), 0))$."""
        side = jnp.tanh(dq / jnp.stack([t.velocity_scale for t in holding]))
        return -level * (1.0 + jnp.minimum(side, 0.0)), level * (1.0 - jnp.maximum(side, 0.0))


LEAST_STICK_BAND = 0.01  # Stiction's default band: the Coulomb friction's smoothing [rad/s or m/s]
# The dwell time `identify` gives a static level it reads [s]: built to 92 % over the shortest stretch the rest search
# calls a rest (0.25 s, `dynax.internal.rest_stretches`), to a few % over a reversal's passage through the band (some
# 5 ms where the joint turns at 4 rad/s^2 and more).
REST_DWELL_TIME = 0.1


def stick_band(speed_noise: float) -> float:
    """The band of speeds `Stiction` sticks in (`velocity_scale`) for a measured speed whose noise at rest is
    `speed_noise` (`dynax.internal.speed_noise_at_rest`): the noise itself, at least `LEAST_STICK_BAND`.

    A window that starts from a state measured at rest starts at a speed of about the noise; with a band
    below it, the joint never sticks. A band much wider holds a joint that truly slips slowly (a band of
    three times the noise fits the level of event-based stick-slip records 13 % low, one of the noise
    3 % low; the band's edge is smooth, `Stiction.weight`, so a start a little outside it still sticks)."""
    return max(float(speed_noise), LEAST_STICK_BAND)


def _inverse(m):
    if m.shape == (2, 2):  # closed form: much cheaper than an LU call inside a vmapped scan
        det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        return jnp.stack([jnp.stack([m[1, 1], -m[0, 1]]), jnp.stack([-m[1, 0], m[0, 0]])]) / det
    return jnp.linalg.inv(m)
