"""Flights given together whose motors or battery are logged in different units (percent among 0-65535 counts,
millivolts among volts): one motor map fitted to all of them predicts none. The command line refuses them
(`tests/cli/hostile_flights.py`); the Python fit and diagnosis warn. The synthetic flights are
`tests/quadrotor/synthetic_flight.py`'s (scipy's DOP853, no dynax model code); the real ones NanoBench's."""

import warnings

import numpy as np
import pytest

import dynax
from dynax.internal import check_input_levels, input_levels
from tests.quadrotor.synthetic_flight import quadrotor_flight
from tests.quadrotor.test_flight_data import NANOBENCH, NANOBENCH_MAP, STAR


def _scaled(flight, column, factor):
    us = np.asarray(flight.us).copy()
    us[:, column] *= factor
    return dynax.Trajectory(flight.ts, flight.xs, us, flight.state_names, flight.input_names, flight.system)


@pytest.fixture(scope="module")
def flights():
    return [quadrotor_flight(6.0, seed=seed, vbat=True) for seed in (3, 4, 5)]


def test_fit_quadrotor_warns_where_one_flight_logs_its_motors_in_percent(flights):
    start = dynax.Quadrotor.from_flights("nominal", flights)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dynax.DataWarning)
        dynax.fit_quadrotor(start, flights, progress=False)
    percent = [*flights[:2], _scaled(flights[2], slice(0, 4), 100 / 65535)]
    with pytest.warns(dynax.DataWarning, match=r"\(flights\[2\]\).*motor inputs.*another unit"):
        dynax.fit_quadrotor(start, percent, progress=False)


def test_the_quadrotor_diagnosis_warns_where_a_validation_flight_logs_millivolts(flights):
    start = dynax.Quadrotor.from_flights("nominal", flights)
    millivolts = _scaled(flights[2], 4, 1e3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dynax.DataWarning)
        with pytest.raises(dynax.DataWarning, match=r"\(flights\[2\]\).*battery voltage.*millivolts"):
            dynax.diagnose(start, flights[:2], millivolts, progress=False)


@pytest.mark.skipif(not STAR.exists(), reason="the NanoBench flights are not in ../shared/datasets")
def test_real_flights_of_one_vehicle_share_their_levels():
    # the 16 NanoBench flights' levels lie within 6 % (motors) and 13 % (battery) of their median
    # (`experiments/flight_input_levels.py`); four of them, and the star flight in percent among them
    levels = {}
    for name in ("B8_star_fast_rep1", "B9_trefoil_medium_rep2", "B6_linear_ramp_rep1", "B10_lissajous_slow_rep1"):
        trajectory, notes = dynax.load_flight(NANOBENCH / f"{name}.csv.gz", mapping=NANOBENCH_MAP)
        levels[name] = input_levels(trajectory, notes.usable)
    check_input_levels(levels, columns=NANOBENCH_MAP)
    levels["B8_star_fast_rep1"]["m1"] *= 100 / 65535
    with pytest.raises(dynax.DataError, match="another unit") as refused:
        check_input_levels(levels, columns=NANOBENCH_MAP)
    assert "B8_star_fast_rep1" in str(refused.value) and refused.value.column == "motor_motor_m1"
