r"""Solvers and monitoring for the engine: L-BFGS (optax) as an optimistix minimiser with a
relative-decrease stopping rule, a loss and wall-clock history recorded inside the compiled loop,
and progress reported to the host through `jax.debug.callback`.

A compiled solve cannot call Python each iteration, so a caller that wants to watch one registers
its callback with `monitor(callback)` and passes the returned integer token into the solve (as an
array, so a new callback does not recompile anything). Each step then emits one
`jax.debug.callback` carrying `(token, step, loss)`; the host looks the callback up by token.
"""

from collections.abc import Callable, Iterator
import contextlib
import itertools
import threading
import time
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree, Scalar
import numpy as np
import optax
import optimistix as optx

_CALLBACKS: dict[int, Callable[[int, float], Any]] = {}
_TOKENS = itertools.count(1)
_LOCK = threading.Lock()
_EPOCH = time.perf_counter()


@contextlib.contextmanager
def monitor(callback: Callable[[int, float], Any] | None) -> Iterator[Int[Array, ""]]:
    """Register `callback(step, loss)` for the duration of the block; yields its token (0: none).

    Pass the token into a solver (`OptaxLBFGS(token=...)`); the solver reports each step through
    `jax.debug.callback` and the host calls `callback` with the 0-based step and its loss.
    """
    if callback is None:
        yield jnp.asarray(0, jnp.int32)
        return
    with _LOCK:
        token = next(_TOKENS)
        _CALLBACKS[token] = callback
    try:
        yield jnp.asarray(token, jnp.int32)
        jax.effects_barrier()  # every step's report has reached the host before the block ends
    finally:
        with _LOCK:
            _CALLBACKS.pop(token, None)


def _host_notify(token, step, loss, accepted):
    callback = _CALLBACKS.get(int(np.max(token)))
    if callback is not None and bool(np.all(accepted)):
        callback(int(np.max(step)), float(np.min(loss)))


def notify(
    token: Int[ArrayLike, ""], step: Int[ArrayLike, ""], loss: Scalar, accepted: Bool[Array, ""] | bool = True
) -> None:
    """From compiled code: tell the callback registered under `token` that `step` ended at `loss`
    (skipped on the host when `accepted` is false)."""
    jax.debug.callback(_host_notify, token, step, loss, jnp.asarray(accepted))


def clock(after: Array) -> Float[Array, ""]:
    """Seconds on the host's monotonic clock, read once `after` has been computed (a data
    dependency orders the read after it inside a compiled loop)."""
    dtype = jnp.result_type(after.dtype, jnp.float32) if jnp.issubdtype(after.dtype, jnp.floating) else jnp.float32

    def now(_):
        return np.asarray(time.perf_counter() - _EPOCH, dtype)

    return jax.pure_callback(now, jax.ShapeDtypeStruct((), dtype), after, vmap_method="sequential")


class History(eqx.Module):
    """A loss and wall-clock history of static length, written inside a compiled loop (NaN past the end)."""

    losses: Float[Array, " size"]
    times: Float[Array, " size"]

    @classmethod
    def start(cls, size: int, loss: Scalar) -> "History":
        losses = jnp.full(size, jnp.nan, loss.dtype).at[0].set(loss)
        return cls(losses, jnp.full(size, jnp.nan, loss.dtype).at[0].set(clock(loss)))

    def record(self, index: Int[Array, ""], loss: Scalar, keep: Bool[Array, ""] | bool = True) -> "History":
        """Write `loss` (and the time) at `index` when `keep`; out-of-range indices are dropped."""
        index = jnp.where(keep, index, self.losses.shape[0])  # an index past the end is dropped
        return History(self.losses.at[index].set(loss, mode="drop"), self.times.at[index].set(clock(loss), mode="drop"))

    def stats(self) -> dict[str, Array]:
        return {"loss_history": self.losses, "time_history": self.times - self.times[0]}


class _LBFGSState(eqx.Module):
    step: Int[Array, ""]
    f: Scalar
    opt_state: PyTree
    terminate: Bool[Array, ""]
    history: History


class OptaxLBFGS(optx.AbstractMinimiser):
    r"""L-BFGS with a zoom line search (optax's `lbfgs`) as an optimistix minimiser.

    Unlike `optimistix.OptaxMinimiser`, each step reuses the value and gradient the line search
    already computed at the accepted point (`optax.value_and_grad_from_state`), so a step costs
    one line search and no extra gradient. It stops when

    - the relative decrease of the loss over a step, $(f_{k-1} - f_k) / f_{k-1}$, is in
      $[0, \text{rtol})$ (a step that raises the loss does not stop it: L-BFGS may recover);
    - the loss is at or below `target` (timing comparisons); or
    - the line search lands on a non-finite loss (the last finite iterate is kept).

    **Fields:**

    - `rtol`: the relative-decrease tolerance; `atol` is unused (kept for optimistix's interface).
    - `memory_size`: L-BFGS memory (default 10, optax's).
    - `target`: stop at or below this loss (default $-\infty$).
    - `history`: length of the recorded loss and wall-clock history (set it to `max_steps + 1`;
      0 records nothing useful but a single entry).
    - `token`: a `monitor` token: each step is reported to the host (0: nobody listening).

    ??? cite

        D. C. Liu and J. Nocedal, "On the limited memory BFGS method for large scale
        optimization", Mathematical Programming 45, 1989; J. Nocedal and S. J. Wright, *Numerical
        Optimization*, 2nd ed., 2006 (ch. 3.5 zoom line search, ch. 7.2 L-BFGS).
    """

    rtol: float = 1e-7
    atol: float = 0.0
    norm: Callable = eqx.field(static=True, default=optx.max_norm)
    memory_size: int = eqx.field(static=True, default=10)
    target: float | Array = -jnp.inf
    history: int = eqx.field(static=True, default=1)
    token: Int[Array, ""] | int = 0

    def _optax(self):
        return optax.lbfgs(memory_size=self.memory_size)

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        f, _ = fn(y, args)
        return _LBFGSState(
            jnp.array(0), f, self._optax().init(y), jnp.array(False), History.start(max(self.history, 1), f)
        )

    def step(self, fn, y, args, options, state, tags):
        def value_fn(y):
            return fn(y, args)[0]

        optim = self._optax()
        value, grad = optax.value_and_grad_from_state(value_fn)(y, state=state.opt_state)
        updates, opt_state = optim.update(grad, state.opt_state, y, value=value, grad=grad, value_fn=value_fn)
        new_y = optax.apply_updates(y, updates)
        new_f = optax.tree_utils.tree_get(opt_state, "value")  # the loss at `new_y`, from the line search
        finite = jnp.isfinite(new_f)
        improvement = (state.f - new_f) / state.f
        terminate = ~finite | ((improvement >= 0) & (improvement < self.rtol)) | (new_f <= self.target)
        y_out = jax.tree.map(lambda a, b: jnp.where(finite, a, b), new_y, y)
        f_out = jnp.where(finite, new_f, state.f)
        notify(self.token, state.step, f_out, finite)
        history = state.history.record(state.step + 1, f_out, finite)
        return y_out, _LBFGSState(state.step + 1, f_out, opt_state, terminate, history), None

    def terminate(self, fn, y, args, options, state, tags):
        return state.terminate, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, state.history.stats()
