"""`simulate`: roll a system out on a sample grid with zero-order-hold inputs, through diffrax."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float
import numpy as np

from .._errors import UsageError
from .._model._system import AbstractSystem


class FixedGrid(eqx.Module):
    r"""Integrate with `substeps` fixed steps of a diffrax `solver` per sample interval, inside `lax.scan`.

    The integrator restarts at every sample time, where the zero-order-hold input jumps, so no
    step straddles a discontinuity. This is the default: on fixed sample grids it is several times
    faster than `Adaptive` for the same accuracy (see `benchmarks/simulate_paths.py`), and its cost
    and memory are known in advance, which suits `vmap` over populations and reverse-mode
    gradients. With the default `Tsit5` and 2 substeps, a 100 Hz acrobot rollout matches
    scipy's DOP853 at rtol 1e-11 to about 1e-8 rad over 5 s.

    **Arguments:**

    - `solver`: a diffrax explicit Runge-Kutta solver (default `diffrax.Tsit5(scan_kind="bounded")`,
      differentiable in forward and reverse mode). Pass `scan_kind="bounded"` to other
      Runge-Kutta solvers too if you need forward-mode derivatives.
    - `substeps`: steps per sample interval (default 2).
    - `roll_stages`: evaluate the Runge-Kutta stages in a `lax.fori_loop` that holds one copy of the
      vector field, instead of writing each stage out (default `False`). Written out, a step runs
      fastest; rolled, it compiles faster where the vector field is large (the diagnosis's family of
      candidate terms: its largest programs compile in about 28 % less time), with results equal to
      rounding (the last digits move: XLA contracts a different program's multiply-adds).
    """

    # "bounded": diffrax's stage loop then supports forward mode (`jax.jvp`, `jax.jacfwd`, used by
    # Levenberg-Marquardt) as well as reverse mode, at the speed of the default "checkpointed" loop,
    # which supports reverse mode only.
    solver: diffrax.AbstractSolver = diffrax.Tsit5(scan_kind="bounded")
    substeps: int = eqx.field(static=True, default=2)
    roll_stages: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if self.substeps < 1:
            raise ValueError(f"FixedGrid: `substeps` must be at least 1, got {self.substeps}")


class Adaptive(eqx.Module):
    """Integrate with `diffrax.diffeqsolve` and an adaptive PID step-size controller.

    The sample times are passed as `jump_ts`, so steps end exactly where the input jumps.
    Use it for stiff or badly scaled systems, or when a tolerance (not a step count) is the
    specification.

    **Arguments:**

    - `solver`: diffrax solver (default `diffrax.Dopri8()`).
    - `rtol`, `atol`: tolerances (default 1e-10, 1e-10).
    - `max_steps`: the step budget of one rollout (default 100,000).
    """

    solver: diffrax.AbstractSolver = diffrax.Dopri8()
    rtol: float = 1e-10
    atol: float = 1e-10
    max_steps: int = eqx.field(static=True, default=100_000)


class Simulation(eqx.Module):
    """The result of `simulate`.

    **Fields:**

    - `ts`: the sample times, shape `(time,)`.
    - `xs`: the states at `ts`, shape `(time, n_states)`; `xs[0] = x0`. Past a divergence the
      rows are NaN.
    - `diverged_at`: the first sample time at which the state left the finite range (non-finite
      or larger than `divergence_bound` in magnitude), `inf` if the rollout stayed bounded,
      `-inf` if the inputs were invalid (non-finite, or `ts` not strictly increasing; only under
      `jax.jit`/`vmap` with `throw=False`, where they cannot be refused up front) and every row is NaN.
    """

    ts: Float[Array, " time"]
    xs: Float[Array, "time n_states"]
    diverged_at: Float[Array, ""]

    @property
    def diverged(self) -> Array:
        """Whether the rollout diverged (or, `diverged_at = -inf`, was given invalid inputs)."""
        return self.diverged_at != jnp.inf


def zoh_term(system):
    # The state's dtype rules: parameters identified in float64 must not promote a float32 rollout.
    return diffrax.ODETerm(lambda t, x, u: system.vector_field(t, x, u).astype(x.dtype))


def _is_concrete(*arrays) -> bool:
    return not any(isinstance(a, jax.core.Tracer) for a in arrays)


def _check_values(x0, ts, us):
    """On concrete (not traced) arguments: refuse non-finite inputs and times that do not strictly increase."""
    for name, arr in (("x0", x0), ("ts", ts), ("us", us)):
        bad = np.argwhere(~np.isfinite(np.asarray(arr)))
        if bad.size:
            where = "[" + ", ".join(str(int(i)) for i in bad[0]) + "]"
            raise UsageError(
                f"simulate: non-finite input: `{name}`{where} is {np.asarray(arr)[tuple(bad[0])].item()!r}"
            )
    ts = np.asarray(ts)
    bad = np.flatnonzero(np.diff(ts) <= 0)
    if bad.size:
        k = int(bad[0])
        raise UsageError(
            f"simulate: `ts` must strictly increase; ts[{k}] = {ts[k].item()!r} then ts[{k + 1}] = {ts[k + 1].item()!r}"
        )


def _invalid_input(x0, ts, us):
    """Traced counterpart of `_check_values`: whether any input is non-finite or `ts` does not increase."""
    finite = jnp.all(jnp.isfinite(x0)) & jnp.all(jnp.isfinite(ts)) & jnp.all(jnp.isfinite(us))
    return ~finite | ~jnp.all(jnp.diff(ts) > 0)


def _check_real(name, arr):
    # a complex array would lose its imaginary part in the cast to the rollout's dtype, silently
    if jnp.issubdtype(arr.dtype, jnp.complexfloating):
        raise UsageError(f"simulate: `{name}` must be real, got dtype {arr.dtype}")


def _check_arguments(system, x0, ts, us):
    if not isinstance(system, AbstractSystem):
        raise UsageError(f"simulate: `system` must be a dynax system (AbstractSystem), got {type(system).__name__}")
    x0 = jnp.asarray(x0)
    ts = jnp.asarray(ts)
    _check_real("x0", x0)
    _check_real("ts", ts)
    if ts.ndim != 1 or ts.shape[0] < 2:
        raise UsageError(f"simulate: `ts` must be a 1-d array of at least 2 sample times, got shape {ts.shape}")
    if x0.ndim != 1:
        raise UsageError(f"simulate: `x0` must be a 1-d state vector, got shape {x0.shape}")
    if x0.shape[0] != system.n_states:
        measured = getattr(getattr(system, "system", None), "n_states", 0)  # an `Extended`'s base system's
        internal = (
            "; its states beyond the measured ones are internal (an input lag, a memory of rest): complete a "
            "measured state with `system.initial_state(x0, u0)`"
            if hasattr(system, "initial_state") and measured == x0.shape[0]
            else ""
        )
        raise UsageError(
            f"simulate: `x0` has {x0.shape[0]} entries but {type(system).__name__} has "
            f"{system.n_states} states {system.state_names}{internal}"
        )
    dtype = jnp.result_type(x0, ts)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    if us is None:
        us = jnp.zeros((ts.shape[0], system.n_inputs), dtype)
    us = jnp.asarray(us)
    _check_real("us", us)
    if us.ndim == 1 and system.n_inputs == 1:
        us = us[:, None]
    if us.ndim != 2 or us.shape[1] != system.n_inputs:
        raise UsageError(
            f"simulate: `us` must have shape (time, {system.n_inputs}) for inputs {system.input_names}, got {us.shape}"
        )
    if us.shape[0] not in (ts.shape[0], ts.shape[0] - 1):
        raise UsageError(
            f"simulate: `us` has {us.shape[0]} rows but `ts` has {ts.shape[0]} samples "
            "(give one input per sample; the last one is not used)"
        )
    x0, ts, us = x0.astype(dtype), ts.astype(dtype), us.astype(dtype)
    if _is_concrete(x0, ts, us):
        _check_values(x0, ts, us)
    return x0, ts, us


def explicit_step(system, solver, rolled: bool = False):
    r"""The step of an explicit Runge-Kutta `solver` from its Butcher tableau.

    On a fixed grid nothing of diffrax's per-step machinery is needed: no error estimate, no dense
    output, no stage buffers over the full square tableau. The step is
    $k_i = f(t_0 + c_i h, y_0 + h \sum_{j<i} a_{ij} k_j)$, $y_1 = y_0 + h \sum_i b_i k_i$ with the
    tableau's nonzero coefficients as constants, the same arithmetic as `solver.step` (equal to
    rounding). By default the stages are written out at trace time (fastest to run); with `rolled`
    they are evaluated in a `lax.fori_loop` over the needed stages, each stage's input chosen by a
    `lax.switch` over the tableau's rows, so the program holds one copy of the vector field instead
    of one per stage (fastest to compile when the vector field is large). Returns `None` for other
    solvers, which then take diffrax's `step`.
    """
    tableau = getattr(solver, "tableau", None)
    if not isinstance(solver, diffrax.AbstractERK) or not isinstance(tableau, diffrax.ButcherTableau):
        return None
    c = np.concatenate([[0.0], np.asarray(tableau.c)])
    a = [np.zeros(0)] + [np.asarray(row) for row in tableau.a_lower]
    b = np.asarray(tableau.b_sol)

    # Reverse mode keeps each stage's input and recomputes the vector field's internals (as
    # diffrax's stage loop does): 1,024 acrobot rollouts of 1,000 RK4 steps take 113 MiB of
    # gradient temporaries instead of 613 MiB, and their gradient 0.66 s instead of 1.11 s (forward
    # unchanged; `benchmarks/rollout.py`).
    @jax.checkpoint
    def field(t, y, u):
        return system.vector_field(t, y, u).astype(y.dtype)

    # A stage is needed if the solution or a later needed stage uses it (the last stage of an FSAL
    # method such as Tsit5 only feeds the next step's error estimate: skipped).
    needed = [False] * len(b)
    for i in reversed(range(len(b))):
        needed[i] = b[i] != 0 or any(needed[j] and a[j][i] != 0 for j in range(i + 1, len(b)))
    stages = [i for i in range(len(b)) if needed[i]]
    slot = {i: n for n, i in enumerate(stages)}

    # The stages a combination uses are stacked and contracted with their coefficients in one dot,
    # not summed term by term: with chains of scaled adds XLA:CPU made a batched closed-loop Tsit5
    # rollout 2x slower than diffrax's stage loop (`benchmarks/pgpe.py`; an optimisation barrier per
    # stage did not help); with the dot it is 1.1-1.3x faster than that loop, RK4 open loop 1.3x.
    def combine(y, h, coefficients, ks):
        used = [j for j, w in enumerate(coefficients) if w != 0.0]
        if not used:
            return y
        w = jnp.asarray([float(coefficients[j]) for j in used], y.dtype)
        return y + h * jnp.tensordot(w, jnp.stack([ks[slot[j]] for j in used]), axes=1)

    def written_out(t0, y0, u, h):
        ks = []
        for i in stages:
            ks.append(field(t0 + float(c[i]) * h, combine(y0, h, a[i], ks), u))
        return combine(y0, h, b, ks)

    def rolled_step(t0, y0, u, h):
        inputs = [lambda ks, h, i=i: combine(y0, h, a[i], ks) for i in stages]
        cs = jnp.asarray([float(c[i]) for i in stages], jnp.result_type(h))  # `h` may be a Python float

        def stage(n, ks):
            y = jax.lax.switch(n, inputs, ks, h)
            return ks.at[n].set(field(t0 + cs[n] * h, y, u))

        ks = jax.lax.fori_loop(0, len(stages), stage, jnp.zeros((len(stages),) + y0.shape, y0.dtype))
        return combine(y0, h, b, ks)

    return rolled_step if rolled else written_out


def sample_interval(system, method: FixedGrid, bound):
    """One sample interval of a fixed-grid rollout, with divergence tracking.

    Returns `advance(x, diverged_at, t0, t1, dt, u) -> (x_next, diverged_at)`: `method.substeps`
    solver steps from `t0` to `t1 = t0 + dt` under the constant input `u`. The caller passes the
    interval lengths `dt = jnp.diff(ts)` computed once over the grid: subtracting inside the loop
    costs 7 % of a 4-state rollout. Once diverged (a state entry
    non-finite or above `bound` in magnitude), the carried state is frozen, so no inf/NaN feeds later
    steps or their gradients, and `diverged_at` holds the end of the first bad interval. The caller
    turns the rows at and after `diverged_at` into NaN once, after its `lax.scan`
    (`mask_diverged`): the per-step work is one comparison and one select, which keeps the rollout
    at the speed of a hand-written RK4 scan (`benchmarks/rollout.py`). Shared by `simulate` and the
    closed-loop rollouts of `dynax.control.simulate_closed_loop`.
    """
    term = zoh_term(system)
    solver = method.solver
    n = method.substeps
    explicit = explicit_step(system, solver, method.roll_stages)

    def advance(x, diverged_at, t0, t1, dt, u):
        h = dt / n

        def substep(i, y):
            ta = t0 + i * h
            if explicit is not None:
                return explicit(ta, y, u, h)
            state = solver.init(term, ta, ta + h, y, u)
            y_next, _, _, _, _ = solver.step(term, ta, ta + h, y, u, state, made_jump=True)
            return y_next

        # The substeps in a rolled loop, not unrolled: unrolled, four Tsit5 substeps of a two-link
        # arm compiled about twice as long and ran slower, batched or not (docs/devdocs/code_notes.md).
        x_new = substep(0, x) if n == 1 else jax.lax.fori_loop(0, n, substep, x)
        # One comparison catches NaN, inf and out-of-bound entries alike (NaN <= bound is False).
        bad = ~jnp.all(jnp.abs(x_new) <= bound)
        diverged_at = jnp.where(bad & jnp.isinf(diverged_at), t1, diverged_at)
        return jnp.where(jnp.isfinite(diverged_at), x, x_new), diverged_at

    return advance


def mask_diverged(ts_after, xs, diverged_at):
    """NaN in the rows of `xs` (states at the times `ts_after`) at and after `diverged_at`."""
    return jnp.where((ts_after >= diverged_at)[:, None], jnp.nan, xs)


# Compiled once per system structure, method and grid shape: called eagerly (data generation, a user's
# loop over parameter values), a bare `lax.scan` over a closure made anew on every call is compiled
# anew on every call (most of a call's time, and the compiled programs pile up in memory; see
# docs/benchmarks.md). Under an outer `jit` this is inlined.
@eqx.filter_jit
def fixed_grid_rollout(system, x0, ts, us, method, bound):
    """`simulate`'s `FixedGrid` rollout: the states at `ts` from `x0` under the zero-order hold `us`, each state
    past the time the rollout leaves `bound` masked, and that time (`inf` if never). Compiled (`filter_jit`);
    its `__wrapped__` is the bare `lax.scan`, which an eager call compiles anew each time."""
    advance = sample_interval(system, method, bound)

    def interval(carry, inputs):
        x_next, diverged_at = advance(*carry, *inputs)
        return (x_next, diverged_at), x_next

    inputs = (ts[:-1], ts[1:], jnp.diff(ts), us[: ts.shape[0] - 1])
    init = (x0, jnp.asarray(jnp.inf, x0.dtype))
    (_, diverged_at), xs = jax.lax.scan(interval, init, inputs)
    return jnp.concatenate([x0[None], mask_diverged(ts[1:], xs, diverged_at)]), diverged_at


@eqx.filter_jit
def _adaptive(system, x0, ts, us, method, bound):
    u_grid = us[: ts.shape[0] - 1]

    def vector_field(t, x, args):
        k = jnp.clip(jnp.searchsorted(ts, t, side="right") - 1, 0, u_grid.shape[0] - 1)
        return system.vector_field(t, x, u_grid[k]).astype(x.dtype)

    solution = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        method.solver,
        t0=ts[0],
        t1=ts[-1],
        dt0=ts[1] - ts[0],
        y0=x0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=method.rtol, atol=method.atol, jump_ts=ts),
        max_steps=method.max_steps,
        throw=False,
    )
    xs = solution.ys
    bad = ~jnp.all(jnp.isfinite(xs), axis=1) | jnp.any(jnp.abs(xs) > bound, axis=1)
    failed = solution.result != diffrax.RESULTS.successful
    bad = bad | (failed & ~jnp.all(jnp.isfinite(xs), axis=1))
    first = jnp.argmax(bad)
    diverged_at = jnp.where(jnp.any(bad), ts[first], jnp.inf)
    after = jnp.arange(ts.shape[0]) >= jnp.where(jnp.any(bad), first, ts.shape[0])
    return jnp.where(after[:, None], jnp.nan, xs), diverged_at


def simulate(
    system: AbstractSystem,
    x0: Float[ArrayLike, " n_states"],
    ts: Float[ArrayLike, " time"],
    us: Float[ArrayLike, "time n_inputs"] | None = None,
    *,
    method: FixedGrid | Adaptive = FixedGrid(),
    divergence_bound: float = 1e6,
    throw: bool = True,
) -> Simulation:
    r"""Simulate `system` from `x0`, returning its states at the sample times `ts`.

    Inputs are a zero-order hold: `us[k]` acts on $[t_k, t_{k+1})$. Sampling may be irregular.
    The function is pure and jittable, differentiable with respect to the system's parameters,
    `x0` and `us`, and batches with `jax.vmap`. The caller's dtype is respected (float32 for
    throughput, float64 for identification).

    **Arguments:**

    - `system`: a dynax system.
    - `x0`: initial state, ordered as `system.state_names`.
    - `ts`: strictly increasing sample times, shape `(time,)`.
    - `us`: inputs, shape `(time, n_inputs)` (or `(time - 1, n_inputs)`); `None` means zero input.
    - `method`: `FixedGrid()` (default: solver steps inside `lax.scan`) or `Adaptive()`
      (`diffrax.diffeqsolve`).
    - `divergence_bound`: a state entry larger than this in magnitude counts as divergence.
    - `throw`: if `True` (default), a divergent rollout, or under `jax.jit` an invalid input,
      raises an error (via `eqx.error_if`);
      if `False`, it is reported in `Simulation.diverged_at` and the states past it are NaN.
      Use `throw=False` for populations in which some members may diverge.

    **Returns:**

    A `Simulation` with `ts`, `xs` of shape `(time, n_states)` and `diverged_at`.

    **Raises:** `UsageError` (a `ValueError`) for arguments of the wrong shape (`x0` must have
    exactly `system.n_states` entries) and, when the arguments are concrete arrays (not traced),
    for a non-finite `x0`, `ts` or `us` or `ts` that does not strictly increase, whatever `throw`.
    """
    x0, ts, us = _check_arguments(system, x0, ts, us)
    invalid = _invalid_input(x0, ts, us)
    if throw:
        x0 = eqx.error_if(
            x0, invalid, "simulate: non-finite input (`x0`, `ts` or `us`) or `ts` not strictly increasing"
        )
    if isinstance(method, FixedGrid):
        xs, diverged_at = fixed_grid_rollout(system, x0, ts, us, method, divergence_bound)
    elif isinstance(method, Adaptive):
        xs, diverged_at = _adaptive(system, x0, ts, us, method, divergence_bound)
    else:
        raise UsageError(f"simulate: `method` must be FixedGrid or Adaptive, got {type(method).__name__}")
    xs = jnp.where(invalid, jnp.nan, xs)
    diverged_at = jnp.where(invalid, -jnp.inf, diverged_at)
    if throw:
        xs = eqx.error_if(
            xs,
            jnp.isfinite(diverged_at),
            "simulate: the rollout diverged (a state became non-finite or exceeded `divergence_bound`). "
            "Call simulate(..., throw=False) and read Simulation.diverged_at to see where.",
        )
    return Simulation(ts=ts, xs=xs, diverged_at=diverged_at)
