"""Compiled programs against Linux's memory-map limit (`dynax.internal.release_compiled_code`)."""

import jax
import jax.numpy as jnp
import pytest

import dynax.internal as di

pytestmark = pytest.mark.skipif(di.map_usage() is None, reason="no /proc memory-map limit to read (not Linux)")


def _compile_distinct(n: int) -> list:
    """`n` programs of distinct shapes, each compiled once; the jitted functions (their caches hold them)."""
    fns = []
    for k in range(n):
        f = jax.jit(lambda x, k=k: jnp.sin(x) * k + jnp.cumsum(x))
        f(jnp.zeros(k + 1)).block_until_ready()
        fns.append(f)
    return fns


def test_compiled_programs_hold_memory_maps_until_the_caches_are_cleared():
    """The premise: each compiled CPU program holds maps of its own, and clearing the caches gives them back."""
    jax.clear_caches()
    before, allowed = di.map_usage()
    fns = _compile_distinct(60)
    held, _ = di.map_usage()
    assert held - before >= 60  # at least one map per program
    assert di.release_compiled_code(share=0.0)  # any use is above a share of 0
    after, _ = di.map_usage()
    assert after < held - 30
    assert all(f._cache_size() == 0 for f in fns)
    assert allowed > 1000


def test_below_the_share_nothing_is_cleared():
    """A warm process keeps its compiled programs while the maps are far from the limit."""
    (f,) = _compile_distinct(1)
    assert not di.release_compiled_code(share=1.0)  # no process holds more than all it may
    assert f._cache_size() == 1
