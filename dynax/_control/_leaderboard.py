r"""The RealAIGym acrobot leaderboard, by its published rules: performance and robustness scores.

The plant is the DFKI double pendulum with the shoulder passive (design C.1, model 1.0), simulated
as the lab's `Simulator` does: Runge-Kutta 4 at `dt` = 2 ms for 10 s from the hanging rest, the
controller called every step on a measured state, the applied torque passed through the motor
model (responsiveness, noise, the torque limit) and the external perturbations added after the
limit. Every rollout is one `lax.scan`; the 722 rollouts of a robustness evaluation are one
`vmap` of it, compiled once.

??? cite

    F. Wiebe, S. Vyas, L. J. Maywald, S. Kumar, F. Kirchner, "RealAIGym: education and research
    platform for studying athletic intelligence", RSS workshop 2022; the rules as code:
    `dfki-ric-underactuated-lab/double_pendulum`, `src/python/double_pendulum/analysis/`
    (`benchmark.py`, `benchmark_scores.py`, `leaderboard.py`), `simulation/simulation.py`,
    `simulation/perturbations.py`, `model/plant.py`, and the leaderboard's
    `benchmark_controller.py` (the perturbation sizes).
"""

import abc
import dataclasses
import enum
import time

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Key, UInt32
import numpy as np

# ---------------------------------------------------------------- the plant


