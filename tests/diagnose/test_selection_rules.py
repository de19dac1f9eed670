"""The admissibility rules of one selection round (`dynax.internal.judge_round`): a candidate whose joint refit pushes
an earlier finding's coefficient to an unphysical sign is not admissible, however much it helps; a
candidate that adds to a nominal parameter the refit keeps (viscous friction) may lower it, not below zero."""

from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np
import pytest

from dynax import (
    Acrobot,
    CoulombFriction,
    default_candidates,
    InputDelay,
    InputLag,
    InputOffset,
    Known,
    Refit,
    Selection,
    Trajectory,
    ViscousFriction,
)
from dynax.internal import (
    candidate_family,
    held_partners,
    judge_round,
    look_alike_tests,
    names_to_refit,
    on_physical_side,
    Refitted,
)


def _round(earlier_fc1, new_delta, *, earlier=CoulombFriction(0)):
    """One round: Coulomb friction at q1 was selected earlier (slot 0); Coulomb friction at q2 is
    refitted jointly with it and lowers every held-out window's error by 40 % (noisy, clearly significant)."""
    rng = np.random.default_rng(0)
    candidates = (earlier, CoulombFriction(1))
    n_nom, max_terms, n_windows, n_steps = 2, 2, 120, 11
    p = np.zeros((2, n_nom + max_terms + 1))
    p[:, n_nom] = earlier_fc1  # the earlier term's coefficient, as each configuration's joint refit left it
    p[1, -1] = new_delta
    score_cur = rng.uniform(1.0, 2.0, n_windows)
    scores = np.stack([score_cur, 0.6 * score_cur * rng.uniform(0.9, 1.1, n_windows)])
    errors = np.ones((2, n_windows, n_steps, 4)) * np.asarray([1.0, 0.7])[:, None, None, None]
    physical = lambda k, delta: on_physical_side(candidates[k], delta, None, (), None)  # noqa: E731
    results = _judge(physical, [1], [0], n_nom, p, errors, scores, score_cur, np.repeat([0, 1], n_windows // 2))
    return results[1]


def _judge(physical, short, selected, n_nom, p, errors, scores, score_cur, runs, n_val=None):
    """`judge_round` of one refitted batch: `short` refitted (the only candidates remaining), `selected` before it,
    every window of `score_cur` held out unless `n_val` says how many are (the rest cross-fitted)."""
    problem = SimpleNamespace(
        physical=physical,
        static_level=lambda *_: None,  # no static friction level in these configurations
        names=tuple(f"theta{i}" for i in range(n_nom)),
        position_index=[0, 1],
        selection=Selection(alpha=0.01, min_gain=0.05),
    )
    yard = SimpleNamespace(
        window_runs=runs, overlap=1, steps=np.asarray([5, 10]), n_val=len(score_cur) if n_val is None else n_val
    )
    current = SimpleNamespace(selected=selected, score=score_cur)
    return judge_round(problem, yard, current, short, Refitted(short, p, np.full_like(p, 0.01), errors, scores))


def test_a_candidate_that_helps_with_every_coefficient_physical_is_admissible():
    r = _round(earlier_fc1=0.2, new_delta=0.1)
    assert r["p"] < 1e-6 and r["gain_windows"] > 0.3
    assert r["physical"] and r["significant"]


@pytest.mark.parametrize("earlier_fc1, new_delta", [(-0.02, 0.1), (0.2, -0.1)])
def test_a_joint_refit_with_any_unphysical_coefficient_is_not_admissible(earlier_fc1, new_delta):
    """The new coefficient's sign was always checked; an earlier finding's, moved by the joint refit, is too."""
    r = _round(earlier_fc1, new_delta)
    assert r["p"] < 1e-6 and r["gain_windows"] > 0.3  # it helps ...
    assert not r["physical"] and not r["significant"]  # ... but not with a physical model
    assert r["rules"] == {
        "significance": True,
        "min_gain": True,
        "sign": False,
        "agreement": True,
        "held_out": True,
    }  # the one rule that stops it


def test_a_candidate_the_cross_fitted_runs_carry_but_the_held_out_runs_reject_is_not_admissible():
    """Cross-fitting pools the training runs' left-out windows with the held-out runs'. A candidate that
    lowers the cross-fitted windows' error by half but raises the held-out runs' by 10 % passes the pooled
    test, the smallest gain and the agreement across runs (three runs of four), and is stopped by the
    held-out runs alone; the same candidate helping the held-out runs a little is admissible."""
    rng = np.random.default_rng(2)
    n_val, n_cv = 60, 180
    score_cur = rng.uniform(1.0, 2.0, n_val + n_cv)
    runs = np.repeat([0, 1, 2, 3], [n_val, n_cv // 3, n_cv // 3, n_cv // 3])

    def judged(held_out_factor):
        factor = np.where(np.arange(n_val + n_cv) < n_val, held_out_factor, 0.5)
        scores = np.stack([score_cur, score_cur * factor * rng.uniform(0.95, 1.05, n_val + n_cv)])
        p = np.zeros((2, 3))
        p[1, -1] = 0.1
        errors = np.ones((2, n_val + n_cv, 11, 4))
        physical = lambda k, delta: True  # noqa: E731
        return _judge(physical, [0], [], 2, p, errors, scores, score_cur, runs, n_val=n_val)[0]

    harmful = judged(1.1)
    assert harmful["gain_windows"] > 0.3 and harmful["gain_held_out"] < 0
    assert harmful["rules"] == {
        "significance": True,
        "min_gain": True,
        "sign": True,
        "agreement": True,
        "held_out": False,
    }
    assert not harmful["significant"]
    assert judged(0.97)["significant"]


def _runs_of_scale(scales, factors, n=60, seed=3):
    """Held-out windows of runs whose nominal window error has the scale `scales[r]`, and a candidate that multiplies
    run `r`'s window errors by `factors[r]` (5 % window-to-window noise): the effect on each run is made here, not
    read from any rule."""
    rng = np.random.default_rng(seed)
    runs = np.repeat(np.arange(len(scales)), n)
    score_cur = rng.uniform(1.0, 2.0, runs.size) * np.asarray(scales, float)[runs]
    return runs, score_cur, score_cur * np.asarray(factors, float)[runs] * rng.uniform(0.95, 1.05, runs.size)


def _judged_alone(runs, score_cur, score_new, n_val=None):
    """`judge_round` of one physical candidate whose window scores are `score_new`."""
    p = np.zeros((2, 3))
    p[1, -1] = 0.1
    errors = np.ones((2, runs.size, 11, 4))
    scores = np.stack([score_cur, score_new])
    return _judge(lambda k, delta: True, [0], [], 2, p, errors, scores, score_cur, runs, n_val=n_val)[0]


def _pooled(score_cur, score_new):
    return 1.0 - float(np.sum(score_new) / np.sum(score_cur))


def test_an_effect_on_every_run_is_not_stopped_by_the_run_of_largest_error():
    """Two held-out runs whose window error the candidate cuts by 60 % and 40 %, and a cross-fitted run whose windows
    score thirty times theirs and which it helps by 1 % (a real rig's elbow friction beside a run it barely changes):
    the pooled gain, below 5 %, reads that run's scale; the test and the smallest-gain rule read the typical window,
    and the effect, real on every run, is admissible."""
    runs, score_cur, score_new = _runs_of_scale((1.0, 1.0, 30.0), (0.4, 0.6, 0.99))
    assert all(_pooled(score_cur[runs == r], score_new[runs == r]) > 0 for r in range(3))  # real on each run
    r = _judged_alone(runs, score_cur, score_new, n_val=120)
    assert r["gain_windows"] == pytest.approx(_pooled(score_cur, score_new)) and r["gain_windows"] < 0.05
    assert all(r["rules"].values()) and r["significant"] and r["p"] < 1e-6
    assert r["gain_held_out"] > 0.4 and r["gain_typical"] > 0.25


def test_a_pooled_gain_from_a_few_windows_of_large_error_is_no_practical_effect():
    """The nominal model loses one stretch (four windows score a hundred times the rest); the candidate mends that
    stretch and makes every other window 12 % worse. Pooled, it gains more than half; on the typical window it gains
    nothing, and the smallest-gain rule stops it."""
    runs, score_cur, score_new = _runs_of_scale((1.0, 1.0), (1.12, 1.12))
    stretch = slice(20, 24)
    score_cur[stretch] *= 100.0
    score_new[stretch] = score_cur[stretch] * 0.1
    assert _pooled(score_cur, score_new) > 0.5
    assert np.mean(np.log(score_cur / score_new)) < 0  # the geometric mean of the windows' ratios: worse
    r = _judged_alone(runs, score_cur, score_new)
    assert not r["rules"]["min_gain"] and not r["significant"]
    assert r["gain_windows"] > 0.5 and r["gain_typical"] < 0.05


def test_a_term_that_wins_on_runs_of_small_error_and_loses_on_the_largest_is_not_named():
    """The other way round: two runs whose error the candidate cuts by 70 % and one whose windows score thirty times
    theirs and which it makes 15 % worse. Its typical window gains, its pooled held-out error grows: the `held_out`
    rule stops it (it helps on two runs of three, which the agreement rule allows)."""
    runs, score_cur, score_new = _runs_of_scale((1.0, 1.0, 30.0), (0.3, 0.3, 1.15))
    r = _judged_alone(runs, score_cur, score_new)
    assert r["rules"]["agreement"] and not r["rules"]["held_out"] and not r["significant"]
    assert r["gain_typical"] > 0.25 and r["gain_held_out"] < 0


def test_terms_of_either_sign_are_not_constrained():
    """An input offset may be negative: a joint refit that moves it there is admissible."""
    r = _round(earlier_fc1=-0.3, new_delta=0.1, earlier=InputOffset(0))
    assert r["physical"] and r["significant"]


def _acrobot_family(mode):
    system = Acrobot()
    rng = np.random.default_rng(0)
    record = Trajectory(
        jnp.arange(200) * 0.01,
        jnp.asarray(rng.normal(size=(200, 4))),
        jnp.asarray(rng.normal(size=(200, 1))),
        system.state_names,
        system.input_names,
    )
    candidates = default_candidates(system)
    refit = names_to_refit(system, mode)
    family, _, _ = candidate_family(system, candidates, refit, [record])
    return system, candidates, refit, family


def test_refit_keeps_the_nominal_friction_and_its_viscous_candidates_add_to_it():
    system, candidates, refit, family = _acrobot_family(Refit())
    assert refit == ("theta1", "theta2", "theta3", "theta4", "theta5")
    partners = held_partners(family, 1.0 - np.asarray(family.refit))
    by_label = {t.label(system): partners[k] for k, t in enumerate(candidates)}
    # The arm's damping is theta6 dq1 (theta7 dq2); ViscousFriction(j, b) is -b dq_j: the same coefficient.
    assert by_label["viscous_friction@q1"][0] == family.names.index("theta6")
    assert by_label["viscous_friction@q2"][0] == family.names.index("theta7")
    assert by_label["viscous_friction@q1"][1] == pytest.approx(1.0, rel=1e-9)
    assert by_label["coulomb_friction@q2"] is None and by_label["rotor_inertia@q2"] is None
    # theta6 = 0.1 in the nominal model: lowering it by 0.05 is physical, by 0.2 is not.
    names = family.names
    assert on_physical_side(ViscousFriction(0), -0.05, by_label["viscous_friction@q1"], names, system)
    assert not on_physical_side(ViscousFriction(0), -0.2, by_label["viscous_friction@q1"], names, system)
    assert on_physical_side(ViscousFriction(0), 0.3, by_label["viscous_friction@q1"], names, system)


def test_all_parameters_can_still_be_refitted_and_known_mode_refits_none():
    assert names_to_refit(Acrobot(), Refit(parameters=tuple(f"theta{i}" for i in range(1, 8))))[-1] == "theta7"
    assert names_to_refit(Acrobot(), Known()) == ()


def test_a_look_alike_is_told_apart_only_by_a_difference_that_matters():
    """A look-alike whose every held-out window is 1 % worse than the finding's is *significantly* worse
    (hundreds of windows, p far below alpha) but not told apart: the difference is below `min_gain`, the
    margin any candidate must gain to count. One 30 % worse is told apart; a structural equivalent never is."""
    rng = np.random.default_rng(1)
    n_windows = 240
    best = rng.uniform(1.0, 2.0, n_windows)
    worse = lambda factor: best * factor * np.exp(rng.normal(0.0, 0.002, n_windows))  # noqa: E731
    scores = np.stack([np.ones(n_windows), best, worse(1.01), worse(1.3), worse(1.3)])
    candidates = (ViscousFriction(1), CoulombFriction(1), InputOffset(0), ViscousFriction(0))
    problem = SimpleNamespace(
        selection=Selection(alpha=0.01, min_gain=0.05),
        candidates=candidates,
        system=Acrobot(),
        look_alikes=lambda k: [1, 2, 3],
        equivalents={0: [3]},
        dt=0.01,
        neutral=np.zeros(4),
    )
    results = {k: {"i": k + 1, "gain_held_out": 0.5, "delta": 0.1} for k in range(4)}
    yard = SimpleNamespace(window_runs=np.repeat([0, 1], n_windows // 2), overlap=1)
    tests = {a["cause"] + str(i): a for i, a in enumerate(look_alike_tests(problem, yard, 0, results, scores))}
    near, far, equivalent = tests["coulomb_friction0"], tests["input_offset1"], tests["viscous_friction2"]
    assert near["p_value"] < 1e-6 and near["gain_over"] == pytest.approx(0.01, abs=0.002)
    assert not near["told_apart"]
    assert far["p_value"] < 1e-6 and far["gain_over"] > 0.2 and far["told_apart"]
    assert equivalent["equivalent"] and not equivalent["told_apart"]


class _CoarseLag(InputLag):
    """A lag whose rollouts resolve it down to 1.25 steps only (a term may say so: `shortest_resolved`)."""

    def shortest_resolved(self, step: float) -> float:
        return 1.25 * step


def test_a_look_alike_fitted_below_what_its_rollouts_resolve_is_not_told_apart():
    """A look-alike fitted below what its term's rollouts resolve (`shortest_resolved`) is simulated wrong, so its far
    worse held-out error is no evidence against it: not told apart, and marked unresolved. The same pair fitted at a
    resolvable size is told apart by the same scores. A dead time resolves at any size (the windowed rollouts shift
    the input by it), so it is told apart from a lag at half a sample."""
    rng = np.random.default_rng(2)
    n_windows = 240
    best = rng.uniform(1.0, 2.0, n_windows)
    scores = np.stack([np.ones(n_windows), best, best * 1.5 * np.exp(rng.normal(0.0, 0.002, n_windows))])
    yard = SimpleNamespace(window_runs=np.repeat([0, 1], n_windows // 2), overlap=1)
    for other, size, resolved in (
        (_CoarseLag(0), 0.005, False),
        (_CoarseLag(0), 0.03, True),
        (InputLag(0), 0.005, True),
    ):
        problem = SimpleNamespace(
            selection=Selection(alpha=0.01, min_gain=0.05),
            candidates=(InputDelay(0), other),
            system=Acrobot(),
            look_alikes=lambda k: [1],
            equivalents={},
            dt=0.01,
            neutral=np.zeros(2),
        )
        results = {k: {"i": k + 1, "gain_held_out": 0.5, "delta": size} for k in range(2)}
        (lag,) = look_alike_tests(problem, yard, 0, results, scores)
        assert lag["p_value"] < 1e-6 and lag["gain_over"] > 0.2
        assert lag["resolved"] is resolved and lag["told_apart"] is resolved
