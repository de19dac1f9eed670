"""The selection rules of a diagnosis round: which refitted candidates pass, which is named, and
whether its look-alikes are told apart.

A round's shortlisted candidates are refitted (`_diagnose._refit`) and scored on held-out windows
(`_summaries.window_scores`); `judge_round` applies the rules (significance under
Benjamini-Hochberg, the smallest gain, physical signs, agreement across runs, no harm on the
held-out runs), `rank` orders those that pass, and `look_alike_tests` says whether the named one is
told apart from its look-alikes. The statistics themselves are in `_statistics.py`.

**Which gain the rules read.** The paired test weighs every window's log error ratio alike, so the
practical size its rules read is the gain that same mean implies, `typical_gain` (one minus the geometric
mean of the windows' error ratios), not the pooled `window_gain` (one minus the ratio of the mean
errors), which weighs windows by their error. The two part where runs differ in error scale: on a real
rig a Coulomb friction that gains 75 % and 32 % on the two held-out runs gains 3 % pooled, because a
cross-fitted run's windows score ten times the others' and the friction barely changes them; the pooled
gain reads that one run's scale, not the effect, and the smallest-gain rule would stop an effect the test
establishes. The other way round, a term that mends a few windows of large error (a stretch the
nominal model loses) gains much pooled and nothing on the typical window, and a significant test on it is
not a practical effect. Either way the rule and the test speak of one quantity. Harm stays judged in
the error itself: a term that wins big on a run of small error and loses on one of large error has a
typical gain but makes the held-out runs' pooled error larger or helps on too few runs, and the
`held_out` and `agreement` rules stop it. The pooled gains are still reported (`gain`, `gain_pooled`),
and `rank` still chooses among the candidates that pass by the held-out runs' pooled gain, the error the
returned model is measured by.
"""

import dataclasses

import numpy as np

from .._model._linear_in_parameters import identification_hooks, violated_bound
from ._candidates import host_nominal_values
from ._statistics import benjamini_hochberg, helps_on_most_runs, log_ratio_differences, paired_block_test, typical_gain
from ._summaries import rmse_curve


def window_gain(score_ref, score_new) -> float:
    """The relative drop of the mean window score from `score_ref` to `score_new` (positive: better)."""
    return float(1 - np.mean(score_new) / np.mean(score_ref))


def paired_test(score_ref, score_new, runs, overlap):
    """One-sided paired test that `score_new` is smaller than `score_ref` over held-out windows (see `_statistics`)."""
    return paired_block_test(log_ratio_differences(score_ref, score_new), runs, overlap)


def look_alike_tests(problem, yard, best, results, scores):
    """Each refitted look-alike of `best` against it: held-out gain, paired p, the finding's gain over it, whether
    it is told apart, and whether it is a structural equivalent.

    Told apart takes a significant difference (`p < alpha`) *and* one that matters: the finding's typical window
    error (`typical_gain`, the paired test's own measure) at least `min_gain` below the look-alike's, the margin a
    candidate must gain to count at all (a practical margin, as in equivalence testing: with hundreds of
    correlated windows a 1 % difference can be significant, and two causes that predict within 1 % of each other
    are not told apart by the data in any useful sense), and its pooled window error not larger (`gain_over`)."""
    o, alternatives = problem.selection, []
    for k in problem.look_alikes(best):
        if k in results:
            s_k, s_best = scores[results[k]["i"]], scores[results[best]["i"]]
            test = paired_test(s_k, s_best, yard.window_runs, yard.overlap)
            margin = window_gain(s_k, s_best)
            margin_typical = typical_gain(s_k, s_best)
            equivalent = k in problem.equivalents.get(best, [])
            resolved = _resolved(problem, (best, k), results)
            alternatives.append(
                {
                    "cause": problem.candidates[k].cause,
                    "where": problem.candidates[k].where(problem.system),
                    "gain": float(results[k]["gain_held_out"]),
                    "p_value": test.p_value,
                    "gain_over": margin,
                    "gain_over_typical": margin_typical,
                    "told_apart": bool(
                        test.p_value < o.alpha
                        and margin_typical >= o.min_gain
                        and margin > 0
                        and not equivalent
                        and resolved
                    ),
                    "equivalent": equivalent,
                    "resolved": resolved,
                }
            )
    return alternatives