class LeaderboardPlant(eqx.Module):
    r"""The double pendulum of the RealAIGym benchmark (`double_pendulum.model.plant`), in its physical parameters.

    $M(q) = \begin{bmatrix} I_1 + I_2 + m_2 l_1^2 + 2 m_2 l_1 r_2 c_2 + (g_r^2 + 1) I_r &
    I_2 + m_2 l_1 r_2 c_2 - g_r I_r \\
    \cdot & I_2 + g_r^2 I_r\end{bmatrix}$, Coriolis and gravity of two rigid links, and friction
    $b_i \dot q_i + c_{f,i} \arctan(100 \dot q_i)$ at each joint. $I_1$, $I_2$ are about the
    joints; $I_r$ is the elbow motor's rotor inertia behind a gear of ratio $g_r$. `nominal()` is
    the benchmark's design C.1, model 1.0. Every field is an array, so plants stack and `vmap`.
    """

    m1: Float[Array, "*batch"]
    m2: Float[Array, "*batch"]
    l1: Float[Array, "*batch"]
    l2: Float[Array, "*batch"]
    r1: Float[Array, "*batch"]
    r2: Float[Array, "*batch"]
    I1: Float[Array, "*batch"]
    I2: Float[Array, "*batch"]
    Ir: Float[Array, "*batch"]
    gr: Float[Array, "*batch"]
    b1: Float[Array, "*batch"]
    b2: Float[Array, "*batch"]
    cf1: Float[Array, "*batch"]
    cf2: Float[Array, "*batch"]
    g: Float[Array, "*batch"]
    torque_limit: Float[Array, "*batch"]

    @classmethod
    def nominal(cls, **changes) -> "LeaderboardPlant":
        """Design C.1, model 1.0 (the acrobot leaderboards' plant); keyword arguments replace fields."""
        values = dict(NOMINAL_PLANT)
        unknown = set(changes) - set(values)
        if unknown:
            raise ValueError(
                f"LeaderboardPlant.nominal: unknown parameter(s) {sorted(unknown)}; expected {sorted(values)}"
            )
        values.update(changes)
        return cls(**{k: jnp.asarray(v, float) for k, v in values.items()})

    def mass_matrix(self, q):
        c2 = jnp.cos(q[1])
        h = self.m2 * self.l1 * self.r2 * c2
        m00 = self.I1 + self.I2 + self.m2 * self.l1**2 + 2 * h + self.gr**2 * self.Ir + self.Ir
        m01 = self.I2 + h - self.gr * self.Ir
        m11 = self.I2 + self.gr**2 * self.Ir
        return m00, m01, m11

    def acceleration(self, x, tau):
        """$\\ddot q = M^{-1}(\\tau_g + \\tau - C\\dot q - F)$ with `tau` = (shoulder, elbow)."""
        q1, q2, v1, v2 = x[0], x[1], x[2], x[3]
        m00, m01, m11 = self.mass_matrix(x[:2])
        h = self.m2 * self.l1 * self.r2 * jnp.sin(q2)
        c_v0 = -2 * h * v2 * v1 - h * v2 * v2
        c_v1 = h * v1 * v1
        s1, s12 = jnp.sin(q1), jnp.sin(q1 + q2)
        g0 = -self.m1 * self.g * self.r1 * s1 - self.m2 * self.g * (self.l1 * s1 + self.r2 * s12)
        g1 = -self.m2 * self.g * self.r2 * s12
        f0 = self.b1 * v1 + self.cf1 * jnp.arctan(100 * v1)
        f1 = self.b2 * v2 + self.cf2 * jnp.arctan(100 * v2)
        rhs0 = g0 + tau[0] - c_v0 - f0
        rhs1 = g1 + tau[1] - c_v1 - f1
        det = m00 * m11 - m01 * m01
        return jnp.stack([(m11 * rhs0 - m01 * rhs1) / det, (m00 * rhs1 - m01 * rhs0) / det])

    def vector_field(self, x, tau):
        return jnp.concatenate([x[2:], self.acceleration(x, tau)])

    def rk4_step(self, x, tau, dt):
        """One classical Runge-Kutta step with the torque held (the lab's `runge_integrator`)."""
        k1 = self.vector_field(x, tau)
        k2 = self.vector_field(x + 0.5 * dt * k1, tau)
        k3 = self.vector_field(x + 0.5 * dt * k2, tau)
        k4 = self.vector_field(x + dt * k3, tau)
        return x + dt * (k1 + 2 * (k2 + k3) + k4) / 6

    def end_effector_height(self, q):
        """The height of the tip of link 2 above the shoulder [m] (negative hanging down)."""
        return -self.l1 * jnp.cos(q[..., 0]) - self.l2 * jnp.cos(q[..., 0] + q[..., 1])

    def energy(self, x):
        """Total mechanical energy (zero potential at the shoulder height) [J]."""
        m00, m01, m11 = self.mass_matrix(x[:2])
        v1, v2 = x[2], x[3]
        kinetic = 0.5 * (m00 * v1 * v1 + 2 * m01 * v1 * v2 + m11 * v2 * v2)
        y1 = -self.r1 * jnp.cos(x[0])
        y2 = -self.l1 * jnp.cos(x[0]) - self.r2 * jnp.cos(x[0] + x[1])
        return kinetic + self.g * (self.m1 * y1 + self.m2 * y2)


NOMINAL_PLANT = dict(
    m1=0.5234602302310271,
    m2=0.6255677234174437,
    l1=0.2,
    l2=0.3,
    r1=0.2,
    r2=0.25569305436052964,
    I1=0.031887199591513114,
    I2=0.05086984812807257,
    Ir=0.0,
    gr=6.0,
    b1=0.0,
    b2=0.0,
    cf1=0.0,
    cf2=0.0,
    g=9.81,
    torque_limit=6.0,
)
"""Design C.1, model 1.0 of the DFKI double pendulum as the acrobot leaderboards use it."""


# ---------------------------------------------------------------- controllers in the benchmark


class AbstractBenchmarkController(eqx.Module):
    """A controller as the benchmark runs it: a state it carries between calls and a step.

    `init(x0)` gives the controller's internal state before the first call (filters, the previous
    measurement); `step(state, t, x_measured) -> (state, tau2)` is one call at one control period,
    returning the elbow torque it commands. Both are pure JAX, so the benchmark can `vmap` them.
    """

    @abc.abstractmethod
    def init(self, x0: Float[Array, " 4"]):
        """The internal state before the first call."""

    @abc.abstractmethod
    def step(self, state, t: Float[Array, ""], x: Float[Array, " 4"]):
        """One control call: `(state, t, x_measured) -> (state, tau2)`."""


