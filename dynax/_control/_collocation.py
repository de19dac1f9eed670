r"""The from-rest swing-up reference by many-start direct collocation against the leaderboard's score.

The reference is the elbow torque at knots `knot_spacing` apart, piecewise linear, zero at the
start and at the end ($6\tanh(w)$ within the limit), from the hanging rest to upright at rest in
`horizon` seconds. Direct collocation makes the states at the knots free besides the torques, with
the defects of the RK4 steps between knots as equality constraints: a collocation with zero
defects is a shooting trajectory, and unlike single shooting its early torques are not
exponentially sensitive, so many starts far from a solution converge (Betts, *Practical Methods
for Optimal Control Using Nonlinear Programming*, 2010, ch. 4). The objective is the score's own
mean of $\tanh(\pi c_i / n_i)$ over the five costs (the swing-up time as the time the end effector
spends below the line, a sigmoid of its height; `score_surrogate`'s definitions).

Each stage is an augmented Lagrangian (Nocedal & Wright, *Numerical Optimization*, 2006, §17.3):
`rounds` multiplier updates $\lambda \leftarrow \lambda + \rho d$ with the penalty $\rho$ growing by
1.25 per round from 10, each round `inner` Adam steps on
$f + \lambda^\top d + \tfrac{\rho}{2} \lVert d \rVert^2$ (the step size decaying from
`learning_rate` to a tenth of it over the stage), then minimum-norm Gauss-Newton steps onto zero
defects. The stages are a continuation: the first runs every start at a 10 ms RK4 step, each later
one continues the best few of the stage before with a smaller step size, the last at the
benchmark's own 2 ms step. A start is a pumping pattern (`PumpingStarts`), all of a stage's in one
`vmap`; the shoulder always turns to $+\pi$: the plant is symmetric under
$(q, \dot q, \tau) \to (-q, -\dot q, -\tau)$, so a swing-up to $-\pi$ is the mirror image of one
to $+\pi$ with the same costs.
"""

import time

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np
import optax

from .._progress import bar_token, ProgressBar, report
from ._leaderboard import LeaderboardPlant, LeaderboardRules

_SCALE = (1.0, 1.0, 0.3, 0.3)  # defects in rad and rad/s


class CollocationStage(eqx.Module):
    """One stage of `ReferenceSearch`'s continuation.

    **Fields:** `continue_best`: how many of the previous stage's best collocations it continues
    (ignored by the first stage, which runs every start); `sub_dt` [s]: the RK4 step within a knot
    interval (a divisor of the knot spacing); `learning_rate`: Adam's initial step size (decaying to
    a tenth over the stage); `rounds`: multiplier updates; `inner`: Adam steps per round.
    """

    continue_best: int = 0
    sub_dt: float = 0.01
    learning_rate: float = 0.01
    rounds: int = 30
    inner: int = 200


