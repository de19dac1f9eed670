"""Where `diagnose`'s cross-fitting spends its time: the fold fits and the cross-fitted rollouts.

The workload is `benchmarks/diagnose.py`'s (a 40 s, 100 Hz acrobot file with Coulomb friction hidden at
the elbow; the full candidate library; the last 30 % held out), a first call and a call on another file
of the same size. Each call runs under `cProfile` with a CPU-time clock (user + system of every thread),
and the compiled calls are read from its call graph by who called them: the batch fits and the fold fits
(`fit_configurations` called by `_fit_batch` and by `_cross_fit`), and the rollouts of the held-out and of
the cross-fitted windows (the compiled `validate_configurations` called by each). A compiled call runs
inside the call that dispatches it, so its time is the program's (with its compilation on the first
call). The profiler's own overhead inflates the Python work of a call, most of all the tracing of the
first; the call's CPU time is printed as measured under it. The compilations come from JAX's
monitoring events (wall seconds per program, first call only).

    python benchmarks/crossfit_profile.py

Prints only.
"""

import collections
import cProfile
import pathlib
import pstats
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

from dynax import Acrobot, diagnose  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from warm_diagnose_split import records  # noqa: E402  # benchmarks/diagnose.py's two files, written and read back

# (file, function) of the callers and callees read from the profile; a compiled call is equinox's `__call__`.
BATCH = ("_forward.py", "_fit_batch")
CROSS_FIT = ("_forward.py", "_cross_fit")
FIT = ("_fit.py", "fit_configurations")
COMPILED = ("_jit.py", "__call__")


def _matches(func, key) -> bool:
    filename, _, name = func
    return pathlib.Path(filename).name == key[0] and name == key[1]


def split(stats: pstats.Stats) -> dict[str, tuple[int, float]]:
    """Calls and cumulative CPU seconds of the cross-fitting and of each compiled call, by who called it."""
    table = stats.stats  # type: ignore[attr-defined]  # pstats' documented dictionary of (cc, nc, tt, ct, callers)
    out: dict[str, tuple[int, float]] = {}

    def edges(callee, caller_key):
        calls, seconds = 0, 0.0
        for func, (*_, callers) in table.items():
            if _matches(func, callee):
                for caller, (_, n, _, c) in callers.items():
                    if _matches(caller, caller_key):
                        calls, seconds = calls + n, seconds + c
        return calls, seconds

    for func, (_, nc, _, ct, _) in table.items():
        if _matches(func, CROSS_FIT):
            out["cross-fitting, all"] = (nc, ct)
    out["batch fits (fit_configurations)"] = edges(FIT, BATCH)
    out["fold fits (fit_configurations)"] = edges(FIT, CROSS_FIT)
    out["held-out rollouts (validate_configurations)"] = edges(COMPILED, BATCH)
    out["cross-fitted rollouts (validate_configurations)"] = edges(COMPILED, CROSS_FIT)
    return out


def main():
    compiled: dict[str, list[float]] = collections.defaultdict(list)

    def on_event(event, duration, fun_name=None, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled[str(fun_name)].append(duration)

    jax.monitoring.register_event_duration_secs_listener(on_event)
    first, other = records()
    for label, record in (("first call (with compilation)", first), ("another file of the same size", other)):
        compiled.clear()
        profile = cProfile.Profile(time.process_time)
        start = time.process_time()
        profile.runcall(diagnose, Acrobot(), record)
        total = time.process_time() - start
        print(f"{label}: {total:.2f} s CPU (under the profiler)")
        for key, (calls, seconds) in split(pstats.Stats(profile)).items():
            print(f"  {key:50s} {calls:3d} calls {seconds:6.2f} s CPU")
        if compiled:
            n, seconds = sum(map(len, compiled.values())), sum(map(sum, compiled.values()))
            print(f"  compiling: {seconds:.2f} s wall in {n} programs; the largest:")
            for name, times in sorted(compiled.items(), key=lambda kv: -sum(kv[1]))[:6]:
                print(f"    {name:48s} {len(times):3d} x {sum(times):6.2f} s wall")


if __name__ == "__main__":
    main()
