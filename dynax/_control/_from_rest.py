r"""Swing-up from the hanging rest: an optimised trajectory tracked by time-varying LQR, then LQR
balance with an energy-shaping recovery, for the RealAIGym acrobot.

The controller is one set of arrays: the reference $(x_k, u_k)$ and the time-varying gains $K_k$
for the first `n_ref` control periods, the balancing LQR, and Spong's energy-shaping swing-up in
the controller's model for when a disturbance knocks the arm out of the balancing region. It
estimates the velocities from the measured positions (a backward difference over one period), so
noise on the measured velocities does not reach the torque. `SwingUpFromRest` runs inside the
JAX benchmark (`step`); `RobotController` is the same law in numpy for a real-time loop, and
both are saved to and loaded from one `.npz` file.
"""

import json
import pathlib
import zipfile

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._errors import DataError, UsageError
from ._leaderboard import AbstractBenchmarkController, LeaderboardPlant

FORMAT = "dynax-acrobot-swing-up"
VERSION = 1
_ARRAYS = ("x_ref", "u_ref", "gains", "k_balance", "s_balance", "model", "swing_up")
_SCALARS = ("dt", "torque_limit", "threshold", "velocity_source")
_OPTIONAL = {"lead": 0.0}
_OPTIONAL_ARRAYS = ("x_track",)


def _wrap(a):
    return jnp.mod(a + jnp.pi, 2 * jnp.pi) - jnp.pi


class SwingUpFromRest(AbstractBenchmarkController):
    r"""Trajectory + time-varying LQR from rest, then LQR balance, with energy shaping to recover.

    At control period $k < $ `n_ref` the torque is $u_k - K_k (\hat x - \hat x_k)$, where
    $\hat x_k$ (`x_track`) is the reference as the estimate below sees it when the plant follows
    the reference exactly (`estimator_view`; the reference $x_k$ itself when `x_track` is None),
    so on the controller's model the feedback is zero and the closed loop follows the reference;
    afterwards it is
    the balancing LQR $-K (\hat x \ominus x_{up})$ when its cost-to-go per second, $\Delta t\,\delta x^\top S \delta x$
    (the discrete Riccati solution summed at the control rate), is below `threshold`,
    else Spong's energy-shaping swing-up $u_e + u_p$ in the controller's model
    (`SpongController.swing_up_torque`'s law with gains $(k_e, k_p, k_d)$). The torque is
    saturated at `torque_limit`. $\hat x$ is the measured state with the velocities replaced by
    the backward difference of the measured positions when `velocity_source` is 1, predicted
    `lead` seconds ahead by one Euler step of the model with the last torque (0: no prediction).

    **Fields:** `x_ref` `(n_ref, 4)`, `u_ref` `(n_ref,)`, `gains` `(n_ref, 4)`; `k_balance` `(4,)`
    and `s_balance` `(4, 4)` (LQR gain and cost-to-go); `model` (the controller's plant, the 16
    `LeaderboardPlant` fields); `swing_up` $(k_e, k_p, k_d)$; `dt`, `torque_limit`, `threshold`,
    `velocity_source` (1: from positions, 0: as measured); `x_track` `(n_ref, 4)` or None.
    """

    x_ref: Float[Array, "n 4"]
    u_ref: Float[Array, " n"]
    gains: Float[Array, "n 4"]
    k_balance: Float[Array, " 4"]
    s_balance: Float[Array, "4 4"]
    model: Float[Array, " 16"]
    swing_up: Float[Array, " 3"]
    threshold: Float[Array, ""]
    lead: Float[Array, ""]
    dt: float = eqx.field(static=True)
    torque_limit: float = eqx.field(static=True)
    velocity_source: int = eqx.field(static=True, default=1)
    x_track: Float[Array, "n 4"] | None = None

    @property
    def plant(self) -> LeaderboardPlant:
        return LeaderboardPlant(*self.model)

    def init(self, x0):
        return (x0[:2], jnp.zeros((), jnp.int32), jnp.zeros((), x0.dtype))

    def estimate(self, state, x):
        """The state the torque is computed for: velocities from positions, then `lead` seconds ahead."""
        q_prev, k, u_prev = state
        v_fd = (x[:2] - q_prev) / self.dt
        v = jnp.where(k > 0, v_fd, x[2:]) if self.velocity_source else x[2:]
        xh = jnp.concatenate([x[:2], v])
        return xh + self.lead * self.plant.vector_field(xh, jnp.stack([jnp.zeros_like(u_prev), u_prev]))

    def torque(self, k, x):
        """The torque at control period `k` for the estimated state `x` (unsaturated)."""
        n = self.u_ref.shape[0]
        i = jnp.minimum(k, n - 1)
        x_track = self.x_ref if self.x_track is None else self.x_track
        u_track = self.u_ref[i] - self.gains[i] @ (x - x_track[i])
        err = jnp.stack([_wrap(x[0] - jnp.pi), _wrap(x[1]), x[2], x[3]])
        u_lqr = -self.k_balance @ err
        v = self.dt * (err @ self.s_balance @ err)
        u_pump = _spong(self.plant, self.swing_up, x)
        u_after = jnp.where(v < self.threshold, u_lqr, u_pump)
        return jnp.where(k < n, u_track, u_after)

    def step(self, state, t, x):
        xh = self.estimate(state, x)
        u = jnp.clip(self.torque(state[1], xh), -self.torque_limit, self.torque_limit)
        return (x[:2], state[1] + 1, u), u

    # ------------------------------------------------------------ files

    def save(self, path) -> pathlib.Path:
        """Write the controller to `path` (`.npz`: its arrays and a JSON header)."""
        path = pathlib.Path(path)
        header = dict(format=FORMAT, version=VERSION, **{k: float(getattr(self, k)) for k in _SCALARS})
        header["velocity_source"] = int(self.velocity_source)
        header["lead"] = float(self.lead)
        arrays = {k: np.asarray(getattr(self, k), np.float64) for k in _ARRAYS}
        if self.x_track is not None:
            arrays["x_track"] = np.asarray(self.x_track, np.float64)
        with open(path, "wb") as f:
            np.savez(f, header=np.asarray(json.dumps(header)), **arrays)
        return path


