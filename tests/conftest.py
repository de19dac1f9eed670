"""Test configuration in diffrax's manner: float64 for the whole suite (identification needs it), rank
promotion raised (implicit broadcasting in the library is an error, not a silent reshape), a seeded key,
paths and shared data fixtures. Comparison helpers live in `tests/helpers.py`."""

import gc
import os
import pathlib

import jax

# In-process CLI calls must not fill the user's cache folder; tests/cli/test_cache.py checks the cache
# in subprocesses with a folder of their own.
os.environ.setdefault("DYNAX_NO_CACHE", "1")

jax.config.update("jax_enable_x64", True)
# As in diffrax's and optimistix's test suites: `x[:, None] + y` with mismatched ranks must be written
# out (`jnp.broadcast_to`, explicit indexing), so a shape bug cannot hide behind broadcasting.
jax.config.update("jax_numpy_rank_promotion", "raise")

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

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
    from dynax._data import save_trajectory, Trajectory

    ts = np.arange(0.0, 6.0, 0.01)
    us = (2.0 * np.sin(1.3 * ts) + 1.0 * np.sin(3.7 * ts + 0.5))[:, None]
    sim = dynax.simulate(dynax.Acrobot(), jnp.array([0.2, 0.0, 0.0, 0.0]), jnp.asarray(ts), jnp.asarray(us))
    path = tmp_path_factory.mktemp("data") / "acrobot.csv"
    save_trajectory(Trajectory(jnp.asarray(ts), sim.xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",)), path)
    return path



def _memory_maps() -> int:
    try:
        with open("/proc/self/maps") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux
        return 0


def _max_memory_maps() -> int:
    try:
        return int(pathlib.Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return 65530


_MAP_LIMIT = _max_memory_maps() // 2


@pytest.fixture(autouse=True)
def _release_compiled_code():
    """Drop JAX's compiled executables when this worker holds many memory maps.

    XLA's CPU backend maps each compiled executable into memory of its own; a test worker that
    compiles several hundred programs (the whole suite on two workers) reaches the kernel's limit
    on memory maps per process (`vm.max_map_count`, 65530 by default) and the next compilation
    dies with a segmentation fault. `jax.clear_caches()` unmaps them; later tests compile again.
    """
    yield
    if _memory_maps() > _MAP_LIMIT:
        jax.clear_caches()
        gc.collect()


# The end-to-end runs that take a minute or more on the 2-core machine: the hidden-effect battery,
# the real-data diagnoses, the two-process run, the cache and tutorial runs. `make test` (and CI)
# runs them; `make quick` (`pytest -m "not slow and not heavy"`) leaves them out for iteration.
HEAVY_MODULES = (
    "tests/diagnose/test_hidden_effects.py",
    "tests/diagnose/test_real_data.py",
    "tests/diagnose/test_helicopter_candidates.py",
    "tests/diagnose/test_pure_delay.py",
    "tests/diagnose/test_discovery.py",
    "tests/diagnose/test_mujoco_data.py",
    "tests/distributed/test_two_processes.py",
    "tests/cli/test_cache.py",
    "tests/docs/test_tutorials.py",
)
HEAVY_TESTS = (
    "tests/identify/test_mujoco_data.py::test_defaults_on_mujoco_records_predict_as_well_as_mujoco_with_honest_standard_errors",
    "tests/identify/test_identify_defaults.py::test_noisy_rig_data_with_defaults_give_consistent_estimates",
    "tests/identify/test_identify_defaults.py::test_noisy_arms_of_other_sizes_give_consistent_estimates",
    "tests/identify/test_identify_defaults.py::test_encoder_angles_alone_with_defaults_give_consistent_estimates",
    "tests/identify/test_identify_defaults.py::test_dfki_least_squares_with_defaults_is_consistent_where_the_unfiltered_fit_is_not",
    "tests/identify/test_identify_defaults.py::test_one_dfki_run_alone_is_said_to_determine_the_size_parameters_poorly",
    "tests/identify/test_identify_defaults.py::test_a_resting_dfki_record_refined_by_default_is_still_said_to_be_poorly_determined",
    "tests/identify/test_angle_zeros.py::test_the_dfki_runs_read_their_angles_from_zeros_of_their_own",
    "tests/identify/test_angle_zeros.py::test_encoder_zeros_that_differ_between_records_are_found_measured_and_fitted_out",
    "tests/diagnose/test_report_and_cli.py::test_cli_diagnose_takes_several_runs_and_keeps_them_apart",
    "tests/control/test_experiment.py::test_quick_experiment_writes_results_and_figures",
    "tests/vehicle/test_compiled_solvers.py::test_compiled_backprop_takes_the_python_lbfgs_steps",
)


# The longest runs that are neither a hidden-effect test nor a real-data one (five to six minutes each on a
# slow 2-core machine, where the whole suite took 62 to 77 minutes on 2026-11-27): marked `slow`, so that
# `make test` and CI leave them out and `pytest -m ""` runs them.
SLOW_TESTS = (
    "tests/identify/test_mujoco_data.py::test_a_dry_friction_that_changes_between_recordings_is_carried_by_the_leave_one_record_out_errors",
    "tests/identify/test_mujoco_data.py::test_acrobot_defaults_on_mujoco_records_of_an_arm_driven_at_the_elbow_only",
)


def pytest_collection_modifyitems(config, items):
    for item in items:
        node = item.nodeid.split("[")[0]
        if node.split("::")[0] in HEAVY_MODULES or node in HEAVY_TESTS:
            item.add_marker(pytest.mark.heavy)
        if node in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
