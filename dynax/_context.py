"""A context variable set for the length of a `with` block: the one mechanism behind dynax's switches
(`progress_mode`, and `dynax.internal`'s `screens_off`, `refinement_options`, `filter_rule`, ...)."""

from collections.abc import Iterator
import contextlib
import contextvars
from typing import TypeVar

T = TypeVar("T")


@contextlib.contextmanager
def set_within(variable: contextvars.ContextVar[T], value: T) -> Iterator[None]:
    """`variable` holds `value` inside the block and what it held before after it, however the block ends."""
    token = variable.set(value)
    try:
        yield
    finally:
        variable.reset(token)