def _spong(plant, gains, x):
    """Spong's collocated energy-shaping swing-up torque in `plant` (friction-free model)."""
    k_e, k_p, k_d = gains[0], gains[1], gains[2]
    q, dq = x[:2], x[2:]
    m00, m01, m11 = plant.mass_matrix(q)
    det = m00 * m11 - m01 * m01
    a2, a3 = -m01 / det, m00 / det
    h = plant.m2 * plant.l1 * plant.r2 * jnp.sin(q[1])
    s1, s12 = jnp.sin(q[0]), jnp.sin(q[0] + q[1])
    bias0 = (
        -2 * h * dq[1] * dq[0]
        - h * dq[1] ** 2
        + plant.g * (plant.m1 * plant.r1 + plant.m2 * plant.l1) * s1
        + plant.g * plant.m2 * plant.r2 * s12
    )
    bias1 = h * dq[0] ** 2 + plant.g * plant.m2 * plant.r2 * s12
    e_up = plant.g * (plant.m1 * plant.r1 + plant.m2 * (plant.l1 + plant.r2))
    u_e = -k_e * (plant.energy(x) - e_up) * dq[1]
    y = -k_p * q[1] - k_d * dq[1]
    return u_e + (a2 * bias0 + y) / a3 + bias1


# ---------------------------------------------------------------- numpy twin for a robot loop


