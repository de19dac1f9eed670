"""Per-record Coulomb friction (`identify(...).record_friction`): a friction that changes from one
recording to the next is found and told apart from records that agree.

The records are made by scipy's DOP853 (not dynax's integrator) with sensor noise at the DFKI rig's
level (`recorded` in `test_identify_defaults`), each with its own elbow friction in the simulated arm.
"""

import numpy as np
import pytest

import dynax
from dynax import Dynamic, identify
from dynax.internal import record_friction
from tests.identify.test_identify_defaults import recorded, RIG, RIG_FC, RIG_IR2

SEEDS = (20, 21, 22, 23)
DIFFERENT = (0.08, 0.16, 0.10, 0.13)  # elbow Coulomb friction per record, N m (the rig's: 0.12)


def arm(fc2):
    rigid = dynax.DoublePendulum.from_base_parameters(RIG)
    return dynax.Extended(
        rigid, (dynax.CoulombFriction(0, RIG_FC[0]), dynax.CoulombFriction(1, fc2), dynax.RotorInertia(1, RIG_IR2))
    )


@pytest.fixture(scope="module")
def differing():
    return [recorded(arm(fc2), 6.0, seed) for fc2, seed in zip(DIFFERENT, SEEDS)]


def test_a_friction_that_differs_between_records_is_found(differing):
    result = identify(
        dynax.DoublePendulum(),
        differing,
        Dynamic(),
        friction="coulomb",
        refine=False,
        validation=dynax.Validate(holdout=0),
    )
    found = result.record_friction
    assert found is not None and found.columns == ("fc1", "fc2")
    assert found.differ() == ("fc2",), (found.f_statistic, found.p_value)
    # The least-squares stage's filter biases every record's value low by about the same (0.12 reads
    # 0.10 on the same records, below), so the records' departures from their mean are what is measured:
    # each within 0.015 N m of the truth's, in the truth's order.
    values, truth = found.values[:, 1], np.asarray(DIFFERENT)
    assert np.max(np.abs((values - values.mean()) - (truth - truth.mean()))) < 0.015, values
    assert list(np.argsort(values)) == list(np.argsort(truth))
    # The parts of each record agree with each other more than the records do: what F measures.
    spread_within = np.sqrt(np.mean(np.var(found.parts[:, :, 1], axis=1, ddof=1)))
    assert found.parts.shape == (4, 4, 2) and spread_within < np.std(values, ddof=1), found.parts[:, :, 1]
    assert found.relative_error < found.shared_relative_error
    note = result.to_json()["record_friction"]["note"]
    assert note is not None and "fc2" in note and "fc1 (" not in note


def test_records_that_share_their_friction_are_not_said_to_differ():
    same = [recorded(arm(RIG_FC[1]), 6.0, seed) for seed in SEEDS]
    found = identify(
        dynax.DoublePendulum(), same, Dynamic(), friction="coulomb", refine=False, validation=dynax.Validate(holdout=0)
    ).record_friction
    assert found.differ() == (), (found.f_statistic, found.p_value)
    # Spread 0.017 N m (0.096 to 0.113), against 0.08 in the records above; all low by the filter's bias.
    assert np.ptp(found.values[:, 1]) < 0.025 and 0.09 < np.mean(found.values[:, 1]) < 0.13, found.values
    assert found.to_json()["note"] is None


def test_exact_equations_recover_each_records_coefficient():
    # Equations with no residual: the friction column of the second record carries 0.3 more than the
    # others' 0.1 (and the records carry offsets of their own, which must not leak into the friction).
    rng = np.random.default_rng(0)
    counts, n = (50, 60, 70), 180
    a = rng.normal(size=(2 * n, 3))
    a[:, 2] = np.sign(rng.normal(size=2 * n))  # a Coulomb-like column
    per_row = np.full(2 * n, 0.1)
    for joint in range(2):  # rows stacked joint by joint, `counts` per record
        per_row[joint * n + counts[0] : joint * n + counts[0] + counts[1]] += 0.3
    y = a[:, :2] @ np.array([1.0, -2.0]) + per_row * a[:, 2]
    y[: counts[0]] += 0.5  # record 0's offset on the first joint
    found = record_friction(a, y, counts, ("t1", "t2", "fc1"), ("fc1",))
    np.testing.assert_allclose(found.values[:, 0], [0.1, 0.4, 0.1], atol=1e-10)
    assert found.differ() == ("fc1",) and found.relative_error < 1e-10


def test_nothing_to_compare_gives_none():
    a, y = np.ones((40, 2)), np.ones(40)
    assert record_friction(a, y, (20,), ("t1", "fc1"), ("fc1",)) is None  # one record
    assert record_friction(a, y, (10, 10), ("t1", "b1"), ("fc1",)) is None  # no Coulomb column


def test_dfki_runs_disagree_on_the_elbow_friction(datasets):
    from tests.identify.test_identify_defaults import dfki

    runs = [dfki(datasets, r) for r in ("00", "01", "02", "03", "05")]
    found = identify(
        dynax.DoublePendulum(), runs, Dynamic(), friction="coulomb", refine=False, validation=dynax.Validate(holdout=0)
    ).record_friction
    # measured 2026-11-26: elbow 0.062 (run 02) to 0.123 N m (run 00), F = 56 on (4, 15) degrees of freedom
    assert "fc2" in found.differ(), (found.f_statistic, found.p_value)
    assert np.ptp(found.values[:, 1]) > 0.04, found.values


def test_the_two_halves_of_the_emps_record_agree_on_their_friction(datasets):
    # A real negative control on another machine (a linear axis, friction a base parameter): one EMPS
    # record cut in two is two records of the same session, whose Coulomb friction must agree. Measured
    # 2026-11-26: 19.97 and 20.01 N (the published 20.39; the eight parts 19.86 to 20.16), F = 0.21 on (1, 6)
    # degrees of freedom, p = 0.67.
    data = dynax.load_trajectory(
        datasets / "emps" / "DATA_EMPS.mat",
        "linear_axis",
        mapping={"q": "qm", "force": "vir"},
        scale={"force": 35.15065188},
    )
    n = len(data)
    result = identify(
        dynax.LinearAxis(),
        [data.slice(0, n // 2), data.slice(n // 2, n)],
        Dynamic(),
        friction="coulomb",
        validation=dynax.Validate(holdout=0),
        refine=False,
    )
    found = result.record_friction
    assert found is not None and found.columns == ("coulomb",)
    assert found.differ() == (), (found.values, found.f_statistic, found.p_value)
    np.testing.assert_allclose(found.values[:, 0], result.parameters["coulomb"], rtol=0.02)