def _resolved(problem, pair, results) -> bool:
    """Whether the diagnosis's rollouts (one step per sample) simulate both fits of a look-alike pair faithfully.

    A look-alike whose fitted size is below what its term resolves at that step (`shortest_resolved`: a dead time
    shorter than about a sample interval, whose Padé filter is stiffer than the step) is simulated wrong, so its
    poor held-out error is the rollout's, not evidence against it. A dead time and a lag of the same size differ
    only at frequencies near the sampling rate's, so where either fit is that short, the pair is not told apart.
    """
    times = [problem.neutral[k] + results[k]["delta"] for k in pair]
    shortest = max(problem.candidates[k].shortest_resolved(problem.dt) for k in pair)
    return not (shortest > 0 and min(times) < shortest)


def rank(results):
    """The key that ranks a round's admissible candidates: the gain on the held-out runs' windows.

    The test pools the cross-fitted training runs with the held-out runs (power), but the held-out runs,
    which no fit of the round has seen, choose among the candidates that pass: with two or three
    training runs each fold fits on one or two runs only, and its left-out run then rewards what
    mends a poorly determined fit as much as the cause (say, viscous friction where the held-out
    runs prefer Coulomb friction). Without cross-fitting this is the pooled gain."""
    return lambda k: results[k]["gain_held_out"]


def passes_but_significance(result) -> bool:
    """Every selection rule but significance holds for a refitted candidate's `result`."""
    return all(ok for name, ok in result["rules"].items() if name != "significance")


def choose(problem, results, admissible) -> int:
    """The candidate a round names: the admissible one with the largest held-out gain, or one of its look-alikes.

    Look-alikes (a dead time and a first-order lag at one input) are two models of one effect. Once one of
    them passes the test, the hypothesis that the effect is absent is rejected for the group (closed testing:
    Marcus, Peritz and Gabriel 1976), and which member describes it is a choice of model, made as for the
    other candidates by the held-out gain. So a refitted look-alike that passes every rule but significance
    and gains more on the held-out runs is named instead; the finding lists the other as a look-alike, told
    apart or not by the paired test between the two (`look_alike_tests`). Without this the member with the
    steadier window-to-window improvement is named whichever predicts better: a true dead time named as a lag.

    ??? cite

        R. Marcus, E. Peritz and K. R. Gabriel, "On closed testing procedures with special reference to
        ordered analysis of variance", Biometrika 63(3), 1976.
    """
    best = max(admissible, key=rank(results))
    group = [k for k in problem.look_alikes(best) if k in results and passes_but_significance(results[k])]
    return max([best, *group], key=rank(results))


def choose_shortlist(look_alikes_of, remaining, gains_scr, shortlist):
    """The best screened candidates and the look-alikes of the best (`look_alikes_of(k)`), `shortlist` in all."""
    order = [remaining[i] for i in np.argsort(-gains_scr)]
    short = order[: max(1, shortlist - 2)]
    for k in look_alikes_of(order[0]):
        if k in remaining and k not in short:
            short.append(k)
    short += [k for k in order if k not in short][: max(0, shortlist - len(short))]
    return short[:shortlist]


def on_physical_side(term, delta, partner, names, system) -> bool:
    """`term` at `delta` from neutral on its physical side (friction, inertia, delay: above neutral)
    and, with `partner = (i, alpha)`, the held nominal parameter `names[i]` plus `alpha * delta`
    within its consistency bound."""
    if term.sign != 0 and not delta * term.sign > 0:
        return False
    if partner is None:
        return True
    i, alpha = partner
    value = float(host_nominal_values(system, names)[i]) + alpha * float(delta)
    return violated_bound(names[i], value, identification_hooks(system).base_parameter_kinds().get(names[i])) is None


@dataclasses.dataclass(frozen=True)
class Refitted:
    """A round's refitted configurations: the shortlisted candidates `short` (configuration `i + 1` adds
    `short[i]` to the current model, configuration 0 is the current model), each configuration's parameters `p`,
    standard errors `std` and held-out window errors `errors` (configuration, window, step, state), and its window
    scores `scores` (the held-out windows, then the cross-fitted ones)."""

    short: list
    p: np.ndarray
    std: np.ndarray
    errors: np.ndarray
    scores: np.ndarray