class RobotController:
    """A saved `SwingUpFromRest` in numpy: `controller(t, x) -> u` for a real-time loop.

    Call it once per control period with the time [s] and the measured state
    `(q1, q2, dq1, dq2)` as float64; it returns the elbow torque as an array of shape `(1,)`. It
    keeps the previous measurement (for the velocity estimate) and counts its calls, so the
    reference is followed period by period from the first call; `reset()` starts over.
    Deterministic: the same calls give the same torques.
    """

    def __init__(self, arrays: dict, header: dict):
        self.header = dict(header)
        self.dt = float(header["dt"])
        self.torque_limit = float(header["torque_limit"])
        self.threshold = float(header["threshold"])
        self.velocity_source = int(header["velocity_source"])
        self.lead = float(header.get("lead", _OPTIONAL["lead"]))
        self.x_ref = np.ascontiguousarray(arrays["x_ref"], np.float64)
        self.u_ref = np.ascontiguousarray(arrays["u_ref"], np.float64)
        self.x_track = np.ascontiguousarray(arrays.get("x_track", arrays["x_ref"]), np.float64)
        self.gains = np.ascontiguousarray(arrays["gains"], np.float64)
        self.k_balance = np.asarray(arrays["k_balance"], np.float64)
        self.s_balance = np.asarray(arrays["s_balance"], np.float64)
        self.model = [float(v) for v in arrays["model"]]
        self.swing_up = [float(v) for v in arrays["swing_up"]]
        (
            self.m1,
            self.m2,
            self.l1,
            self.l2,
            self.r1,
            self.r2,
            self.I1,
            self.I2,
            self.Ir,
            self.gr,
            self.b1,
            self.b2,
            self.cf1,
            self.cf2,
            self.g,
            _,
        ) = self.model
        self.n_ref = self.u_ref.shape[0]
        self.reset()

    def reset(self) -> None:
        self._k = 0
        self._q_prev = None
        self._u_prev = 0.0

    def _mass_matrix(self, c2):
        """The arm's mass matrix entries (rotor inertia through the gear ratio included) at `cos(q2)` = `c2`."""
        hc = self.m2 * self.l1 * self.r2 * c2
        gr2 = self.gr * self.gr * self.Ir
        m00 = self.I1 + self.I2 + self.m2 * self.l1**2 + 2 * hc + gr2 + self.Ir
        return m00, self.I2 + hc - self.gr * self.Ir, self.I2 + gr2

    def _acceleration(self, q1, q2, v1, v2, tau2):
        c2, s2 = np.cos(q2), np.sin(q2)
        s1, s12 = np.sin(q1), np.sin(q1 + q2)
        m00, m01, m11 = self._mass_matrix(c2)
        h = self.m2 * self.l1 * self.r2 * s2
        g = self.g
        rhs0 = (
            -self.m1 * g * self.r1 * s1
            - self.m2 * g * (self.l1 * s1 + self.r2 * s12)
            - (-2 * h * v2 * v1 - h * v2 * v2)
            - self.b1 * v1
            - self.cf1 * np.arctan(100 * v1)
        )
        rhs1 = -self.m2 * g * self.r2 * s12 + tau2 - h * v1 * v1 - self.b2 * v2 - self.cf2 * np.arctan(100 * v2)
        det = m00 * m11 - m01 * m01
        return (m11 * rhs0 - m01 * rhs1) / det, (m00 * rhs1 - m01 * rhs0) / det

    def _spong(self, q1, q2, v1, v2):
        k_e, k_p, k_d = self.swing_up
        c2, s2 = np.cos(q2), np.sin(q2)
        s1, s12 = np.sin(q1), np.sin(q1 + q2)
        m00, m01, m11 = self._mass_matrix(c2)
        det = m00 * m11 - m01 * m01
        a2, a3 = -m01 / det, m00 / det
        h = self.m2 * self.l1 * self.r2 * s2
        g = self.g
        bias0 = (
            -2 * h * v2 * v1
            - h * v2 * v2
            + g * (self.m1 * self.r1 + self.m2 * self.l1) * s1
            + g * self.m2 * self.r2 * s12
        )
        bias1 = h * v1 * v1 + g * self.m2 * self.r2 * s12
        kinetic = 0.5 * (m00 * v1 * v1 + 2 * m01 * v1 * v2 + m11 * v2 * v2)
        potential = g * (
            self.m1 * (-self.r1 * np.cos(q1)) + self.m2 * (-self.l1 * np.cos(q1) - self.r2 * np.cos(q1 + q2))
        )
        e_up = g * (self.m1 * self.r1 + self.m2 * (self.l1 + self.r2))
        u_e = -k_e * (kinetic + potential - e_up) * v2
        return u_e + (a2 * bias0 - k_p * q2 - k_d * v2) / a3 + bias1

    def __call__(self, t, x) -> np.ndarray:
        q1, q2, v1, v2 = float(x[0]), float(x[1]), float(x[2]), float(x[3])
        if self.velocity_source and self._q_prev is not None:
            v1 = (q1 - self._q_prev[0]) / self.dt
            v2 = (q2 - self._q_prev[1]) / self.dt
        self._q_prev = (q1, q2)
        if self.lead:
            a1, a2 = self._acceleration(q1, q2, v1, v2, self._u_prev)
            q1, q2, v1, v2 = q1 + self.lead * v1, q2 + self.lead * v2, v1 + self.lead * a1, v2 + self.lead * a2
        k = self._k
        self._k = k + 1
        if k < self.n_ref:
            r = self.x_track[k]
            kk = self.gains[k]
            u = self.u_ref[k] - (kk[0] * (q1 - r[0]) + kk[1] * (q2 - r[1]) + kk[2] * (v1 - r[2]) + kk[3] * (v2 - r[3]))
        else:
            e = np.array([(q1 - np.pi + np.pi) % (2 * np.pi) - np.pi, (q2 + np.pi) % (2 * np.pi) - np.pi, v1, v2])
            if self.dt * (e @ self.s_balance @ e) < self.threshold:
                u = -float(self.k_balance @ e)
            else:
                u = self._spong(q1, q2, v1, v2)
        u = min(max(u, -self.torque_limit), self.torque_limit)
        self._u_prev = u
        return np.array([u])

    def to_benchmark(self) -> SwingUpFromRest:
        """The same controller as a JAX `SwingUpFromRest` (for `dynax.control.performance` and `robustness`)."""
        return SwingUpFromRest(
            jnp.asarray(self.x_ref),
            jnp.asarray(self.u_ref),
            jnp.asarray(self.gains),
            jnp.asarray(self.k_balance),
            jnp.asarray(self.s_balance),
            jnp.asarray(self.model),
            jnp.asarray(self.swing_up),
            jnp.asarray(self.threshold),
            jnp.asarray(self.lead),
            self.dt,
            self.torque_limit,
            self.velocity_source,
            jnp.asarray(self.x_track),
        )