class PumpingStarts(eqx.Module):
    r"""Initial guesses from the way an acrobot is pumped: the shoulder swung back, then turned over.

    Each guess is a motion $q(s)$, $s = t / T$: the shoulder $q_1 = \pi (3s^2 - 2s^3) - a_b
    \sin(\pi b s)$ (turned over smoothly after `b` back-swings of size `back_amplitude`), the elbow
    $q_2 = a_e \sin(\pi p s) \sqrt{\sin \pi s}$ (`p` half-periods of amplitude $a_e$, either way),
    its velocities by finite differences, and as first torques the elbow torque of the guessed
    motion by the elbow's own equation of motion, clipped within 95 % of the limit. The guesses are
    the grid of `back_swings` x `elbow_half_periods` x `elbow_amplitudes`, in that order (its first
    `number` only, when given). With `seed` > 0 each guess's two amplitudes are scaled by random
    factors between 0.75 and 1.25 (another set of starts of the same patterns).
    """

    back_swings: tuple[int, ...] = (1, 2)
    elbow_half_periods: tuple[int, ...] = (1, 2)
    elbow_amplitudes: tuple[float, ...] = (2.0, 1.0, -1.0, -2.0)
    back_amplitude: float = 0.7
    number: int | None = None
    seed: int = 0

    def grid(self) -> list[tuple[int, int, float]]:
        g = [(b, p, a) for b in self.back_swings for p in self.elbow_half_periods for a in self.elbow_amplitudes]
        return g if self.number is None else g[: self.number]

    def guesses(self, plant: LeaderboardPlant, n: int, h: float, limit: float):
        """The decision vectors `(starts, 5 (n - 1))` (knot states 1..n-1, then `arctanh(u / limit)`) and labels."""
        s = np.arange(n + 1) / n
        t = s * n * h
        zs, labels = [], []
        rng = np.random.default_rng(self.seed)
        for back, pumps, a_elbow in self.grid():
            a_back = self.back_amplitude
            if self.seed:
                a_back, a_elbow = a_back * rng.uniform(0.75, 1.25), a_elbow * rng.uniform(0.75, 1.25)
            q1 = np.pi * s**2 * (3 - 2 * s) - a_back * np.sin(np.pi * back * s)
            q2 = a_elbow * np.sin(np.pi * pumps * s) * np.sin(np.pi * s) ** 0.5
            v1, v2 = np.gradient(q1, t), np.gradient(q2, t)
            a1, a2 = np.gradient(v1, t), np.gradient(v2, t)
            x = np.stack([q1, q2, v1, v2], axis=1)
            h_c = float(plant.m2 * plant.l1 * plant.r2)
            tau = (
                (float(plant.I2) + h_c * np.cos(q2)) * a1
                + float(plant.I2) * a2
                + h_c * np.sin(q2) * v1**2
                + float(plant.m2 * plant.g * plant.r2) * np.sin(q1 + q2)
            )
            tau = np.clip(tau[1:n], -0.95 * limit, 0.95 * limit)
            zs.append(np.concatenate([x[1:n].ravel(), np.arctanh(tau / limit)]))
            labels.append(
                dict(back_swings=back, elbow_half_periods=pumps, back_amplitude=a_back, elbow_amplitude=a_elbow)
            )
        return np.stack(zs), labels


def _default_stages() -> tuple[CollocationStage, ...]:
    return (
        CollocationStage(0, 0.01, 0.01),
        CollocationStage(2, 0.01, 0.003),
        CollocationStage(1, 0.002, 0.001),
    )


class ReferenceSearch(eqx.Module):
    """How `search_reference` finds the swing-up reference.

    **Fields:** `horizon` [s]: the reference's length; `knot_spacing` [s]: the spacing of its
    torque knots; `starts`: the initial guesses (`PumpingStarts`); `stages`: the continuation
    (`CollocationStage`s: every start at a 10 ms step, the best two with a smaller step size, the
    best at the benchmark's 2 ms); `feasible`: the largest defect a first-stage collocation may keep
    to be continued; `torque_limit` [N m].
    """

    horizon: float = 1.5
    knot_spacing: float = 0.02
    starts: PumpingStarts = PumpingStarts()
    stages: tuple[CollocationStage, ...] = eqx.field(default_factory=_default_stages)
    feasible: float = 0.05
    torque_limit: float = 6.0


class Transcription(eqx.Module):
    """The collocation's unknowns: `n` knot intervals `knot_spacing` apart from the hanging rest to
    `end` (upright at rest by default), the torques zero at both ends and `torque_limit tanh(w)` between.

    A decision vector is the free knot states 1..n-1 `(4 (n - 1))`, then the `w` of knots 1..n-1.
    """

    n: int = eqx.field(static=True)
    knot_spacing: float = eqx.field(static=True, default=0.02)
    torque_limit: float = eqx.field(static=True, default=6.0)
    end: Float[Array, " 4"] = eqx.field(default_factory=lambda: jnp.array([jnp.pi, 0.0, 0.0, 0.0]))

    def unpack(self, z):
        """Knot states `(n + 1, 4)` and knot torques `(n + 1,)` of a decision vector."""
        n = self.n
        xs = jnp.concatenate(
            [jnp.zeros((1, 4), z.dtype), z[: 4 * (n - 1)].reshape(n - 1, 4), self.end[None].astype(z.dtype)]
        )
        w = z[4 * (n - 1) :]
        u = jnp.concatenate([jnp.zeros(1, z.dtype), self.torque_limit * jnp.tanh(w), jnp.zeros(1, z.dtype)])
        return xs, u

    def pack(self, xs, u):
        """The decision vector of knot states `(n + 1, 4)` and torques `(n + 1,)` (their ends dropped)."""
        w = jnp.arctanh(jnp.clip(jnp.asarray(u)[1:-1] / self.torque_limit, -0.999999, 0.999999))
        return jnp.concatenate([jnp.asarray(xs)[1:-1].ravel(), w])