def judge_round(problem, yard, current, remaining, fits: Refitted) -> dict:
    """Each shortlisted candidate's held-out test: paired block test, Benjamini-Hochberg over every remaining candidate
    (those not refitted count with p = 1), the smallest typical gain (`typical_gain`, see the module), agreement
    across runs, a physical sign of every coefficient of the joint refit: the new one's *and* those of the terms
    selected in earlier rounds, which the joint refit moves (a later term must not push an earlier friction below
    zero to fit), and no harm on the held-out runs.

    The last rule reads the held-out runs' pooled window error. Without cross-fitting it stops a term whose
    typical window gains while the windows of large error lose more; with cross-fitting also one the test's
    pooling carries: the test pools the cross-fitted training runs' windows with the held-out runs' for
    power, and on a few training runs their evidence can outweigh the held-out runs'. The held-out runs are the
    one judge no fit has seen, and the model the diagnosis returns is the one they measure: a candidate that
    makes their windows' error larger is not named, however much the cross-fitted folds liked it (seen on a real
    rig: a torque offset that the pooled windows favoured and the held-out runs did not; docs/devdocs/code_notes.md).

    **Arguments:**

    - `problem`: the diagnosis's `Problem`: `physical(k, delta)` (a coefficient's physical side),
      `static_level(k, p_row, std_row, selected, round_levels)` (`None` where the configuration has no static
      friction level, else whether every static level in it stands above the Coulomb level at its joint: rule
      `above_coulomb`; `round_levels` maps each refitted candidate to its new coefficient), `names` (the nominal
      parameters), `position_index`, and `selection` (`alpha`, `min_gain`).
    - `yard`: the `Yardstick`: `window_runs`, `overlap`, `steps`, and `n_val` (how many of the windows are the
      held-out runs'; the rest are cross-fitted).
    - `current`: the model reached: `selected` (the candidates selected in earlier rounds) and `score` (its window
      scores).
    - `remaining`: the candidates not yet selected (the Benjamini-Hochberg family).
    - `fits`: the round's `Refitted` configurations.
    """
    short, p_j, std_j, scores_j = fits.short, fits.p, fits.std, fits.scores
    score_cur, selected, n_nom, n_val = current.score, current.selected, len(problem.names), yard.n_val
    physical, rules_of = problem.physical, problem.selection
    tests = {k: paired_test(score_cur, scores_j[i], yard.window_runs, yard.overlap) for i, k in enumerate(short, 1)}
    p_values = [tests[k].p_value for k in short] + [1.0] * (len(remaining) - len(short))
    rejected = benjamini_hochberg(p_values, rules_of.alpha)
    results = {}
    round_levels = {k: p_j[i, -1] for i, k in enumerate(short, start=1)}  # each refitted candidate's new coefficient
    for i, k in enumerate(short, start=1):
        test = tests[k]
        delta = p_j[i, -1]
        gain_windows = window_gain(score_cur, scores_j[i])  # every held-out window, cross-fitted ones included
        gain_typical = typical_gain(score_cur, scores_j[i])  # the same windows, each alike: the test's measure
        gain_held_out = window_gain(score_cur[:n_val], scores_j[i][:n_val])  # the held-out runs' alone
        ok = physical(k, delta) and all(physical(s, p_j[i, n_nom + m]) for m, s in enumerate(selected))
        helped = sum(v > 0 for v in test.per_run.values())
        agree = helps_on_most_runs(test.per_run)
        rules = {
            "significance": bool(rejected[i - 1]),
            "min_gain": bool(gain_typical >= rules_of.min_gain),
            "sign": bool(ok),
            "agreement": bool(agree),  # each rule on its own: the report says which stopped a candidate
            "held_out": bool(gain_held_out > 0),
        }
        above = problem.static_level(k, p_j[i], std_j[i], selected, round_levels)
        if above is not None:
            rules["above_coulomb"] = bool(above)
        results[k] = dict(
            i=i,
            delta=delta,
            std=std_j[i, -1],
            gain_windows=gain_windows,
            gain_held_out=gain_held_out,
            gain_typical=gain_typical,
            p=test.p_value,
            test=test,
            rmse=rmse_curve(fits.errors[i], yard.steps, problem.position_index),
            physical=ok,
            runs_helped=helped,
            n_runs=len(test.per_run),
            n_tested=len(remaining),
            rules=rules,
            significant=all(rules.values()),
        )
    return results