def load_controller(path) -> RobotController:
    """Load a controller saved by `SwingUpFromRest.save` as a numpy `RobotController`.

    **Arguments:** `path` to the `.npz` file.

    **Returns:** a `RobotController`: `controller(t, x) -> u` on a float64 state, pure numpy.

    **Raises:** `UsageError` when the file is missing, `DataError` when it is not a saved controller.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise UsageError(f"load_controller: no file {str(path)!r}")
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if not isinstance(header, dict) or header.get("format") != FORMAT:
                found = header.get("format") if isinstance(header, dict) else None
                raise DataError(f"load_controller: {str(path)!r} has format {found!r}, expected {FORMAT!r}")
            arrays = {k: np.asarray(data[k]) for k in _ARRAYS}
            arrays |= {k: np.asarray(data[k]) for k in _OPTIONAL_ARRAYS if k in data.files}
    except (ValueError, KeyError, OSError, EOFError, zipfile.BadZipFile) as e:  # a truncated or foreign file
        if isinstance(e, DataError):
            raise
        raise DataError(f"load_controller: {str(path)!r} is not a saved dynax controller ({e})") from None
    missing = [k for k in _SCALARS if k not in header]
    if missing:
        raise DataError(f"load_controller: {str(path)!r} lacks header field(s) {missing}")
    n = arrays["u_ref"].shape
    if (
        len(n) != 1
        or arrays["x_ref"].shape != (n[0], 4)
        or arrays.get("x_track", arrays["x_ref"]).shape != (n[0], 4)
        or arrays["gains"].shape != (n[0], 4)
        or arrays["model"].shape != (16,)
        or arrays["swing_up"].shape != (3,)
        or arrays["k_balance"].shape != (4,)
        or arrays["s_balance"].shape != (4, 4)
    ):
        raise DataError(f"load_controller: {str(path)!r} has arrays of inconsistent shapes")
    if not all(np.all(np.isfinite(a)) for a in arrays.values()):
        raise DataError(f"load_controller: {str(path)!r} holds non-finite numbers")
    return RobotController(arrays, header)


# ---------------------------------------------------------------- design


class SwingUpDesign(eqx.Module):
    """How `design_swing_up` builds a `SwingUpFromRest`.

    `design_swing_up` finds its reference by `ReferenceSearch` (`swing_up_reference`); the search
    fields below (`horizon` to `elbow_range`, `polish_*`) are those of `optimise_swing_up`, the
    earlier single-basin search, and `end_upright` uses `knot_spacing`, `dt` and `torque_limit`.

    **Fields:**

    - `horizon` [s], `knot_spacing` [s]: the reference's length and the spacing of its torque
      knots (piecewise linear, starting at zero torque).
    - `coarse_dt` [s]: the RK4 step of the shooting search (the reference is then refined at `dt`).
    - `starts`, `iterations` (collocation), `shooting_iterations`, `refine_iterations`,
      `learning_rate`, `seed`: the multi-start Adam searches (`optimise_swing_up`).
    - `terminal_weight`: the weight on the distance from upright at the horizon.
    - `elbow_range` [rad]: the elbow angle the reference keeps within (a penalty beyond it; no
      limit by default: the searches with 2.6 rad found costlier swing-ups).
    - `q_track`, `r_track`: the time-varying LQR's costs; `q_balance`, `r_balance`: the balancing LQR's.
    - `threshold`: the cost-to-go below which the balancing LQR acts after the reference.
    - `swing_up`: Spong's $(k_e, k_p, k_d)$ for recovering after a knock.
    - `polish_starts`, `polish_sigma`, `polish_feasibility`, `polish_iterations`,
      `polish_learning_rate`: the search on the hand-over constraint after the shooting
      (`polish_on_constraint`): the shooting's reference and `polish_starts - 1` perturbations of
      its knots (sizes growing to `2 polish_sigma` on the `tanh` scale), `polish_feasibility`
      Gauss-Newton steps back onto the constraint, then `polish_iterations` projected Adam steps
      against the score's smooth surrogate (0 iterations: no polish).
    - `velocity_source`: 1 to estimate velocities from positions, 0 to use the measured ones.
    - `lead` [s]: how far ahead the controller predicts the estimated state (one Euler step of
      its model with the last torque), against measurement delay.
    - `track_estimate`: 1 to compare the estimate with the reference as the estimate sees it
      (`estimator_view`: no feedback while the plant follows the reference, so the nominal
      episode is the reference and scores as it does), 0 to compare it with the reference itself
      (the lagged, predicted estimate then differs from it by about `lead` times the velocity).

    The feedback defaults (`q_track` to `swing_up`) are the mean of a PGPE search over randomised
    plants, noise, delays and torque pulses (`experiments/acrobot_recovery_pgpe.py`, run twice, the
    second run from the first's mean) around the reference of the pipeline without its search on
    the hand-over constraint, to six digits: the success under torque pulses is sensitive to them.
    """

    horizon: float = 2.0
    knot_spacing: float = 0.02
    coarse_dt: float = 0.01
    starts: int = 8
    iterations: int = 12000
    shooting_iterations: int = 1000
    refine_iterations: int = 300
    learning_rate: float = 0.01
    seed: int = 0
    terminal_weight: float = 1000.0
    elbow_range: float = float("inf")
    q_track: tuple[float, ...] = (27.1258, 27.1258, 0.0490508, 0.0490508)
    r_track: float = 13.4084
    q_balance: tuple[float, ...] = (41.7773, 11.0094, 0.117626, 0.284858)
    r_balance: float = 8.08058
    threshold: float = 129.18
    swing_up: tuple[float, float, float] = (15.6466, 36.4042, 3.01587)
    polish_starts: int = 16
    polish_sigma: float = 0.3
    polish_feasibility: int = 80
    polish_iterations: int = 500
    polish_learning_rate: float = 0.003
    velocity_source: int = 1
    lead: float = 0.02
    track_estimate: int = 1
    dt: float = 0.002
    torque_limit: float = 6.0


def knot_matrix(n_steps, dt, spacing, n_knots):
    """Interpolation weights (n_steps, n_knots + 1) from the knots to the step times (piecewise linear)."""
    t = np.arange(n_steps) * dt
    j = np.minimum((t // spacing).astype(int), n_knots - 1)
    frac = (t - j * spacing) / spacing
    w = np.zeros((n_steps, n_knots + 1))
    w[np.arange(n_steps), j] = 1 - frac
    w[np.arange(n_steps), j + 1] = frac
    return jnp.asarray(w)


def open_loop_rollout(plant, us, dt):
    def step(x, u):
        return plant.rk4_step(x, jnp.stack([jnp.zeros_like(u), u]), dt), x

    x_final, xs = jax.lax.scan(step, jnp.zeros(4, us.dtype), us)
    return x_final, xs


def _surrogate(plant, w, interp, dt, fine_dt, limit, terminal_weight, elbow_range=jnp.inf):
    """The leaderboard's smooth costs of an open-loop swing-up plus the distance from upright at its end."""
    knots = jnp.concatenate([jnp.zeros(1, w.dtype), limit * jnp.tanh(w)])
    us = interp @ knots
    x_final, xs = open_loop_rollout(plant, us, dt)
    q2 = jnp.concatenate([xs[:, 1], x_final[1:2]])
    energy = jnp.sum(jnp.abs(jnp.diff(q2) * us))
    torque = jnp.sum(us**2) * dt
    velocity = jnp.sum(xs[:, 2:] ** 2) * dt
    smooth = jnp.std(jnp.diff(us)) * fine_dt / dt
    costs = jnp.tanh(jnp.pi * jnp.stack([energy / 60, torque / 20, smooth / 0.1, velocity / 400]))
    err = jnp.stack([2 * jnp.cos(x_final[0] / 2), 2 * jnp.sin(x_final[1] / 2), 0.5 * x_final[2], 0.5 * x_final[3]])
    elbow = jnp.sum(jax.nn.relu(jnp.abs(xs[:, 1]) - elbow_range) ** 2) * dt
    return jnp.sum(costs) + terminal_weight * (jnp.sum(err**2) + elbow), (jnp.sum(costs), err)


def _adam_search(plant, w0, interp, dt, design, iterations, ramp):
    import optax

    opt = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(design.learning_rate))

    def one(w0):
        def it(carry, i):
            w, s = carry
            weight = jnp.minimum(design.terminal_weight, 0.3 * ramp**i) if ramp > 1 else design.terminal_weight
            (loss, _), g = jax.value_and_grad(_surrogate, argnums=1, has_aux=True)(
                plant, w, interp, dt, design.dt, design.torque_limit, weight, design.elbow_range
            )
            updates, s = opt.update(g, s)
            return (jax.tree.map(lambda a, b: a + b, w, updates), s), loss

        (w, _), losses = jax.lax.scan(it, (w0, opt.init(w0)), jnp.arange(iterations))
        _, (cost, err) = _surrogate(
            plant, w, interp, dt, design.dt, design.torque_limit, design.terminal_weight, design.elbow_range
        )
        return w, cost, jnp.sum(err**2)

    return jax.vmap(one)(w0)


