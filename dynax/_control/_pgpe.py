"""PGPE: policy gradients with parameter-based exploration, as pure ask/tell functions plus `run`.

The search runs in normalised coordinates $z = \theta / s$ with per-parameter `scales` $s$, so
parameters of very different magnitude (gains of order 10, a threshold of order 1000) share one
exploration width and one step size. Rewards are maximised.
"""

import abc
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from jaxtyping import Array, ArrayLike, Float, Int, Key, PRNGKeyArray, UInt32
import optax

from .._distributed import multi_process, replicate_in_jit
from .._progress import bar_token, progress_enabled, ProgressBar, report

Objective = Callable[[Float[Array, " n_params"], PRNGKeyArray], Float[Array, ""]]
"""`objective(params, key) -> reward`: the episode reward of one parameter vector (maximised).
`key` draws whatever is random in the episode (for example its start state); the two members of
a symmetric pair get the same key (common random numbers)."""


class ClipUpState(eqx.Module):
    velocity: Array


def clipup(step_size: float, max_speed: float | None = None, momentum: float = 0.9) -> optax.GradientTransformation:
    r"""ClipUp: heavy-ball momentum on the normalised gradient, with the velocity norm clipped.

    $v \leftarrow \mu v + \alpha\, g / \|g\|$, then $v \leftarrow v \min(1, v_{max}/\|v\|)$; the
    update is $-v$ (optax's descent convention). The step length is bounded by `max_speed`
    whatever the scale of the fitness, which suits evolution strategies.

    **Arguments:**

    - `step_size`: $\alpha$.
    - `max_speed`: $v_{max}$ (default $2\alpha$).
    - `momentum`: $\mu$.

    **Returns:**

    An `optax.GradientTransformation`.

    ??? cite

        N. E. Toklu, P. Liskowski, R. K. Srivastava, "ClipUp: a simple and powerful optimizer
        for distribution-based policy evolution", PPSN 2020.
    """
    max_speed = 2 * step_size if max_speed is None else max_speed

    def init(params):
        return ClipUpState(jax.tree.map(jnp.zeros_like, params))

    def update(grads, state, params=None):
        del params
        g, unravel = jax.flatten_util.ravel_pytree(grads)
        v, _ = jax.flatten_util.ravel_pytree(state.velocity)
        norm = jnp.linalg.norm(g)
        v = momentum * v + step_size * jnp.where(norm > 0, g / jnp.where(norm > 0, norm, 1.0), 0.0)
        speed = jnp.linalg.norm(v)
        v = v * jnp.minimum(1.0, max_speed / jnp.where(speed > 0, speed, 1.0))
        return unravel(-v), ClipUpState(unravel(v))

    return optax.GradientTransformation(init, update)


class PGPEState(eqx.Module):
    """The state of a PGPE search (normalised coordinates; see `PGPE`).

    **Fields:** `mean` and `sigma` of the search distribution over $z$; the optimiser state;
    `baseline` (moving average of the reward) and `best_reward` (the paper's $m$);
    `best_params` (in parameter units, the best single evaluation so far); `iteration`.
    """

    mean: Float[Array, " n_params"]
    sigma: Float[Array, " n_params"]
    opt_state: optax.OptState
    baseline: Float[Array, ""]
    best_reward: Float[Array, ""]
    best_params: Float[Array, " n_params"]
    iteration: Int[Array, ""]


class AbstractFitnessShaping(eqx.Module):
    """How a batch of symmetric-pair rewards becomes the signals for the mean and sigma updates."""

    @abc.abstractmethod
    def __call__(
        self, r_plus: Float[Array, " pairs"], r_minus: Float[Array, " pairs"], state: PGPEState
    ) -> tuple[Float[Array, " pairs"], Float[Array, " pairs"]]:
        """Return `(mean_signal, sigma_signal)`, one value per pair."""