class Stateless(AbstractBenchmarkController):
    """A plain `controller(t, x) -> u` (u of shape `(1,)`, the elbow torque) as a benchmark controller."""

    controller: object

    def init(self, x0):
        return jnp.zeros((), x0.dtype)

    def step(self, state, t, x):
        return state, jnp.reshape(jnp.asarray(self.controller(t, x), x.dtype), ())


def as_benchmark_controller(controller) -> AbstractBenchmarkController:
    """`controller` itself if it has `init`/`step`, else `Stateless(controller)`."""
    if isinstance(controller, AbstractBenchmarkController):
        return controller
    if not callable(controller):
        raise ValueError(
            f"leaderboard: a controller must be callable as controller(t, x) -> u, got {type(controller).__name__}"
        )
    return Stateless(controller)


# ---------------------------------------------------------------- the rules


class LeaderboardRules(eqx.Module):
    """The benchmark's settings: simulation, performance normalisation and robustness perturbations.

    The defaults are the acrobot leaderboards' (v2): RK4 at 2 ms for 10 s from rest; swing-up when
    the end effector stays above 0.9 (l1 + l2); costs normalised by 20 s, 60 J, 20 N^2 m^2 s,
    0.1 N m and 400 rad^2/s; a robust case ends within (0.35, 0.35, 1, 1) of upright; 21 sizes per
    perturbation, 10 repetitions of the noisy ones, 50 runs with random torque pulses.
    """

    dt: float = 0.002
    t_final: float = 10.0
    height_fraction: float = 0.9
    normalisation: tuple[float, ...] = (20.0, 60.0, 20.0, 0.1, 400.0)
    tolerance: tuple[float, ...] = (0.35, 0.35, 1.0, 1.0)
    n_sizes: int = 21
    repetitions: int = 10
    model_range: tuple[float, float] = (0.75, 1.25)
    rotor_inertia_max: float = 1e-4
    damping_max: float = 0.1
    coulomb_max: float = 0.2
    velocity_noise_max: float = 0.5
    torque_noise_max: float = 1.1
    responsiveness_range: tuple[float, float] = (0.1, 2.0)
    delay_max: float = 0.04
    pulse_runs: int = 50
    pulses_per_joint: int = 3
    pulse_spacing: float = 1.0
    pulse_width: tuple[float, float] = (0.05, 0.1)
    pulse_amplitude: tuple[float, float] = (0.5, 5.0)
    seed: int = 0

    @property
    def n_steps(self) -> int:
        """The number of controller calls: the lab's `while t < tf: t += dt` loop, counted in float64."""
        t, n = 0.0, 0
        while t < self.t_final:
            t += self.dt
            n += 1
        return n

    @property
    def max_delay_steps(self) -> int:
        return int(self.delay_max / self.dt)


COST_NAMES = ("swingup_time", "energy", "torque_cost", "torque_smoothness", "velocity_cost")
"""The five performance costs, in the order of `Performance.costs` and `LeaderboardRules.normalisation`."""


class Family(str, enum.Enum):  # noqa: UP042 -- StrEnum would change str()/format() of members in JSON and reports
    """The six robustness families."""

    MODEL = "model"
    VELOCITY_NOISE = "velocity_noise"
    TORQUE_NOISE = "torque_noise"
    TORQUE_RESPONSE = "torque_response"
    DELAY = "delay"
    PERTURBATIONS = "perturbations"


MODEL_PARAMETERS = ("Ir", "m1r1", "I1", "b1", "cf1", "m2r2", "m2", "I2", "b2", "cf2")
"""The model parameters varied one at a time, in the rules' order."""


# ---------------------------------------------------------------- one rollout