def _collocation_loss(plant, z, rho, n, h, fine_dt, limit, elbow_range):
    xs = jnp.concatenate([jnp.zeros((1, 4), z.dtype), z[: 4 * n].reshape(n, 4)])
    us = limit * jnp.tanh(z[4 * n :])
    step = jax.vmap(lambda x, u: plant.rk4_step(x, jnp.stack([jnp.zeros_like(u), u]), h))
    defects = step(xs[:-1], us) - xs[1:]
    energy = jnp.sum(jnp.abs(jnp.diff(xs[:, 1]) * us))
    costs = jnp.stack(
        [
            energy / 60,
            jnp.sum(us**2) * h / 20,
            jnp.sum(xs[:-1, 2:] ** 2) * h / 400,
            jnp.std(jnp.diff(us)) * fine_dt / h / 0.1,
        ]
    )
    final = xs[-1] - jnp.array([jnp.pi, 0.0, 0.0, 0.0], z.dtype)
    elbow = jnp.sum(jax.nn.relu(jnp.abs(xs[:, 1]) - elbow_range) ** 2)
    return jnp.pi * jnp.sum(costs) + rho * (jnp.sum(defects**2) + jnp.sum(final**2) + elbow)


@eqx.filter_jit
def collocation_reference(plant, z0, design, n, iterations):
    import optax

    opt = optax.adam(design.learning_rate / 3)
    h = design.knot_spacing

    def one(z0):
        def it(carry, i):
            z, s = carry
            rho = jnp.minimum(1e5, 1.0015**i)
            g = jax.grad(_collocation_loss, argnums=1)(
                plant, z, rho, n, h, design.dt, design.torque_limit, design.elbow_range
            )
            updates, s = opt.update(g, s)
            return (z + updates, s), None

        (z, _), _ = jax.lax.scan(it, (z0, opt.init(z0)), jnp.arange(iterations))
        return z

    return jax.vmap(one)(z0)