class BaselineNormalisation(AbstractFitnessShaping):
    r"""Sehnke et al.'s normalisation by the best reward $m$ and a moving-average baseline $b$.

    Mean signal $\frac{r^+ - r^-}{2m - r^+ - r^-}$, sigma signal
    $\frac{(r^+ + r^-)/2 - b}{m - b}$. Both are invariant to shifting and scaling the reward.
    """

    def __call__(self, r_plus, r_minus, state):
        m = state.best_reward
        b = state.baseline
        mean_den = 2 * m - r_plus - r_minus
        sigma_den = m - b
        mean_signal = jnp.where(mean_den > 0, (r_plus - r_minus) / jnp.where(mean_den > 0, mean_den, 1.0), 0.0)
        sigma_signal = jnp.where(
            sigma_den > 0, (0.5 * (r_plus + r_minus) - b) / jnp.where(sigma_den > 0, sigma_den, 1.0), 0.0
        )
        return mean_signal, sigma_signal


class CentredRank(AbstractFitnessShaping):
    r"""Centred-rank fitness shaping: rewards replaced by their ranks mapped to $[-\frac12, \frac12]$.

    Mean signal $u^+ - u^-$ and sigma signal $(u^+ + u^-)/2$ (the ranks are centred, so the
    baseline is zero). Robust to outliers and to the reward's scale.

    ??? cite

        D. Wierstra et al., "Natural evolution strategies", JMLR 15, 2014 (fitness shaping);
        T. Salimans et al., "Evolution strategies as a scalable alternative to reinforcement
        learning", 2017 (centred ranks).
    """

    def __call__(self, r_plus, r_minus, state):
        rewards = jnp.concatenate([r_plus, r_minus])
        n = rewards.shape[0]
        ranks = jnp.argsort(jnp.argsort(rewards)).astype(rewards.dtype)
        u = ranks / (n - 1) - 0.5
        u_plus, u_minus = u[: n // 2], u[n // 2 :]
        return u_plus - u_minus, 0.5 * (u_plus + u_minus)


class PGPE(eqx.Module):
    r"""Policy gradients with parameter-based exploration with symmetric sampling (Sehnke et al. 2010).

    Each iteration draws `population_size // 2` perturbations $\epsilon \sim N(0, \sigma^2)$ and
    evaluates the pairs $\mu \pm \epsilon$. With the fitness shaping's mean signal $r_T$ and
    sigma signal $r_S$ per pair, the mean moves along $\sum_n r_{T,n}\epsilon_n / N$ through
    `optimizer` (plain SGD with the paper's learning rate by default; `clipup` or
    `optax.adam` work too), and the exploration widths follow
    $\sigma \leftarrow \sigma + \alpha_\sigma \sum_n r_{S,n}(\epsilon_n^2 - \sigma^2)/\sigma / N$,
    the change clipped to a fraction `max_sigma_change` of $\sigma$. All of this happens in
    normalised coordinates $z = \theta / s$ with per-parameter `scales` $s$.

    The methods are pure: `init`, `ask`, `tell`; `run` does a whole search in one `lax.scan`
    with the population's episodes `vmap`ped (and sharded across devices when there are
    several), so a search is one compiled function and a sweep over seeds is a `vmap` of it.

    **Arguments:**

    - `population_size`: even number of evaluations per iteration.
    - `scales`: per-parameter scale $s$ (default ones), shape `(n_params,)`.
    - `init_sigma`: initial exploration width in normalised units (scalar or per parameter).
    - `optimizer`: optax transformation for the mean (default `optax.sgd(0.2)`).
    - `sigma_learning_rate`: $\alpha_\sigma$ (default 0.1).
    - `fitness_shaping`: `BaselineNormalisation()` (the paper's, default) or `CentredRank()`.
    - `max_sigma_change`: largest relative change of $\sigma$ per iteration (default 0.2).
    - `min_sigma`: floor on $\sigma$ in normalised units (default 1e-4).
    - `baseline_decay`: the moving-average factor of the baseline (default 0.9).

    ??? cite

        F. Sehnke, C. Osendorfer, T. Rückstieß, A. Graves, J. Peters, J. Schmidhuber,
        "Parameter-exploring policy gradients", Neural Networks 23(4), 2010.
    """

    population_size: int = eqx.field(static=True)
    scales: Float[Array, " n_params"] | None = None
    init_sigma: Float[ArrayLike, "..."] = 0.1
    optimizer: optax.GradientTransformation = eqx.field(static=True, default_factory=lambda: optax.sgd(0.2))
    sigma_learning_rate: Float[ArrayLike, ""] = 0.1
    fitness_shaping: AbstractFitnessShaping = BaselineNormalisation()
    max_sigma_change: float = 0.2
    min_sigma: float = 1e-4
    baseline_decay: float = 0.9

    def __check_init__(self):
        if self.population_size < 2 or self.population_size % 2:
            raise ValueError(f"PGPE: `population_size` must be an even number >= 2, got {self.population_size}")

    def _scales(self, params):
        return jnp.ones_like(params) if self.scales is None else jnp.asarray(self.scales, params.dtype)

    def init(self, params: Float[ArrayLike, " n_params"]) -> PGPEState:
        """The initial state, centred on `params` (in parameter units)."""
        params = jnp.asarray(params)
        if params.ndim != 1:
            raise ValueError(f"PGPE.init: `params` must be a 1-d vector, got shape {params.shape}")
        if not jnp.issubdtype(params.dtype, jnp.floating):
            params = params.astype(float)
        scales = self._scales(params)
        if scales.shape != params.shape:
            raise ValueError(f"PGPE: `scales` must have shape {params.shape}, got {scales.shape}")
        mean = params / scales
        sigma = jnp.broadcast_to(jnp.asarray(self.init_sigma, params.dtype), params.shape)
        return PGPEState(
            mean=mean,
            sigma=sigma,
            opt_state=self.optimizer.init(mean),
            baseline=jnp.asarray(0.0, params.dtype),
            best_reward=jnp.asarray(-jnp.inf, params.dtype),
            best_params=params,
            iteration=jnp.asarray(0),
        )

    def ask(
        self, state: PGPEState, key: PRNGKeyArray
    ) -> tuple[Float[Array, "population n_params"], Float[Array, "pairs n_params"]]:
        """Sample a population: `(params, noise)` with `params[:P/2] = mean + noise`, `params[P/2:] = mean - noise`
        (parameter units)."""
        pairs = self.population_size // 2
        noise = state.sigma[None] * jax.random.normal(key, (pairs, state.mean.shape[0]), state.mean.dtype)
        z = jnp.concatenate([state.mean[None] + noise, state.mean[None] - noise])
        return z * self._scales(state.mean)[None], noise

    def tell(
        self, state: PGPEState, noise: Float[Array, "pairs n_params"], rewards: Float[Array, " population"]
    ) -> PGPEState:
        """Update the search distribution from the rewards of the population `ask` returned."""
        pairs = self.population_size // 2
        rewards = jnp.asarray(rewards, state.mean.dtype)
        if rewards.shape != (self.population_size,):
            raise ValueError(f"PGPE.tell: `rewards` must have shape ({self.population_size},), got {rewards.shape}")
        # A non-finite reward is the worst reward of the batch (a diverged episode).
        finite = jnp.isfinite(rewards)
        worst = jnp.min(jnp.where(finite, rewards, jnp.inf))
        rewards = jnp.where(finite, rewards, jnp.where(jnp.isfinite(worst), worst, 0.0))
        r_plus, r_minus = rewards[:pairs], rewards[pairs:]
        scales = self._scales(state.mean)

        first = state.iteration == 0
        batch_best = jnp.argmax(rewards)
        improved = rewards[batch_best] > state.best_reward
        candidates = jnp.concatenate([state.mean[None] + noise, state.mean[None] - noise]) * scales[None]
        best_params = jnp.where(improved, candidates[batch_best], state.best_params)
        best_reward = jnp.maximum(state.best_reward, rewards[batch_best])
        baseline = jnp.where(first, jnp.mean(rewards), state.baseline)
        shaped_state = eqx.tree_at(lambda s: (s.best_reward, s.baseline), state, (best_reward, baseline))

        mean_signal, sigma_signal = self.fitness_shaping(r_plus, r_minus, shaped_state)
        grad_mean = mean_signal @ noise / pairs
        updates, opt_state = self.optimizer.update(-grad_mean, state.opt_state, state.mean)
        mean = optax.apply_updates(state.mean, updates)

        sigma = state.sigma
        grad_sigma = sigma_signal @ ((noise**2 - sigma[None] ** 2) / sigma[None]) / pairs
        step = jnp.clip(
            self.sigma_learning_rate * grad_sigma, -self.max_sigma_change * sigma, self.max_sigma_change * sigma
        )
        sigma = jnp.maximum(sigma + step, self.min_sigma)

        baseline = self.baseline_decay * baseline + (1 - self.baseline_decay) * jnp.mean(rewards)
        return PGPEState(
            mean=mean,
            sigma=sigma,
            opt_state=opt_state,
            baseline=baseline,
            best_reward=best_reward,
            best_params=best_params,
            iteration=state.iteration + 1,
        )

    def mean_params(self, state: PGPEState) -> Float[Array, " n_params"]:
        """The mean of the search distribution, in parameter units (the usual final answer)."""
        return state.mean * self._scales(state.mean)


class PGPEHistory(eqx.Module):
    """Per-iteration record of `run`: `reward` (population average), `best_reward` (so far),
    `mean_params` (parameter units, before the iteration's update) and `sigma` (normalised)."""

    reward: Float[Array, " *iterations"]
    best_reward: Float[Array, " *iterations"]
    mean_params: Float[Array, "*iterations n_params"]
    sigma: Float[Array, "*iterations n_params"]


def population_sharding(population_size: int) -> NamedSharding | None:
    """A sharding that splits a population's leading axis across all devices, or `None` with one device.

    All devices of all processes: after `dynax.initialize_distributed` (`jax.distributed`),
    `jax.devices()` lists every process's devices, so the population is split across them all.
    `None` also when `population_size` does not divide evenly among the devices.
    """
    devices = jax.devices()
    if len(devices) < 2 or population_size % len(devices):
        return None
    return NamedSharding(Mesh(devices, ("population",)), PartitionSpec("population"))


def evaluate_population(
    objective: Objective,
    population: Float[Array, "population n_params"],
    keys: Key[Array, " population"] | UInt32[Array, "population 2"],
    *,
    shard: bool = True,
) -> Float[Array, " population"]:
    """All episodes of a population as one `vmap`; split across devices when several are present.

    **Arguments:**

    - `objective`: `objective(params, key) -> reward`.
    - `population`: parameter vectors, shape `(population, n_params)`.
    - `keys`: one key per member, shape `(population,)` (or a key array of that length).
    - `shard`: constrain the population axis to be split across devices (`jax.sharding`) when
      more than one device is available; XLA then runs each device's share of the `vmap`. In a
      multi-process run (`dynax.initialize_distributed`) the devices are those of every
      process: each process passes the whole population, evaluates its devices' share, and gets
      all rewards back (called outside `jit`, the evaluation is compiled for that).

    **Returns:**

    The rewards, shape `(population,)`.
    """
    traced = any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((population, keys)))
    if shard and not traced and multi_process():
        return _evaluate_everywhere(objective, population, keys)
    return _evaluate(objective, population, keys, shard)