class Case(eqx.Module):
    """One robustness case: the plant and the imperfections of one rollout (stackable for `vmap`).

    **Fields:** `plant`; `velocity_noise` and `torque_noise` (standard deviations); `responsiveness`
    $k$ in $\\tau = \\tau_{prev} + k(\\tau_{des} - \\tau_{prev})$; `delay_steps` (measurement delay in
    control periods, positions and velocities); `pulse_centre`, `pulse_width`, `pulse_amplitude`
    (shape `(2, n)`: Gaussian torque pulses per joint); `key` for the noise.
    """

    plant: LeaderboardPlant
    velocity_noise: Float[Array, "*batch"]
    torque_noise: Float[Array, "*batch"]
    responsiveness: Float[Array, "*batch"]
    delay_steps: Array
    pulse_centre: Float[Array, "*batch 2 n"]
    pulse_width: Float[Array, "*batch 2 n"]
    pulse_amplitude: Float[Array, "*batch 2 n"]
    key: Key[Array, "*batch"] | UInt32[Array, "*batch 2"]


def nominal_case(plant: LeaderboardPlant | None = None, n_pulses: int = 3) -> Case:
    """The unperturbed case: no noise, an ideal motor, no delay, pulses of zero amplitude."""
    plant = LeaderboardPlant.nominal() if plant is None else plant
    zeros = jnp.zeros((2, n_pulses))
    return Case(
        plant,
        jnp.asarray(0.0),
        jnp.asarray(0.0),
        jnp.asarray(1.0),
        jnp.asarray(0),
        zeros,
        jnp.ones((2, n_pulses)),
        zeros,
        jax.random.key(0),
    )


class Rollout(eqx.Module):
    """A simulated episode: `ts` (N + 1,), true states `xs` (N + 1, 4), applied elbow torques `us` (N,).

    `us` is the torque the plant received at each step (after the motor model, the limit and the
    external pulses), the record the lab's simulator keeps and its scores read.
    """

    ts: Float[Array, " time"]
    xs: Float[Array, "time 4"]
    us: Float[Array, " steps"]


def leaderboard_rollout(controller, case, x0, dt, n_steps, max_delay, record):
    plant = case.plant
    dtype = x0.dtype
    vel_mask = jnp.array([0.0, 0.0, 1.0, 1.0], dtype)
    delay = jnp.clip(case.delay_steps, 0, max_delay)

    def body(carry, k):
        x, history, tau_prev, cstate = carry
        t = k * dt
        # measurement: x(t - delay), the first state standing in before the start (lab's x_values)
        history = jnp.concatenate([x[None], history[:-1]])
        x_meas = history[delay]
        key = jax.random.fold_in(case.key, k)
        k_meas, k_tau = jax.random.split(key)
        x_meas = x_meas + case.velocity_noise * vel_mask * jax.random.normal(k_meas, (4,), dtype)
        cstate, u = controller.step(cstate, t, x_meas)
        u = jnp.asarray(u, dtype)
        # motor: responsiveness on the last applied torque, noise, the limit (0 at the shoulder)
        tau_des = jnp.stack([jnp.zeros((), dtype), u])
        tau = tau_prev + case.responsiveness * (tau_des - tau_prev)
        tau = tau + jnp.stack([jnp.zeros((), dtype), case.torque_noise * jax.random.normal(k_tau, (), dtype)])
        limit = jnp.stack([jnp.zeros((), dtype), plant.torque_limit])
        tau = jnp.clip(tau, -limit, limit)
        # external pulses, added after the limit
        pulses = case.pulse_amplitude * jnp.exp(-((t - case.pulse_centre) ** 2) / (2 * case.pulse_width**2))
        tau = tau + jnp.sum(pulses, axis=1)
        x_next = plant.rk4_step(x, tau, dt)
        out = (x_next, tau[1]) if record else None
        return (x_next, history, tau, cstate), out

    history = jnp.broadcast_to(x0, (max_delay + 1, 4))
    init = (x0, history, jnp.zeros(2, dtype), controller.init(x0))
    (x_final, *_), out = jax.lax.scan(body, init, jnp.arange(n_steps))
    return x_final, out


