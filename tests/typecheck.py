"""The test-time type checker: every annotation of dynax (jaxtyping's shapes and dtypes, and every other hint)
checked by beartype on every call the tests make, as optimistix's tests check theirs (pytest's
`--jaxtyping-packages=dynax,tests.typecheck.typechecked`, in `pyproject.toml`). An annotation that says less or other
than what dynax accepts or returns fails the test that calls it.

Integers pass where a float is annotated (PEP 484's numeric tower), numpy integers where an int is. A test that
passes a wrong type or shape on purpose, to see dynax's own refusal as a user sees it (a user's program runs
unchecked), is marked `wrong_types`: the checker stands aside while it runs (`tests/conftest.py`).
"""

import contextlib
import functools
import inspect

from beartype import beartype, BeartypeConf, FrozenDict
import numpy as np

# an int passes for a float (PEP 484's numeric tower, as the static checker reads it), a numpy integer for an int
_check = beartype(conf=BeartypeConf(is_pep484_tower=True, hint_overrides=FrozenDict({int: int | np.integer})))
_aside = [False]


def typechecked(fn):
    """`fn` checked by beartype, except while `standing_aside`."""
    if not inspect.isfunction(fn):
        return _check(fn)
    checked = _check(fn)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        return (fn if _aside[0] else checked)(*args, **kwargs)

    return call


@contextlib.contextmanager
def standing_aside():
    """No type checks inside (a test of dynax's own refusal of a wrong type)."""
    before, _aside[0] = _aside[0], True
    try:
        yield
    finally:
        _aside[0] = before