def optimise_swing_up(plant: LeaderboardPlant, design: SwingUpDesign = SwingUpDesign()):
    """A torque profile from rest to upright: direct collocation, then gradients through RK4 rollouts.

    The elbow torque is piecewise linear between knots `knot_spacing` apart, $6\\tanh(w)$ at each
    knot (so within the limit), zero at the start. The objective is the leaderboard's energy,
    torque cost, smoothness and velocity cost (each $\\pi c / n$, the slope of the score's
    $\\tanh(\\pi c / n)$ at zero, so no cost saturates) plus a penalty on the distance from upright.

    1. Direct collocation at the knots (states and torques free, the RK4 defects penalised with
       a weight that grows to $10^5$), `starts` initial guesses in one `vmap`: rotations of
       $q_1$ to $\\pm\\pi$ with elbow oscillations of different frequencies. Collocation does not
       suffer single shooting's sensitivity to the early torques.
    2. Single shooting from each collocation's torques at `coarse_dt` (Adam on the knots with
       the terminal penalty `terminal_weight`, angles through $2\\cos(q_1/2)$, $2\\sin(q_2/2)$),
       which makes the profile exactly feasible; the best that ends near upright is refined at
       the control period `dt`.
    3. A search on the hand-over constraint (`polish_on_constraint`) from that reference and
       `polish_starts - 1` random perturbations of it, against the score's smooth surrogate
       (the swing-up time included); the best that stays on the constraint is kept.

    **Returns:** `(xs, us)`: the reference states `(n, 4)` at the control periods and the torques `(n,)`.
    """
    n_knots = int(round(design.horizon / design.knot_spacing))
    coarse_steps = int(round(design.horizon / design.coarse_dt))
    fine_steps = int(round(design.horizon / design.dt))
    coarse = knot_matrix(coarse_steps, design.coarse_dt, design.knot_spacing, n_knots)
    fine = knot_matrix(fine_steps, design.dt, design.knot_spacing, n_knots)
    # 1. collocation from guesses that turn q1 either way with different elbow oscillations
    s = np.linspace(0.0, 1.0, n_knots + 1)[1:]
    rng = np.random.default_rng(design.seed)
    guesses = []
    for i in range(design.starts):
        sign = 1.0 if i % 2 == 0 else -1.0
        q1 = sign * np.pi * s
        q2 = 0.5 * np.sin(2 * np.pi * s * (1 + i // 2))
        x = np.stack([q1, q2, np.gradient(q1, design.knot_spacing), np.gradient(q2, design.knot_spacing)], axis=1)
        guesses.append(np.concatenate([x.ravel(), 0.3 * rng.normal(size=n_knots)]))
    z = collocation_reference(plant, jnp.asarray(np.stack(guesses)), design, n_knots, design.iterations)
    # 2. shooting from the collocation torques
    w0 = z[:, 4 * n_knots :]
    w, cost, err = reference_search(plant, w0, coarse, design.coarse_dt, design, design.shooting_iterations, 1.0)
    best = int(jnp.argmin(jnp.where(err < 1e-3, cost, cost + 100 + err)))
    w_best = w[best : best + 1]
    if design.refine_iterations:
        w_best, _, _ = reference_search(plant, w_best, fine, design.dt, design, design.refine_iterations, 1.0)
    if design.polish_iterations:
        # 3. the shooting's reference and perturbations of it, searched on the hand-over constraint
        scale = design.polish_sigma * np.linspace(0.0, 2.0, design.polish_starts)[:, None]
        noise = np.random.default_rng(design.seed).normal(size=(design.polish_starts, n_knots))
        w0 = w_best + jnp.asarray(scale * noise)
        w, _, end, score, _ = polish_on_constraint(plant, w0, coarse, design.coarse_dt, design)
        ok = np.asarray(end) < 1e-4
        if ok.any():
            w_best = w[int(np.argmin(np.where(ok, np.asarray(score), np.inf)))][None]
    w_end = end_upright_residuals(plant, w_best[0], fine, design.dt, design.torque_limit)
    knots = jnp.concatenate([jnp.zeros(1), design.torque_limit * jnp.tanh(w_end)])
    us = fine @ knots
    _, xs = open_loop_rollout(plant, us, design.dt)
    return xs, us


@eqx.filter_jit
def end_upright_residuals(plant, w, interp, dt, limit, iterations=30, max_step=0.5):
    """Gauss-Newton on the knots so the rollout ends exactly upright at rest with zero torque (minimum-norm steps).

    The five residuals are the final state minus the nearest upright rest $(\\pi + 2\\pi i, 2\\pi j, 0, 0)$
    and the last knot's torque (zero upright at rest, so the hand-over to the LQR has no jump);
    each step is $\\Delta w = -J^\\top (J J^\\top + \\epsilon I)^{-1} r$, the smallest change of the
    knots that zeroes the linearised residual, so the optimised costs barely move.
    """

    def final(w):
        knots = jnp.concatenate([jnp.zeros(1, w.dtype), limit * jnp.tanh(w)])
        x_final, _ = open_loop_rollout(plant, interp @ knots, dt)
        return jnp.concatenate([x_final, knots[-1:]])

    x0 = final(w)
    target = jnp.stack(
        [
            jnp.pi + 2 * jnp.pi * jnp.round((x0[0] - jnp.pi) / (2 * jnp.pi)),
            2 * jnp.pi * jnp.round(x0[1] / (2 * jnp.pi)),
            0.0,
            0.0,
            0.0,
        ]
    )

    def it(w, _):
        r = final(w) - target
        j = jax.jacfwd(final)(w)
        step = j.T @ jnp.linalg.solve(j @ j.T + 1e-9 * jnp.eye(5), r)
        norm = jnp.linalg.norm(step)
        step = step * jnp.minimum(1.0, max_step / jnp.maximum(norm, 1e-12))  # damped far from the solution
        return w - step, jnp.sum(r**2)

    w, _ = jax.lax.scan(it, w, None, length=iterations)
    return w


reference_search = eqx.filter_jit(_adam_search)


def _knots(w, limit):
    return jnp.concatenate([jnp.zeros(1, w.dtype), limit * jnp.tanh(w)])


def hand_over_residuals(plant, w, interp, dt, limit):
    """The end of the rollout minus the nearest upright rest, and the last knot's torque (scaled).

    Zero exactly when the reference ends upright at rest with zero torque, where the balancing
    LQR takes over; the nearest whole turns are held fixed (no gradient) within a step.
    """
    knots = _knots(w, limit)
    x, _ = open_loop_rollout(plant, interp @ knots, dt)
    turns = jax.lax.stop_gradient(jnp.round(jnp.stack([x[0] - jnp.pi, x[1]]) / (2 * jnp.pi)))
    return jnp.stack(
        [x[0] - jnp.pi - 2 * jnp.pi * turns[0], x[1] - 2 * jnp.pi * turns[1], 0.3 * x[2], 0.3 * x[3], knots[-1] / limit]
    )


def score_surrogate(plant, w, interp, dt, design, sharpness=0.01):
    """The leaderboard score's smooth surrogate for a reference that ends upright: `(mean tanh term, costs)`.

    The mean of $\\tanh(\\pi c_i / n_i)$ over the five costs, as the score has them, with the
    swing-up time replaced by the time the end effector spends below the line (a sigmoid of its
    height, `sharpness` metres wide) and the torque smoothness by the standard deviation of the
    control-period changes of the piecewise-linear profile over the whole episode (at rest after
    the reference). Lower is better: the score is one minus it.
    """
    from ._leaderboard import LeaderboardRules

    rules = LeaderboardRules(dt=design.dt)
    knots = _knots(w, design.torque_limit)
    us = interp @ knots
    x_final, xs = open_loop_rollout(plant, us, dt)
    line = rules.height_fraction * (plant.l1 + plant.l2)
    below = jnp.sum(jax.nn.sigmoid((line - plant.end_effector_height(xs[:, :2])) / sharpness)) * dt
    q2 = jnp.concatenate([xs[:, 1], x_final[1:2]])
    energy = jnp.sum(jnp.abs(jnp.diff(q2) * us))
    torque = jnp.sum(us**2) * dt
    per_step = jnp.sum(jnp.diff(knots) ** 2) * design.dt / design.knot_spacing
    smooth = jnp.sqrt(per_step / (rules.n_steps - 1) + 1e-14)
    velocity = jnp.sum(xs[:, 2:] ** 2) * dt
    costs = jnp.stack([below, energy, torque, smooth, velocity])
    return jnp.mean(jnp.tanh(jnp.pi * costs / jnp.asarray(rules.normalisation))), costs


def _min_norm(r, j):
    return j.T @ jnp.linalg.solve(j @ j.T + 1e-6 * jnp.eye(j.shape[0]), r)


@eqx.filter_jit
def polish_on_constraint(plant, w0, interp, dt, design):
    """Search torque knots on the hand-over constraint against `score_surrogate`, from each start in one `vmap`.

    From each start `w0[i]`: `polish_feasibility` damped Gauss-Newton steps of minimum norm
    (at most 0.1 each) onto `hand_over_residuals = 0`; then `polish_iterations` Adam steps on
    the surrogate's gradient projected onto the constraint's tangent space
    ($g - J^\\top (J J^\\top)^{-1} J g$), each followed by one Gauss-Newton correction back onto
    it: a reduced-gradient method with restoration.

    **Returns:** `(w, after_feasibility, end, surrogate, costs)` per start: the knots, the squared
    residual after the Gauss-Newton steps and at the end, the surrogate and its five costs.
    """
    import optax

    def res(w):
        return hand_over_residuals(plant, w, interp, dt, design.torque_limit)

    def surrogate(w):
        return score_surrogate(plant, w, interp, dt, design)[0]

    opt = optax.adam(design.polish_learning_rate)

    def one(w0):
        def gn(w, _):
            step = _min_norm(res(w), jax.jacrev(res)(w))
            w = w - step * jnp.minimum(1.0, 0.1 / jnp.maximum(jnp.linalg.norm(step), 1e-12))
            return jnp.where(jnp.all(jnp.isfinite(w)), w, w0), None

        w, _ = jax.lax.scan(gn, w0, None, length=design.polish_feasibility)
        feasible = jnp.sum(res(w) ** 2)

        def it(carry, _):
            w, s = carry
            g = jax.grad(surrogate)(w)
            j = jax.jacrev(res)(w)
            u, s = opt.update(g - _min_norm(j @ g, j), s)
            w_new = w + u
            step = _min_norm(res(w_new), jax.jacrev(res)(w_new))
            w_new = w_new - step * jnp.minimum(1.0, 0.5 / jnp.maximum(jnp.linalg.norm(step), 1e-12))
            return (jnp.where(jnp.all(jnp.isfinite(w_new)), w_new, w), s), None

        (w, _), _ = jax.lax.scan(it, (w, opt.init(w)), None, length=design.polish_iterations)
        score, costs = score_surrogate(plant, w, interp, dt, design)
        return w, feasible, jnp.sum(res(w) ** 2), score, costs

    return jax.vmap(one)(w0)


def end_upright(plant: LeaderboardPlant, us, design: SwingUpDesign = SwingUpDesign()):
    """Re-end a reference's torques `us` (at the control periods, piecewise linear between knots
    `knot_spacing` apart, zero at the start) exactly upright at rest with zero final torque.

    **Returns:** `(xs, us)` of the corrected reference.
    """
    n_steps = us.shape[0]
    per_knot = int(round(design.knot_spacing / design.dt))
    n_knots = n_steps // per_knot
    knots = jnp.concatenate([us[per_knot::per_knot], us[-1:]])[:n_knots]
    w = jnp.arctanh(jnp.clip(knots / design.torque_limit, -0.9999, 0.9999))
    fine = knot_matrix(n_steps, design.dt, design.knot_spacing, n_knots)
    w = end_upright_residuals(plant, w, fine, design.dt, design.torque_limit)
    us = fine @ jnp.concatenate([jnp.zeros(1), design.torque_limit * jnp.tanh(w)])
    _, xs = open_loop_rollout(plant, us, design.dt)
    return xs, us


def _discrete_model(plant, dt):
    def f(x, u):
        return plant.rk4_step(x, jnp.stack([jnp.zeros_like(u), u]), dt)

    return f


@eqx.filter_jit
def balance_lqr(plant: LeaderboardPlant, q, r, dt):
    """The discrete LQR of the RK4 step about upright: `(K, S)` for $u = -K(x \\ominus x_{up})$."""
    from ._riccati import solve_discrete_are

    f = _discrete_model(plant, dt)
    x_up = jnp.array([jnp.pi, 0.0, 0.0, 0.0])
    a = jax.jacfwd(f, 0)(x_up, jnp.zeros(()))
    b = jax.jacfwd(f, 1)(x_up, jnp.zeros(()))[:, None]
    q = jnp.diag(jnp.asarray(q, float))
    r = jnp.asarray(r, float).reshape(1, 1)
    s = solve_discrete_are(a, b, q, r)
    k = jnp.linalg.solve(r + b.T @ s @ b, b.T @ s @ a)
    return k[0], s


@eqx.filter_jit
def tvlqr(plant: LeaderboardPlant, xs, us, q, r, s_final, dt):
    """Time-varying LQR gains along a reference (the discrete Riccati recursion backwards from `s_final`)."""
    f = _discrete_model(plant, dt)
    a = jax.vmap(jax.jacfwd(f, 0))(xs, us)
    b = jax.vmap(jax.jacfwd(f, 1))(xs, us)[:, :, None]
    q = jnp.diag(jnp.asarray(q, float))
    r = jnp.asarray(r, float).reshape(1, 1)

    def back(s, ab):
        a_k, b_k = ab
        k = jnp.linalg.solve(r + b_k.T @ s @ b_k, b_k.T @ s @ a_k)
        s = q + a_k.T @ s @ (a_k - b_k @ k)
        return 0.5 * (s + s.T), k[0]

    _, gains = jax.lax.scan(back, s_final, (a, b), reverse=True)
    return gains


def estimator_view(plant: LeaderboardPlant, xs, us, lead, dt, velocity_source=1):
    r"""The reference `(xs, us)` as `SwingUpFromRest`'s estimate sees it when the plant follows it exactly.

    At period $k$: the positions $q_k$, the velocities $(q_k - q_{k-1}) / \Delta t$ (the
    measured ones at $k = 0$, or always with `velocity_source` 0), predicted `lead` seconds ahead
    by one Euler step of `plant` with the previous torque $u_{k-1}$ ($u_{-1} = 0$).
    """
    xs, us = jnp.asarray(xs), jnp.asarray(us)
    if velocity_source:
        q_prev = jnp.concatenate([xs[:1, :2], xs[:-1, :2]])
        first = (jnp.arange(xs.shape[0]) == 0)[:, None]
        v = jnp.where(first, xs[:, 2:], (xs[:, :2] - q_prev) / dt)
    else:
        v = xs[:, 2:]
    xh = jnp.concatenate([xs[:, :2], v], axis=1)
    u_prev = jnp.concatenate([jnp.zeros(1, us.dtype), us[:-1]])
    f = jax.vmap(lambda x, u: plant.vector_field(x, jnp.stack([jnp.zeros_like(u), u])))(xh, u_prev)
    return xh + lead * f


def swing_up_reference(
    plant: LeaderboardPlant | None = None, search=None, design: SwingUpDesign = SwingUpDesign(), say=None
):
    """The swing-up reference from rest by `search_reference`'s continuation of collocations.

    The best collocation's knot torques (by the score's surrogate) are interpolated to the control
    periods and re-ended exactly upright at rest at `design.dt` (`end_upright`).

    **Arguments:** `plant` (the benchmark's nominal by default), `search` (a `ReferenceSearch`; its
    defaults when None), `design` (its `dt`, `torque_limit`), `say(line)` for the stages' reports (printed by default).

    **Returns:** `(xs, us)`: the reference states `(n, 4)` at the control periods and the torques `(n,)`.
    """
    from ._collocation import ReferenceSearch, search_reference

    plant = LeaderboardPlant.nominal() if plant is None else plant
    search = ReferenceSearch(torque_limit=design.torque_limit) if search is None else search
    knots = np.asarray(search_reference(plant, search, say)[0]["knots"])
    fine = knot_matrix(int(round(search.horizon / design.dt)), design.dt, search.knot_spacing, knots.shape[0] - 1)
    knot_design = eqx.tree_at(lambda d: d.knot_spacing, design, search.knot_spacing)
    return end_upright(plant, fine @ jnp.asarray(knots), knot_design)


def design_swing_up(
    plant: LeaderboardPlant | None = None, design: SwingUpDesign = SwingUpDesign(), reference=None, search=None
) -> SwingUpFromRest:
    """Build a `SwingUpFromRest` for `plant` (the controller's model; the benchmark's nominal by default).

    Finds the reference (`swing_up_reference` with `search`, a `ReferenceSearch`) unless
    `reference = (xs, us)` is given, then computes the balancing LQR and the time-varying gains
    that end in it; with `design.track_estimate` the feedback compares the estimate with
    `estimator_view` of the reference.
    """
    plant = LeaderboardPlant.nominal() if plant is None else plant
    xs, us = swing_up_reference(plant, search, design) if reference is None else reference
    k_bal, s_bal = balance_lqr(plant, design.q_balance, design.r_balance, design.dt)
    gains = tvlqr(plant, xs, us, design.q_track, design.r_track, s_bal, design.dt)
    model = jnp.stack([jnp.asarray(getattr(plant, k), float) for k in LeaderboardPlant.__dataclass_fields__])
    view = estimator_view(plant, xs, us, design.lead, design.dt, design.velocity_source)
    return SwingUpFromRest(
        xs,
        us,
        gains,
        k_bal,
        s_bal,
        model,
        jnp.asarray(design.swing_up, float),
        jnp.asarray(design.threshold, float),
        jnp.asarray(design.lead, float),
        design.dt,
        design.torque_limit,
        design.velocity_source,
        view if design.track_estimate else None,
    )
