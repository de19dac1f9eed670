"""Test configuration in diffrax's manner: float64 for the whole suite (identification needs it), rank
promotion raised (implicit broadcasting in the library is an error, not a silent reshape), a seeded key,
paths and shared data fixtures. Comparison helpers live in `tests/helpers.py`."""

import gc
import os
import pathlib
import tempfile

# JAX's persistent compilation cache, shared by the two xdist workers and the subprocesses the CLI and
# multi-process tests start: a computation compiled once (same HLO, same JAX) is read back instead of
# compiled again, which takes 8 to 12 % off the suite. Set JAX_COMPILATION_CACHE_DIR to choose
# the folder.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(tempfile.gettempdir(), "dynax-tests-jax-cache"))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")

import jax  # noqa: E402

jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update(
    "jax_persistent_cache_min_compile_time_secs", float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"])
)

# In-process CLI calls must not fill the user's cache folder; tests/cli/test_cache.py checks the cache
# in subprocesses with a folder of their own.
os.environ.setdefault("DYNAX_NO_CACHE", "1")

jax.config.update("jax_enable_x64", True)
# As in diffrax's and optimistix's test suites: `x[:, None] + y` with mismatched ranks must be written
# out (`jnp.broadcast_to`, explicit indexing), so a shape bug cannot hide behind broadcasting.
jax.config.update("jax_numpy_rank_promotion", "raise")

from hypothesis import settings as hypothesis_settings  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

# Property tests draw the same examples on every run (a seed derived from each test), so that a red CI is the
# code's and not the draw's; `HYPOTHESIS_PROFILE=explore` draws anew, keeping what fails in `.hypothesis/`.
hypothesis_settings.register_profile("dynax", derandomize=True, database=None)
hypothesis_settings.register_profile("explore", derandomize=False)
hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dynax"))

REPO = pathlib.Path(__file__).resolve().parents[1]
DATASETS = REPO.parent / "shared" / "datasets"

DFKI_MAPPING = {
    "t": "time",
    "q1": "pos_meas1",
    "q2": "pos_meas2",
    "dq1": "vel_meas1",
    "dq2": "vel_meas2",
    "tau1": "tau_meas1",
    "tau2": "tau_meas2",
}


@pytest.fixture
def key():
    return jax.random.PRNGKey(0)


@pytest.fixture(scope="session")
def datasets():
    if not DATASETS.is_dir():
        pytest.fail(f"the shared datasets are missing: expected {DATASETS} beside the repository")
    return DATASETS


@pytest.fixture(scope="session")
def acrobot_csv(tmp_path_factory):
    """6 s of the default acrobot under a two-sine elbow torque, simulated and saved as a contract CSV (read-only)."""
    import dynax
    from dynax import save_trajectory, Trajectory

    ts = np.arange(0.0, 6.0, 0.01)
    us = (2.0 * np.sin(1.3 * ts) + 1.0 * np.sin(3.7 * ts + 0.5))[:, None]
    sim = dynax.simulate(dynax.Acrobot(), jnp.array([0.2, 0.0, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us))
    path = tmp_path_factory.mktemp("data") / "acrobot.csv"
    save_trajectory(Trajectory(jnp.asarray(ts), sim.xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",)), path)
    return path


@pytest.fixture(autouse=True)
def _release_compiled_code():
    """Drop JAX's compiled executables when this worker holds half the memory maps a process may
    (`dynax.internal.release_compiled_code`): a worker that compiles several hundred programs (the whole
    suite on two workers) would otherwise reach `vm.max_map_count` and die in the next compilation."""
    from dynax.internal import release_compiled_code

    yield
    if release_compiled_code():
        gc.collect()


@pytest.fixture(autouse=True)
def _wrong_types(request):
    """The test-time type checker (`tests/typecheck.py`) stands aside for a test marked `wrong_types`, which passes
    a wrong type or shape on purpose to see dynax's own refusal."""
    if request.node.get_closest_marker("wrong_types") is None:
        yield
        return
    from tests.typecheck import standing_aside

    with standing_aside():
        yield