def _interval(plant, x, ua, ub, sub_dt, m):
    """`m` RK4 steps of `sub_dt` from `x`, the torque interpolated from `ua` to `ub` at each step's start:
    the steps' start states `(m, 4)`, their torques `(m,)` and the end state."""

    def sub(x, j):
        uj = ua + (ub - ua) * j / m
        return plant.rk4_step(x, jnp.stack([jnp.zeros_like(uj), uj]), sub_dt), (x, uj)

    x, (starts, torques) = jax.lax.scan(sub, x, jnp.arange(m, dtype=x.dtype))  # a loop: small to compile
    return starts, torques, x


def defect_jacobian(plant, z, tr: Transcription, sub_dt):
    """The scaled defects' Jacobian `(4 n, 5 (n - 1))` with respect to the decision vector, from the
    intervals' own Jacobians: interval k's defect depends only on the knot states k and k + 1 and the
    knot torques k and k + 1, so six forward-mode directions per interval give the whole (banded) matrix."""
    n, limit = tr.n, tr.torque_limit
    m = int(round(tr.knot_spacing / sub_dt))
    xs, u = tr.unpack(z)

    def end(x, ua, ub):
        return _interval(plant, x, ua, ub, sub_dt, m)[2]

    a, b, c = jax.vmap(jax.jacfwd(end, argnums=(0, 1, 2)))(xs[:-1], u[:-1], u[1:])  # (n, 4, 4), (n, 4), (n, 4)
    du = limit * (1 - jnp.tanh(z[4 * (n - 1) :]) ** 2)  # du/dw at knots 1..n-1
    scale = jnp.asarray(_SCALE, z.dtype)
    j = jnp.zeros((n, 4, 5 * (n - 1)), z.dtype)
    k = jnp.arange(1, n)  # intervals that start at a free knot
    cols = 4 * (k - 1)[:, None] + jnp.arange(4)[None]
    j = j.at[k[:, None, None], jnp.arange(4)[None, :, None], cols[:, None, :]].set(a[1:])
    j = j.at[k, :, 4 * (n - 1) + k - 1].set(b[1:] * du[:, None])
    k = jnp.arange(0, n - 1)  # intervals that end at a free knot
    cols = 4 * k[:, None] + jnp.arange(4)[None]
    j = j.at[k[:, None, None], jnp.arange(4)[None, :, None], cols[:, None, :]].add(-jnp.eye(4, dtype=z.dtype)[None])
    j = j.at[k, :, 4 * (n - 1) + k].set(c[:-1] * du[:, None])
    return (j * scale[None, :, None]).reshape(4 * n, 5 * (n - 1))


def collocation_costs(plant, xs, u, h, sub_dt, rules: LeaderboardRules = LeaderboardRules(), sharpness=0.01):
    """The five smooth costs of a collocated trajectory and its scaled RK4 defects `(n, 4)`.

    `xs` `(n + 1, 4)` are the knot states, `u` `(n + 1,)` the knot torques; between knots `h`
    apart, RK4 steps of `sub_dt` with the torque interpolated at each step's start (the shooting's
    steps). The costs are `score_surrogate`'s: the time below the line, the energy, the torque cost,
    the smoothness over the whole episode and the velocity cost.
    """
    m = int(round(h / sub_dt))
    starts, steps_u, ends = jax.vmap(lambda x, ua, ub: _interval(plant, x, ua, ub, sub_dt, m))(xs[:-1], u[:-1], u[1:])
    q2_next = jnp.concatenate([starts[:, 1:, 1], xs[1:, 1:2]], axis=1).reshape(-1)
    starts, steps_u = starts.reshape(-1, 4), steps_u.reshape(-1)
    line = rules.height_fraction * (plant.l1 + plant.l2)
    below = jnp.sum(jax.nn.sigmoid((line - plant.end_effector_height(starts[:, :2])) / sharpness)) * sub_dt
    energy = jnp.sum(jnp.abs((q2_next - starts[:, 1]) * steps_u))
    torque = jnp.sum(steps_u**2) * sub_dt
    smooth = jnp.sqrt(jnp.sum(jnp.diff(u) ** 2) * rules.dt / h / (rules.n_steps - 1) + 1e-14)
    velocity = jnp.sum(starts[:, 2:] ** 2) * sub_dt
    defects = (ends - xs[1:]) * jnp.asarray(_SCALE, xs.dtype)[None]
    return jnp.stack([below, energy, torque, smooth, velocity]), defects