def _evaluate(objective, population, keys, shard):
    sharding = population_sharding(population.shape[0]) if shard else None
    if sharding is not None:
        population = jax.lax.with_sharding_constraint(population, sharding)
        keys = jax.lax.with_sharding_constraint(keys, sharding)
    return jax.vmap(objective)(population, keys)


@eqx.filter_jit
def _evaluate_everywhere(objective, population, keys):
    return replicate_in_jit(_evaluate(objective, population, keys, True))


def run_pgpe(
    pgpe: PGPE,
    objective: Objective,
    params: Float[ArrayLike, " n_params"],
    key: PRNGKeyArray,
    n_iterations: int,
    *,
    shard: bool = True,
    progress: bool | None = None,
) -> tuple[PGPEState, PGPEHistory]:
    """Run `n_iterations` of PGPE from `params`: one compiled `lax.scan` (`vmap` it over keys for a sweep).

    **Arguments:**

    - `pgpe`: the strategy.
    - `objective`: `objective(params, key) -> reward`, maximised; pairs share a key.
    - `params`: the starting parameters (the initial mean), parameter units.
    - `key`: a PRNG key.
    - `n_iterations`: number of generations (static).
    - `shard`: split each population across devices when several exist (`evaluate_population`),
      in a multi-process run across every process's devices; every process gets the whole result.
    - `progress`: a bar per generation with the best reward so far, on stderr, reported from
      inside the compiled scan (`jax.debug.callback`); `None` draws it when stderr is a terminal
      (see `dynax.internal.progress_mode`). Never drawn when called inside a user's `jit` or `vmap`.

    **Returns:**

    `(state, history)`: the final `PGPEState` and a `PGPEHistory` with one row per iteration.
    """
    return _with_bar(_run_pgpe_jit, "PGPE", _Job(pgpe, objective, params, key, n_iterations, shard), progress)


