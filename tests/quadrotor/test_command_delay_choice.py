"""The NanoBench experiments' command dead time: chosen on training flights alone, applied as a model property.

`experiments/nanobench_heldout.py --command-delay scan` (and the models `nanobench_paired.py` pairs with a delay)
choose the dead time between the logged motor commands and the motion on the training flights (the regression of
the angular acceleration on the commands taken k samples earlier, `experiments/nanobench_delay.py`), and apply it
by moving the commands (`delayed_commands`). Checked on synthetic flights made without dynax's model code
(`synthetic_flight.quadrotor_flight`, each rotor receiving the command logged `delay / dt` samples before).
"""

import pathlib
import sys

import numpy as np
import pytest

from .synthetic_flight import quadrotor_flight

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[2] / "experiments"


@pytest.fixture(scope="module")
def experiment():
    pytest.importorskip("scipy.signal")
    sys.path.insert(0, str(EXPERIMENTS))  # its scan imports `nanobench_delay` when called
    try:
        import nanobench_heldout

        yield nanobench_heldout
    finally:
        sys.path.remove(str(EXPERIMENTS))


def test_runs_delayed_by_different_times_line_up_on_the_same_rows(experiment):
    """Row i of a run delayed by k from row `first` on holds the state of row first + i and the motor commands of
    row first + i - k; `vbat` stays at its own row."""
    flight = quadrotor_flight(1.0, seed=0, noise=False, vbat=True)
    us = np.asarray(flight.us)
    late, early = experiment.delayed_commands(flight, 4, 5), experiment.delayed_commands(flight, 1, 5)
    for run, k in ((late, 4), (early, 1)):
        assert len(run) == len(flight) - 5
        np.testing.assert_array_equal(np.asarray(run.xs), np.asarray(flight.xs)[5:])
        np.testing.assert_array_equal(np.asarray(run.us)[:, :4], us[5 - k : len(flight) - k, :4])
        np.testing.assert_array_equal(np.asarray(run.us)[:, 4], us[5:, 4])
    assert experiment.delayed_commands(flight, 0) is flight
    with pytest.raises(ValueError, match="no commands 4 samples earlier"):
        experiment.delayed_commands(flight, 4, 3)


def test_the_training_scan_finds_a_hidden_dead_time(experiment):
    """A 40 ms dead time hidden in a 10 s flight is chosen at 4 samples, or 5: the scan's angular acceleration is a
    centred derivative, which reads the commands of the two intervals around a sample and so puts a zero-order
    hold's effect half a sample late (the same flight without the delay is chosen at 0 or 1 samples)."""
    delayed = experiment.command_delay("scan", [quadrotor_flight(10.0, seed=1, delay=0.04)])
    prompt = experiment.command_delay("scan", [quadrotor_flight(10.0, seed=1)])
    assert delayed in (4, 5), delayed
    assert prompt in (0, 1), prompt