@eqx.filter_jit
def _round(plant, iterate, r, lr, token, tr: Transcription, stage: CollocationStage):
    """One augmented-Lagrangian round (`inner` Adam steps, then the multiplier update) for every start; `iterate` is
    `(z, lam, state)`: the decision vectors, the multipliers and Adam's state."""
    z, lam, state = iterate
    norm = jnp.asarray(LeaderboardRules().normalisation)
    total = stage.rounds * stage.inner
    adam = optax.scale_by_adam()

    def costs(z):
        xs, u = tr.unpack(z)
        return collocation_costs(plant, xs, u, tr.knot_spacing, stage.sub_dt)

    def one(z, lam, state):
        rho = 10.0 * 1.25**r

        def lagrangian(z):
            c, d = costs(z)
            return jnp.mean(jnp.tanh(jnp.pi * c / norm)) + jnp.sum(lam * d) + 0.5 * rho * jnp.sum(d**2)

        def step(carry, i):
            z, state = carry
            g = jax.grad(lagrangian)(z)
            upd, state = adam.update(g, state)
            rate = lr * 0.1 ** ((r * stage.inner + i) / total)
            return (z - rate * upd, state), None

        (z, state), _ = jax.lax.scan(step, (z, state), jnp.arange(stage.inner))
        c, d = costs(z)
        return z, lam + rho * d, state, jnp.mean(jnp.tanh(jnp.pi * c / norm)), jnp.max(jnp.abs(d))

    z, lam, state, f, dmax = jax.vmap(one)(z, lam, state)
    report(token, r, best_score=jnp.max(jnp.where(dmax < 0.05, 1 - f, 0.0)), defect=jnp.min(dmax))
    return z, lam, state


@eqx.filter_jit
def _project(plant, z, tr: Transcription, stage: CollocationStage, steps=20):
    """Minimum-norm Gauss-Newton steps onto zero defects (full where they lower them, else a tenth);
    returns the knots, the surrogate (mean tanh term), the five costs and the largest defect per start."""
    norm = jnp.asarray(LeaderboardRules().normalisation)

    def costs(z):
        xs, u = tr.unpack(z)
        return collocation_costs(plant, xs, u, tr.knot_spacing, stage.sub_dt)

    def one(z):
        def defects(z):
            return costs(z)[1].ravel()

        def gauss_newton(z, _):
            d, j = defects(z), defect_jacobian(plant, z, tr, stage.sub_dt)
            step = j.T @ jnp.linalg.solve(j @ j.T + 1e-10 * jnp.eye(d.shape[0]), d)
            full, short = z - step, z - 0.1 * step
            z_new = jnp.where(jnp.sum(defects(full) ** 2) < jnp.sum(d**2), full, short)
            return jnp.where(jnp.all(jnp.isfinite(z_new)), z_new, z), None

        z, _ = jax.lax.scan(gauss_newton, z, None, length=steps)
        c, d = costs(z)
        return z, jnp.mean(jnp.tanh(jnp.pi * c / norm)), c, jnp.max(jnp.abs(d))

    return jax.lax.map(one, z)  # one start at a time: batched dense solves are slow on the CPU