@eqx.filter_jit
def _simulate(controller, case, x0, dt, n_steps, max_delay):
    _, (xs, us) = leaderboard_rollout(controller, case, x0, dt, n_steps, max_delay, True)
    ts = jnp.arange(n_steps + 1) * dt
    return Rollout(ts, jnp.concatenate([x0[None], xs]), us)


@eqx.filter_jit
def _final_states(controller, cases, x0, dt, n_steps, max_delay):
    return jax.vmap(lambda c: leaderboard_rollout(controller, c, x0, dt, n_steps, max_delay, False)[0])(cases)


def simulate_leaderboard(controller, case: Case | None = None, rules: LeaderboardRules = LeaderboardRules()) -> Rollout:
    """Simulate one benchmark episode from rest (the nominal case by default) and record it.

    The record holds the applied elbow torques (`Rollout`), as the lab's simulator records them.

    **Arguments:**

    - `controller`: an `AbstractBenchmarkController`, or any `controller(t, x) -> u` (JAX-traceable).
    - `case`: the plant and imperfections (`nominal_case()` by default).
    - `rules`: the `LeaderboardRules`.

    **Returns:** a `Rollout` with the true states and the commanded torques.
    """
    controller = as_benchmark_controller(controller)
    case = nominal_case() if case is None else case
    x0 = jnp.zeros(4, jnp.result_type(float))
    return _simulate(controller, case, x0, rules.dt, rules.n_steps, rules.max_delay_steps)


# ---------------------------------------------------------------- performance


class Performance(eqx.Module):
    """The performance score of one episode.

    **Fields:** `costs` (the five costs of `COST_NAMES`, raw), `success` (swung up and stayed),
    `score` $= s\\,(1 - \\frac15 \\sum_i \\tanh(\\pi c_i / n_i))$.
    """

    costs: Float[Array, " 5"]
    success: Array
    score: Float[Array, ""]

    def as_dict(self) -> dict[str, float]:
        out = {name: float(c) for name, c in zip(COST_NAMES, self.costs)}
        out.update(success=bool(self.success), score=float(self.score))
        return out


def performance_costs(
    rollout: Rollout, plant: LeaderboardPlant, rules: LeaderboardRules = LeaderboardRules()
) -> Performance:
    r"""The five leaderboard costs and the score of a recorded episode (`leaderboard.py`'s functions).

    The lab saves the episode as rows of equal length, so it scores the first $N$ of the $N + 1$
    recorded times and states with the $N$ applied torques $u_k$ (`save_trajectory` cuts the
    columns to the shortest). With $T_k$, $X_k$ for $k < N$:

    - swing-up time: $T_i$ for the first $i \ge 1$ from which the end effector stays above
      `height_fraction` $(l_1 + l_2)$ through sample $N - 2$, else $T_{N-1}$ (the lab's backward
      loop); success is a time below $T_{N-1}$;
    - energy $\sum_{k<N-1} |(q_{2,k+1} - q_{2,k}) u_k|$ (the shoulder's torque is zero);
    - torque cost $\sum_{k<N-1} u_k^2 \Delta t_k$; velocity cost
      $\sum_{k<N-1} (\dot q_{1,k}^2 + \dot q_{2,k}^2)\Delta t_k$;
    - torque smoothness: the standard deviation of the $N - 1$ changes $u_{k+1} - u_k$.
    """
    n_u = rollout.us.shape[0]
    ts, xs, us = rollout.ts[:n_u], rollout.xs[:n_u], rollout.us
    dtype = xs.dtype
    up = plant.end_effector_height(xs[:, :2]) > rules.height_fraction * (plant.l1 + plant.l2)
    n = xs.shape[0]
    inner = up[1 : n - 1]  # samples 1 .. N-2, the range the lab's loop visits
    trailing = jnp.flip(jnp.cumprod(jnp.flip(inner).astype(jnp.int32))).astype(bool)
    first = jnp.argmax(trailing) + 1
    index = jnp.where(trailing[-1], first, n - 1)
    swingup_time = ts[index]
    success = index < n - 1
    dt = jnp.diff(ts)
    energy = jnp.sum(jnp.abs(jnp.diff(xs[:, 1]) * us[:-1]))
    torque_cost = jnp.sum(us[:-1] ** 2 * dt)
    smoothness = jnp.std(jnp.diff(us))
    velocity_cost = jnp.sum(jnp.sum(xs[:-1, 2:] ** 2, axis=1) * dt)
    costs = jnp.stack([swingup_time, energy, torque_cost, smoothness, velocity_cost]).astype(dtype)
    norm = jnp.asarray(rules.normalisation, dtype)
    score = success * (1 - jnp.mean(jnp.tanh(jnp.pi * costs / norm)))
    return Performance(costs, success, score)


