"""Compiled code against the process's memory-map limit: many diagnoses or identifications in one process.

Every program JAX compiles for the CPU keeps its machine code in memory maps of its own (about three per
program), and each diagnosis or identification compiles its models' programs afresh (a new model, new
shapes). A process that runs many of them in a row, a study or a sweep over records, reaches Linux's
`vm.max_map_count` (65,530 maps by default) after some fifty diagnoses, and LLVM then aborts the whole
process ("Unable to allocate section memory"): no Python exception, no traceback, results not yet written
lost. `jax.clear_caches()` releases them (300 small programs: 1,401 maps to 515).

So `diagnose` and `identify` look at the maps in use as they start, and where more than `MAP_SHARE` of the
limit is in use they clear JAX's caches first: what is compiled later compiles again (from the persistent
compilation cache where one is set), which costs seconds where the alternative is an abort. Below the share
nothing is cleared and a warm process keeps its compiled programs. Elsewhere than Linux there is no such
limit to read, and nothing is done.
"""

import jax

MAP_SHARE = 0.5


def map_usage() -> tuple[int, int] | None:
    """The memory maps this process holds and the most it may hold (`vm.max_map_count`); `None` off Linux."""
    try:
        with open("/proc/self/maps") as maps:
            used = sum(1 for _ in maps)
        with open("/proc/sys/vm/max_map_count") as limit:
            allowed = int(limit.read())
    except (OSError, ValueError):
        return None
    return used, allowed


def release_compiled_code(share: float = MAP_SHARE) -> bool:
    """Clear JAX's compiled programs (`jax.clear_caches()`) when this process holds more than `share` of the memory
    maps Linux allows it; whether it did. See the module."""
    usage = map_usage()
    if usage is None or usage[0] <= share * usage[1]:
        return False
    jax.clear_caches()
    return True