def collocate(plant, z0, tr: Transcription, stage: CollocationStage, bar: ProgressBar | None = None):
    """Run one `CollocationStage` from the decision vectors `z0` `(starts, 5 (n - 1))` of `tr`, all in one `vmap`.

    **Returns:** `(z, surrogate, costs, defect)` per start: the decision vectors after the
    Gauss-Newton projection, the mean of $\\tanh(\\pi c / n)$ (lower is better; the score is one
    minus it), the five costs and the largest scaled defect.
    """
    z = jnp.asarray(z0)
    lam = jnp.zeros((z.shape[0], tr.n, 4), z.dtype)
    state = jax.vmap(optax.scale_by_adam().init)(z)
    lr, token = jnp.asarray(stage.learning_rate, z.dtype), bar_token(bar)
    for r in range(stage.rounds):
        z, lam, state = _round(plant, (z, lam, state), jnp.asarray(r, z.dtype), lr, token, tr, stage)
    return _project(plant, z, tr, stage)


def _say(line: str) -> None:
    print(line, flush=True)


def search_reference(plant: LeaderboardPlant | None = None, search: ReferenceSearch = ReferenceSearch(), say=None):
    """The swing-up reference's candidates by `search`'s continuation of collocations, best first.

    **Arguments:** `plant` (the benchmark's nominal by default); `search` (`ReferenceSearch`);
    `say(line)` reports each stage (a progress bar is drawn per stage where bars are on).

    **Returns:** a list of dicts, best surrogate first, each with `knots` (the torques at the
    knots, zero at both ends), `surrogate` (the score's smooth surrogate, one minus the mean tanh
    term), `costs`, `defect` and the `start` it came from (`PumpingStarts`' labels).
    """
    plant = LeaderboardPlant.nominal() if plant is None else plant
    say = _say if say is None else say
    h, limit = search.knot_spacing, search.torque_limit
    n = int(round(search.horizon / h))
    if n < 3 or abs(n * h - search.horizon) > 1e-9:
        raise ValueError(f"ReferenceSearch: horizon {search.horizon} is not a whole number (>= 3) of knot spacings {h}")
    if not search.stages:
        raise ValueError("ReferenceSearch: at least one stage is needed")
    tr = Transcription(n, h, limit)
    z0, labels = search.starts.guesses(plant, n, h, limit)
    z = jnp.asarray(z0)
    keep = np.arange(len(labels))
    t0 = time.perf_counter()
    surrogate, defect, costs = np.zeros(0), np.zeros(0), np.zeros((0, 5))
    for i, stage in enumerate(search.stages):
        if i > 0:
            ok = defect < search.feasible
            order = np.argsort(np.where(ok, -surrogate, np.inf), kind="stable")
            best = order[: min(stage.continue_best, int(ok.sum()))]
            if best.size == 0:
                raise RuntimeError(
                    f"search_reference: no collocation with defects below {search.feasible} after stage {i}"
                )
            z, keep = z[best], keep[best]
        m = round(h / stage.sub_dt)
        if abs(m * stage.sub_dt - h) > 1e-12:
            raise ValueError(f"CollocationStage: sub_dt {stage.sub_dt} does not divide the knot spacing {h}")
        description = f"stage {i + 1}/{len(search.stages)}: {len(keep)} start(s), {1e3 * stage.sub_dt:g} ms"
        with ProgressBar(stage.rounds, description, unit="round", reduce="max") as bar:
            z, f, c, d = collocate(plant, z, tr, stage, bar)
        surrogate, costs, defect = 1 - np.asarray(f), np.asarray(c), np.asarray(d)
        ok = defect < search.feasible
        say(
            f"{description} (lr {stage.learning_rate:g}): {int(ok.sum())} with defects < {search.feasible}, "
            f"best surrogate scores {np.round(np.sort(surrogate[ok])[::-1][:4], 3).tolist()} "
            f"[{time.perf_counter() - t0:.0f} s]"
        )
    order = np.argsort(np.where(defect < search.feasible, -surrogate, np.inf), kind="stable")
    return [
        dict(
            knots=np.asarray(tr.unpack(z[j])[1]),
            surrogate=float(surrogate[j]),
            costs=costs[j].tolist(),
            defect=float(defect[j]),
            start=labels[int(keep[j])],
        )
        for j in order
    ]
