"""The typed feature library: the period search, named equivalents, physical readings."""

import numpy as np

from dynax import Acrobot, LinearAxis
from dynax.internal import Discovered, Feature, feature_library, named_equivalent, physical_readings, search_period


def test_period_search_finds_the_period_of_a_force_periodic_in_position():
    rng = np.random.default_rng(0)
    q = np.cumsum(rng.normal(0, 0.003, 4000))  # a wandering position, as under a random force
    y = 3.0 * np.sin(2 * np.pi * q / 0.037 + 1.1) + 2.0 * q + rng.normal(0, 2.0, q.size)
    period, explained = search_period(q, y - 2.0 * q, p_min=0.005, p_max=float(np.ptp(q)) / 2)
    assert abs(period / 0.037 - 1) < 0.01
    assert explained > 0.3


def test_library_is_typed_by_coordinate():
    xs = np.random.default_rng(1).normal(size=(100, 4))
    names = [f.name(Acrobot()) for f in feature_library(Acrobot(), 1, xs)]
    assert {"q2", "sin(q1)", "sign(dq2)", "|dq2|dq2", "q2*sign(dq2)", "tau2", "tau2*q2", "1"} <= set(names)
    assert not any("2π" in n for n in names)  # angles get sin/cos, not a searched period
    axis = [f.name(LinearAxis()) for f in feature_library(LinearAxis(), 0, xs[:, :2], period=0.05)]
    assert "sin(2π q/0.05)" in axis and "sin(q)" not in axis


def test_features_a_named_cause_represents_carry_its_label():
    acrobot = Acrobot()
    assert named_equivalent(acrobot, Feature("sign", 1), 1) == "coulomb_friction@q2"
    assert named_equivalent(acrobot, Feature("abs_velocity", 0), 0) == "quadratic_drag@q1"
    assert named_equivalent(acrobot, Feature("input", 1, input=0), 1) == "input_gain@tau2"
    assert named_equivalent(acrobot, Feature("constant", 1), 1) == "input_offset@tau2"
    assert named_equivalent(acrobot, Feature("constant", 0), 0) is None  # the shoulder is not driven
    assert named_equivalent(acrobot, Feature("position", 1), 1) is None


def test_readings_name_a_spring_and_a_periodic_force():
    spring = physical_readings(Acrobot(), Discovered(1, (Feature("position", 1),), [-1.5]))
    assert spring and "joint spring" in spring[0] and "k = 1.5" in spring[0]
    pair = (Feature("periodic_sin", 0, period=0.05), Feature("periodic_cos", 0, period=0.05))
    periodic = physical_readings(LinearAxis(), Discovered(0, pair, [3.0, 4.0]))
    assert "period 0.05 m" in periodic[0] and "amplitude 5 N" in periodic[0]
