"""Progress bars with an ETA on stderr, from Python loops and from inside compiled loops.

One stream (stderr) and one look for every long computation. Bars come from
[tqdm](https://github.com/tqdm/tqdm), as diffrax's `TqdmProgressMeter` does: it is small
(pure Python, no dependencies, ~20 ms to import), writes a plain carriage-return bar that degrades
to nothing when disabled, and is what JAX users already see from diffrax. (rich draws prettier
bars but costs more to import and takes over the terminal, which fights with plain `print`.)

Whether a bar is drawn: an explicit `progress=True/False` wins; otherwise the mode set by
`progress_mode` (the CLI's `--quiet` sets `"never"`, `--progress` sets `"always"`); in the default
`"auto"` mode a bar is drawn only when stderr is a terminal, so logs and CI output stay clean.

Inside `jit`, `lax.scan` or `vmap`, a loop reports through `jax.debug.callback` (the approach of
diffrax's `progress_meter` and optimistix's verbose output): the host-side bar lives in a
registry here, and the compiled code carries only its integer token, so a compiled function is
reused whatever bar it reports to. Under `vmap` the callback runs once per batch member; the bar
keeps the furthest step and the best (`"max"` or `"min"`) or latest value seen.
"""

from collections.abc import Iterator
import contextlib
import contextvars
import itertools
import sys
import threading
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int
import numpy as np

from ._context import set_within

ProgressMode = Literal["auto", "always", "never"]
PROGRESS_MODE: contextvars.ContextVar[str] = contextvars.ContextVar("dynax_progress_mode", default="auto")


@contextlib.contextmanager
def progress_mode(mode: ProgressMode) -> Iterator[None]:
    """Within the block, draw bars `"always"`, `"never"` or, in `"auto"`, when stderr is a terminal.

    The CLI wraps every sub-command in this (`--quiet` is `"never"`, `--progress` is `"always"`).
    An explicit `progress=` argument of a function still wins.
    """
    if mode not in ("auto", "always", "never"):
        raise ValueError(f"progress_mode: expected 'auto', 'always' or 'never', got {mode!r}")
    with set_within(PROGRESS_MODE, mode):
        yield


def progress_enabled(progress: bool | None = None) -> bool:
    """Whether to draw a bar: `progress` if given, else the current `progress_mode`."""
    if progress is not None:
        return bool(progress)
    mode = PROGRESS_MODE.get()
    if mode != "auto":
        return mode == "always"
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


_REGISTRY: dict[int, "ProgressBar"] = {}
_TOKENS = itertools.count(1)
_LOCK = threading.Lock()


class ProgressBar:
    """A progress bar on stderr with an ETA and named values (a loss, a best reward).

    Use it as a context manager around a loop. From Python, call `update`. From compiled code,
    pass `bar.token` into the jitted function and call `report(token, step, ...)` there. When
    disabled (see `progress_enabled`), every method is a cheap no-op and `token` is 0.

    **Arguments:**

    - `total`: the number of steps (iterations, generations, candidates); `None` if unknown.
    - `description`: a few words shown before the bar.
    - `progress`: `True` / `False` to force; `None` follows `progress_mode`.
    - `unit`: what a step is called (`"it"`, `"gen"`, `"stage"`).
    - `reduce`: how values reported from a `vmap` batch combine: `"max"` (rewards), `"min"`
      (losses) or `"last"`.
    """

    def __init__(
        self,
        total: int | None,
        description: str = "",
        *,
        progress: bool | None = None,
        unit: str = "it",
        reduce: Literal["max", "min", "last"] = "last",
    ):
        if reduce not in ("max", "min", "last"):
            raise ValueError(f"ProgressBar: `reduce` must be 'max', 'min' or 'last', got {reduce!r}")
        self.enabled = progress_enabled(progress)
        self._lines = progress is not False and PROGRESS_MODE.get() != "never"  # `say` prints when no bar is drawn
        self.reduce = reduce
        self.values: dict[str, float] = {}
        self._bar = None
        self.token = 0
        if self.enabled:
            from tqdm import tqdm

            self._bar = tqdm(
                total=total, desc=description, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=True, smoothing=0.1
            )
            with _LOCK:
                self.token = next(_TOKENS)
                _REGISTRY[self.token] = self

    def update(self, n: int = 1, **values: float) -> None:
        """Advance by `n` steps and show `values` (e.g. `loss=0.12`)."""
        if self._bar is None:
            return
        self._merge(values)
        self._bar.update(n)

    def reach(self, step: int, **values: float | Float[ArrayLike, ""]) -> None:
        """Move to step `step` (steps done; never backwards) and show `values`."""
        if self._bar is None:
            return
        self._merge(values)
        if step > self._bar.n:
            self._bar.update(step - self._bar.n)
        else:
            self._bar.refresh()

    def say(self, line: str) -> None:
        """Report a stage in words and advance one step: the line is written above the bar, or, with
        no bar (stderr not a terminal), printed to stderr as a log line; `"never"` mode prints nothing.

        Pass `bar.say` where a function takes a `progress(line)` callback, e.g.
        `with ProgressBar(None, "diagnose", unit="stage") as bar: dynax.diagnose(..., progress=bar.say)`.
        """
        if self._bar is not None:
            self._bar.write(line, file=sys.stderr)
            self._bar.update(1)
        elif self._lines:
            print(line, file=sys.stderr, flush=True)

    def _merge(self, values):
        for name, value in values.items():
            value = np.asarray(value, dtype=float).reshape(-1)
            if value.size == 0:
                continue
            old = self.values.get(name, np.nan)
            if self.reduce == "max":  # fmax ignores NaN unless every value is NaN
                self.values[name] = float(np.fmax(old, np.fmax.reduce(value)))
            elif self.reduce == "min":
                self.values[name] = float(np.fmin(old, np.fmin.reduce(value)))
            else:
                self.values[name] = float(value[-1])
        if values:
            self._bar.set_postfix({k: f"{v:.4g}" for k, v in self.values.items()}, refresh=False)

    def close(self) -> None:
        """Finish the bar (it stays on screen with its final values)."""
        if self._bar is None:
            return
        self._bar.close()
        self._bar = None
        with _LOCK:
            _REGISTRY.pop(self.token, None)

    def __enter__(self) -> "ProgressBar":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _host_report(token, step, values):
    bar = _REGISTRY.get(int(np.max(token)))
    if bar is not None:
        bar.reach(int(np.max(step)) + 1, **values)


def report(token: Int[ArrayLike, ""], step: Int[ArrayLike, ""] | Float[ArrayLike, ""], **values: ArrayLike) -> None:
    """From inside compiled code, tell the bar with `token` that step `step` (0-based) is done.

    Emits a `jax.debug.callback`; with `token == 0` (no bar) the host side does nothing. Call it
    inside a `lax.scan` / `fori_loop` body with the loop index and any scalars to show.

    **Arguments:**

    - `token`: `ProgressBar.token`, passed into the jitted function as an array (so changing bars
      does not recompile).
    - `step`: the 0-based index of the step just finished.
    - `values`: scalars to show beside the bar (`best_reward=...`, `loss=...`).
    """
    jax.debug.callback(_host_report, token, step, values)


def bar_token(bar: ProgressBar | None) -> Int[Array, ""]:
    """`bar.token` as an int32 array, to pass into a jitted function (0 for no bar)."""
    return jnp.asarray(0 if bar is None else bar.token, dtype=jnp.int32)
