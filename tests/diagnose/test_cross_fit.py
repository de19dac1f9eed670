"""Cross-fitting in `diagnose` (leave-one-run-out over the training runs, blocks of a single one): a left-out
run's windows weigh nothing in the fit, the screening pools the left-out runs, and the held-out test pools their
windows."""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import Acrobot, CoulombFriction, diagnose, Extended, InputOffset, Selection, Trajectory
from dynax.internal import cross_fit_folds, Family, fit_configurations, Fold, horizon_grid, make_windows
from dynax.synthetic import DEMO_TRUTH_PHYSICAL, Multisine, synthetic_trajectory

from .test_engine_rollouts_validation import _axis_record, NOMINAL


def _family(records, candidates):
    return Family(
        model=Extended(NOMINAL, candidates),
        names=("mass", "viscous", "coulomb", "offset"),
        refit=jnp.asarray([1.0, 1.0, 0.0, 0.0]),
        nominal_scale=jnp.asarray([95.0, 200.0, 1.0, 1.0]),
        candidate_scale=jnp.asarray([10.0, 10.0]),
        candidate_init=jnp.asarray([0.0, 0.0]),
        neutral=jnp.asarray([0.0, 0.0]),
        state_scale=jnp.asarray(np.concatenate([np.asarray(r.xs) for r in records]).std(axis=0)),
    )


def test_a_left_out_run_weighs_nothing_in_the_fit():
    """The fit with run 1's windows at weight zero is the fit on run 0's windows alone (cut out, another shape).
    The runs differ (Coulomb friction 25 N in one, 10 N in the other), so a fit that still saw run 1 would
    land elsewhere; and a left-out run whose rollouts diverge (NaN) must not spoil the fit."""
    runs = [
        _axis_record(Extended(NOMINAL, (CoulombFriction(0, 25.0, velocity_scale=0.01),)), seed=0, name="a.csv"),
        _axis_record(Extended(NOMINAL, (CoulombFriction(0, 10.0, velocity_scale=0.01),)), seed=1, name="b.csv"),
    ]
    candidates = (CoulombFriction(0, velocity_scale=0.01), InputOffset(0))
    family = _family(runs, candidates)
    both = make_windows(runs, 50, 50)
    alone = make_windows(runs[:1], 50, 50)
    poisoned = both.without_span(1, 0, len(runs[1]))
    xs = np.asarray(poisoned.xs).copy()
    xs[np.asarray(poisoned.starts)[:, 0] == 1] = np.nan  # what a diverged left-out rollout would give
    poisoned = eqx.tree_at(lambda w: w.xs, poisoned, jnp.asarray(xs))
    p0 = np.asarray([95.1089, 203.5034, 0.0, 0.0, 0.0, 1.0])
    args = (jnp.asarray([[-1]]), jnp.asarray([0]), jnp.asarray(p0[None]), jnp.ones(6))
    fits = {
        name: np.asarray(fit_configurations(family, w, *args)[0])[0, -1]
        for name, w in (("masked", poisoned), ("cut", alone), ("both", both))
    }
    assert abs(fits["cut"] - 25.0) < 1.0  # run 0's friction
    assert abs(fits["masked"] - fits["cut"]) < 1e-6 * abs(fits["cut"])
    assert abs(fits["both"] - fits["cut"]) > 3.0  # run 1 pulls a fit that sees it (between 10 and 25 N)


@pytest.mark.slow  # about 55 s
def test_a_short_held_out_run_with_cross_fitted_training_runs_names_a_small_friction():
    """Three 8 s training runs, one 2.5 s held-out run, Coulomb friction 0.03 N m at the elbow (the demo's
    truth acrobot, simulated on a finer grid than the fits use, with measurement noise). The held-out run
    alone is too short for the test (p = 0.011, not significant among 15 candidates: no finding); with each
    training run also held out in turn the friction is named at its size and helps on every run."""
    truth = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (CoulombFriction(1, 0.03),))

    def run(seed, seconds, name):
        record = synthetic_trajectory(
            truth, duration=seconds, dt=0.01, excitation=Multisine(amplitude=2.0), seed=seed, system_name="acrobot"
        )
        return dataclasses.replace(record, source=name)

    train = [run(s, 8.0, f"run{s}.csv") for s in (11, 12, 13)]
    validation = [run(14, 2.5, "held.csv")]
    j = diagnose(Acrobot(), train, validation, selection=Selection(discovery=False)).to_json()
    assert [(f["cause"], f["where"]) for f in j["findings"][:1]] == [("coulomb_friction", "q2")], j["findings"]
    assert abs(j["findings"][0]["coefficient"] - 0.03) < 0.003
    cross_fitted = [r for r in j["runs"] if r["held_out"] == "cross-fitted"]
    assert [r["run"] for r in cross_fitted] == ["run11.csv", "run12.csv", "run13.csv"]
    assert all(r["gain"] > 0 for r in cross_fitted), j["runs"]
    assert j["test"]["cross_fitting"] and any("Cross-fitting" in n for n in j["notes"])
    # The held-out run alone: the same candidates, no finding.
    alone = diagnose(Acrobot(), train, validation, selection=Selection(discovery=False, cross_fit=False)).to_json()
    assert not alone["findings"] and alone["test"]["cross_fitting"] is None
    assert all(r["held_out"] == "validation" for r in alone["runs"])