def performance(
    controller, rules: LeaderboardRules = LeaderboardRules(), plant: LeaderboardPlant | None = None
) -> Performance:
    """Simulate the nominal episode from rest and score it (`performance_costs`)."""
    plant = LeaderboardPlant.nominal() if plant is None else plant
    return performance_costs(simulate_leaderboard(controller, nominal_case(plant), rules), plant, rules)


# ---------------------------------------------------------------- robustness


@dataclasses.dataclass(frozen=True)
class RobustnessCases:
    """The 722 robustness rollouts of the rules, stacked, with what each one varies.

    **Fields:** `cases` (a stacked `Case`); `family` (index into `Family`, per case); `size` (the
    perturbation's size: the varied parameter's value, the noise's sigma, $k$, the delay [s], or
    the run number); `parameter` (index into `MODEL_PARAMETERS` for the model family, else -1);
    `repetition` (per case).
    """

    cases: Case
    family: np.ndarray
    size: np.ndarray
    parameter: np.ndarray
    repetition: np.ndarray


@dataclasses.dataclass(frozen=True)
class _Perturbation:
    """What one robustness case changes from the nominal episode (`Case`'s fields, before stacking).

    `plant`: the plant's parameters (a dict of `NOMINAL_PLANT`'s keys; `None`: nominal);
    `pulses`: `(centre, width, amplitude)`, each `(2, n)` (`None`: no pulses).
    """

    plant: dict | None = None
    velocity_noise: float = 0.0
    torque_noise: float = 0.0
    responsiveness: float = 1.0
    delay_steps: int = 0
    pulses: tuple | None = None


def _sizes(lo, hi, n):
    return np.linspace(lo, hi, n)


def pulse_schedule(rules: LeaderboardRules, rng: np.random.Generator):
    """Random Gaussian torque pulses as `get_random_gauss_perturbation_array` draws them.

    Centres: $2n$ instants, each at least `pulse_spacing` after the previous one with a uniform
    wiggle, shuffled between the joints; widths uniform in `pulse_width`; amplitudes of random sign
    with magnitude uniform in `pulse_amplitude`. Returns `(centre, width, amplitude)`, each `(2, n)`.
    """
    n = 2 * rules.pulses_per_joint
    wiggle = (rules.t_final - (n + 1) * rules.pulse_spacing) / n
    mu = []
    for i in range(n):
        mu.append((rules.pulse_spacing if i == 0 else mu[-1] + rules.pulse_spacing) + rng.random() * wiggle)
    rng.shuffle(mu)
    mu = np.reshape(mu, (2, rules.pulses_per_joint))
    lo, hi = rules.pulse_width
    sigma = lo + rng.random((2, rules.pulses_per_joint)) * (hi - lo)
    a_lo, a_hi = rules.pulse_amplitude
    amp = rng.uniform(-(a_hi - a_lo), a_hi - a_lo, size=(2, rules.pulses_per_joint))
    amp = amp + a_lo * np.sign(amp)
    return mu, sigma, amp