class _Job(NamedTuple):
    """What one PGPE run (or sweep) is given: strategy, objective, start, key(s), generations, sharding."""

    pgpe: object
    objective: object
    params: object
    key: object
    n_iterations: int
    shard: bool


def _with_bar(run, description, job: _Job, progress):
    traced = any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((job.params, job.key)))
    if traced or not progress_enabled(progress):
        return run(*job, False, bar_token(None))
    with ProgressBar(job.n_iterations, description, progress=True, unit="gen", reduce="max") as bar:
        out = run(*job, True, bar_token(bar))
        jax.block_until_ready(out)
    return out


def _run_pgpe(pgpe, objective, params, key, n_iterations, shard, with_progress, token):
    state = pgpe.init(params)
    pairs = pgpe.population_size // 2

    def generation(state, inputs):
        i, key = inputs
        sample_key, episode_key = jax.random.split(key)
        population, noise = pgpe.ask(state, sample_key)
        pair_keys = jax.random.split(episode_key, pairs)
        keys = jnp.concatenate([pair_keys, pair_keys])
        rewards = evaluate_population(objective, population, keys, shard=shard)
        new_state = pgpe.tell(state, noise, rewards)
        record = PGPEHistory(
            reward=jnp.mean(rewards),
            best_reward=new_state.best_reward,
            mean_params=pgpe.mean_params(state),
            sigma=state.sigma,
        )
        if with_progress:
            report(token, i, best_reward=new_state.best_reward)
        return new_state, record

    return jax.lax.scan(generation, state, (jnp.arange(n_iterations), jax.random.split(key, n_iterations)))