def test_a_single_training_run_is_cross_fitted_by_blocks_and_two_runs_are_not():
    """One run: three contiguous blocks covering it; two runs: no folds (each would fit one run alone); three: the
    runs; a run too short for blocks of eight longest reference horizons: none."""
    n_long = 50
    one = [np.zeros(3000)]
    assert cross_fit_folds(one, n_long) == (Fold(0, 0, 1000), Fold(0, 1000, 2000), Fold(0, 2000, 3000))
    assert cross_fit_folds([np.zeros(3000)] * 2, n_long) == ()
    assert cross_fit_folds([np.zeros(n) for n in (900, 1200, 3000)], n_long) == (
        Fold(0, 0, 900),
        Fold(1, 0, 1200),
        Fold(2, 0, 3000),
    )
    assert cross_fit_folds([np.zeros(3 * 8 * n_long - 1)], n_long) == ()


def _still(seconds, dt=0.01):
    n = int(round(seconds / dt)) + 1
    return Trajectory(np.arange(n) * dt, np.zeros((n, 2)), np.zeros((n, 1)), ("q", "dq"), ("force",))


def test_the_candidate_horizons_stop_where_a_single_training_run_can_still_be_cross_fitted():
    """A 20 s run beside a 20 s held-out one: the held-out time alone would allow 1 s (a twentieth of it), which
    would leave the run too short for three blocks of eight horizons; the candidates stop at 0.8 s, where they fit.
    Where the held-out time is the shorter cap (the calibration battery's 10 s), two runs are not cross-fitted, or
    cross-fitting is off, the candidates are what they were."""
    horizons = (0.1, 0.25, 0.5, 1.0, 2.0)

    def longest(train, held_out, cross_fit=True):
        return float(horizon_grid(horizons, None, train, held_out, [], cross_fit=cross_fit)[1].max())

    assert longest([_still(20.0)], [_still(20.0)]) == pytest.approx(0.8)
    assert cross_fit_folds([np.zeros(2001)], 80) and not cross_fit_folds([np.zeros(2001)], 100)
    assert longest([_still(20.0)], [_still(20.0)], cross_fit=False) == pytest.approx(1.0)
    assert longest([_still(20.0)], [_still(10.0)]) == pytest.approx(0.5)
    assert longest([_still(20.0)] * 2, [_still(20.0)]) == pytest.approx(1.0)


def test_a_held_out_block_leaves_out_every_fit_window_that_shares_a_sample_with_it():
    """Windows of 50 steps every 10 samples; holding out samples 400:600 of record 0 zeroes exactly the windows of
    record 0 that reach into it (start + 50 >= 400 and start < 600), and nothing of record 1."""
    runs = [
        _axis_record(Extended(NOMINAL, (CoulombFriction(0, 25.0, velocity_scale=0.01),)), seed=s, name=f"{s}.csv")
        for s in (0, 1)
    ]
    windows = make_windows(runs, 50, 10)
    starts, weights = np.asarray(windows.starts), np.asarray(windows.without_span(0, 400, 600).weights)
    expected = ~((starts[:, 0] == 0) & (starts[:, 1] >= 350) & (starts[:, 1] < 600))
    assert np.array_equal(weights == 1.0, expected) and (weights[~expected] == 0).all()
    assert expected.sum() < len(expected) and (weights[starts[:, 0] == 1] == 1).all()


def test_the_host_coefficients_are_the_compiled_ones_bit_for_bit():
    """`Family.host_coefficients` (numpy, for the host) gives `Family.coefficients`' numbers for every configuration:
    each slot, the new term, none, negative and zero parameters, zero and nonzero neutral values; and a model built
    from them has the same leaves as one built from the compiled coefficients."""
    import equinox as eqx
    import jax

    record = _axis_record(NOMINAL, seed=0, name="a.csv")
    family = _family([record], (CoulombFriction(0, velocity_scale=0.01), InputOffset(0)))
    rng = np.random.default_rng(0)
    checked = 0
    for neutral in ([0.0, 0.0], [1.0, 0.0], [0.0, -2.5]):
        fam = eqx.tree_at(lambda f: f.neutral, family, jnp.asarray(neutral))
        for slots in ([-1, -1], [0, -1], [1, -1], [1, 0], [-1, 1]):
            for new in (-1, 0, 1):
                if new >= 0 and new in slots:
                    continue
                for p in (rng.normal(size=7), -np.abs(rng.normal(size=7)), np.zeros(7), -np.zeros(7)):
                    compiled = fam.coefficients(jnp.asarray(slots), jnp.asarray(new), jnp.asarray(p))
                    host = fam.host_coefficients(np.asarray(slots), new, p)
                    np.testing.assert_array_equal(host, np.asarray(compiled))
                    assert np.array_equal(np.signbit(host), np.signbit(np.asarray(compiled)))
                    checked += 1
    assert checked == 3 * 10 * 4
    values = jnp.asarray(np.asarray([95.0, 200.0, 1.0, 1.0]))
    coefficients = np.asarray([0.3, -0.0])
    by_host = jax.tree.leaves(family.build(values, coefficients))
    by_device = jax.tree.leaves(family.build(values, jnp.asarray(coefficients)))
    assert len(by_host) == len(by_device)
    for a, b in zip(by_host, by_device):
        assert isinstance(a, jax.Array) and a.dtype == b.dtype and a.weak_type == b.weak_type
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