def robustness_cases(
    rules: LeaderboardRules = LeaderboardRules(), plant: LeaderboardPlant | None = None
) -> RobustnessCases:
    """Build every robustness case of the rules (`benchmark_controller.py`'s lists) around `plant`."""
    plant = LeaderboardPlant.nominal() if plant is None else plant
    nominal = {k: float(getattr(plant, k)) for k in NOMINAL_PLANT}
    n = rules.n_sizes
    lo, hi = rules.model_range
    rows = []
    none = (
        np.zeros((2, rules.pulses_per_joint)),
        np.ones((2, rules.pulses_per_joint)),
        np.zeros((2, rules.pulses_per_joint)),
    )

    def add(perturbation=_Perturbation(), *, family=0, size=0.0, parameter=-1, rep=0):
        rows.append((perturbation.plant or nominal, perturbation, family, size, parameter, rep))

    lists = {
        "Ir": _sizes(0.0, rules.rotor_inertia_max, n),
        "m1r1": _sizes(lo, hi, n) * nominal["m1"] * nominal["r1"],
        "I1": _sizes(lo, hi, n) * nominal["I1"],
        "b1": _sizes(-rules.damping_max, rules.damping_max, n),
        "cf1": _sizes(-rules.coulomb_max, rules.coulomb_max, n),
        "m2r2": _sizes(lo, hi, n) * nominal["m2"] * nominal["r2"],
        "m2": _sizes(lo, hi, n) * nominal["m2"],
        "I2": _sizes(lo, hi, n) * nominal["I2"],
        "b2": _sizes(-rules.damping_max, rules.damping_max, n),
        "cf2": _sizes(-rules.coulomb_max, rules.coulomb_max, n),
    }
    for j, name in enumerate(MODEL_PARAMETERS):
        for value in lists[name]:
            p = dict(nominal)
            if name == "m1r1":
                p["r1"] = value / p["m1"]
            elif name == "m2r2":
                p["r2"] = value / p["m2"]
            else:
                p[name] = value
            add(_Perturbation(plant=p), family=0, size=value, parameter=j)
    for sigma in _sizes(0.0, rules.velocity_noise_max, n):
        for r in range(rules.repetitions):
            add(_Perturbation(velocity_noise=sigma), family=1, size=sigma, rep=r)
    for sigma in _sizes(0.0, rules.torque_noise_max, n):
        for r in range(rules.repetitions):
            add(_Perturbation(torque_noise=sigma), family=2, size=sigma, rep=r)
    for k in _sizes(*rules.responsiveness_range, n):
        add(_Perturbation(responsiveness=k), family=3, size=k)
    for delay in _sizes(0.0, rules.delay_max, n):
        add(_Perturbation(delay_steps=int(delay / rules.dt)), family=4, size=delay)
    rng = np.random.default_rng(rules.seed)
    for r in range(rules.pulse_runs):
        add(_Perturbation(pulses=pulse_schedule(rules, rng)), family=5, size=float(r), rep=r)

    perturbations = [row[1] for row in rows]
    pulses = [none if q.pulses is None else q.pulses for q in perturbations]
    plants = LeaderboardPlant(**{k: jnp.asarray([row[0][k] for row in rows], float) for k in NOMINAL_PLANT})
    keys = jax.random.split(jax.random.key(rules.seed), len(rows))
    cases = Case(
        plants,
        jnp.asarray([q.velocity_noise for q in perturbations], float),
        jnp.asarray([q.torque_noise for q in perturbations], float),
        jnp.asarray([q.responsiveness for q in perturbations], float),
        jnp.asarray([q.delay_steps for q in perturbations], jnp.int32),
        jnp.asarray(np.stack([pl[0] for pl in pulses])),
        jnp.asarray(np.stack([pl[1] for pl in pulses])),
        jnp.asarray(np.stack([pl[2] for pl in pulses])),
        keys,
    )
    return RobustnessCases(
        cases,
        np.asarray([r[2] for r in rows]),
        np.asarray([r[3] for r in rows], float),
        np.asarray([r[4] for r in rows]),
        np.asarray([r[5] for r in rows]),
    )