@eqx.filter_jit
def _run_pgpe_jit(pgpe, objective, params, key, n_iterations, shard, with_progress, token):
    # In a multi-process run every process gets the whole result (a no-op in one process).
    return replicate_in_jit(_run_pgpe(pgpe, objective, params, key, n_iterations, shard, with_progress, token))


def sweep_pgpe(
    pgpe: PGPE,
    objective: Objective,
    params: Float[ArrayLike, " n_params"],
    keys: Key[Array, " runs"] | UInt32[Array, "runs 2"],
    n_iterations: int,
    *,
    shard: bool = True,
    progress: bool | None = None,
) -> tuple[PGPEState, PGPEHistory]:
    """Independent PGPE runs, one per key, as one compiled `vmap` of `run_pgpe`; runs split across devices.

    With several devices (and a number of runs that divides evenly) the run axis is constrained
    to a `NamedSharding` across them, so each device does whole runs and no data moves between
    them; in a multi-process run (`dynax.initialize_distributed`) across every process's devices,
    and every process gets all runs' results. For a sweep over hyper-parameters, give `PGPE`
    array-valued fields (for example `sigma_learning_rate`) and `eqx.filter_vmap` this function
    over the strategy.

    **Arguments:** as `run_pgpe`, with `keys` of shape `(runs,)`; the bar shows the generation
    and the best reward over all runs.

    **Returns:** `(states, histories)` with a leading `runs` axis.
    """
    return _with_bar(_sweep_pgpe_jit, "PGPE sweep", _Job(pgpe, objective, params, keys, n_iterations, shard), progress)


@eqx.filter_jit
def _sweep_pgpe_jit(pgpe, objective, params, keys, n_iterations, shard, with_progress, token):
    sharding = population_sharding(keys.shape[0]) if shard else None
    if sharding is not None:
        keys = jax.lax.with_sharding_constraint(keys, sharding)
    out = jax.vmap(lambda key: _run_pgpe(pgpe, objective, params, key, n_iterations, False, with_progress, token))(keys)
    return replicate_in_jit(out)