def ends_upright(xs: Float[Array, "*batch 4"], tolerance=(0.35, 0.35, 1.0, 1.0)) -> Array:
    """Whether final states lie within `tolerance` of $(\\pi, 0, 0, 0)$, angles wrapped (the rules' check)."""
    e1 = jnp.mod(xs[..., 0] - jnp.pi + jnp.pi, 2 * jnp.pi) - jnp.pi
    e2 = jnp.mod(xs[..., 1] + jnp.pi, 2 * jnp.pi) - jnp.pi
    err = jnp.stack([e1, e2, xs[..., 2], xs[..., 3]], axis=-1)
    ok = jnp.all(jnp.abs(err) < jnp.broadcast_to(jnp.asarray(tolerance, err.dtype), err.shape), axis=-1)
    return ok & jnp.all(jnp.isfinite(xs), axis=-1)


@dataclasses.dataclass(frozen=True)
class Robustness:
    """The robustness of one controller: the per-case outcomes and the family scores.

    **Fields:** `cases` (the `RobustnessCases` run); `final_states` (per case); `success` (per
    case); `family_scores` (six, in `Family` order: the fraction of sizes that succeed, a noisy size
    succeeding when more than half its repetitions do); `score` (their mean); `seconds` (wall time
    of the evaluation, compilation included).
    """

    cases: RobustnessCases
    final_states: np.ndarray
    success: np.ndarray
    family_scores: np.ndarray
    score: float
    seconds: float

    def table(self) -> dict[str, float]:
        return {f.value: float(s) for f, s in zip(Family, self.family_scores)}

    def curves(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Success against size: per model parameter, and per other family (fraction of repetitions)."""
        c = self.cases
        out = {}
        for j, name in enumerate(MODEL_PARAMETERS):
            m = (c.family == 0) & (c.parameter == j)
            out[f"model:{name}"] = (c.size[m], self.success[m].astype(float))
        for f in list(Family)[1:]:
            m = c.family == list(Family).index(f)
            sizes = np.unique(c.size[m])
            out[f.value] = (sizes, np.asarray([self.success[m & (c.size == s)].mean() for s in sizes]))
        return out


def family_scores(cases: RobustnessCases, success: np.ndarray) -> np.ndarray:
    """The six family scores of per-case successes (`benchmark_scores.py`)."""
    scores = []
    for f in range(len(Family)):
        m = cases.family == f
        if f in (1, 2):  # noisy: a size succeeds when most repetitions do
            sizes = np.unique(cases.size[m])
            scores.append(np.mean([success[m & (cases.size == s)].mean() > 0.5 for s in sizes]))
        else:
            scores.append(success[m].mean())
    return np.asarray(scores)


def robustness(
    controller,
    rules: LeaderboardRules = LeaderboardRules(),
    plant: LeaderboardPlant | None = None,
    cases: RobustnessCases | None = None,
) -> Robustness:
    """Run every robustness case (one compiled, vmapped call) and score it.

    **Arguments:** `controller` (as `simulate_leaderboard`); `rules`; the nominal `plant` the
    perturbations are built around; prebuilt `cases` (from `robustness_cases`) to reuse.
    """
    controller = as_benchmark_controller(controller)
    cases = robustness_cases(rules, plant) if cases is None else cases
    start = time.perf_counter()
    x0 = jnp.zeros(4, jnp.result_type(float))
    final = _final_states(controller, cases.cases, x0, rules.dt, rules.n_steps, rules.max_delay_steps)
    success = np.asarray(ends_upright(final, rules.tolerance))
    seconds = time.perf_counter() - start
    scores = family_scores(cases, success)
    return Robustness(cases, np.asarray(final), success, scores, float(np.mean(scores)), seconds)
