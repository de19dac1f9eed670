"""Verdicts from effect size and power (`dynax.Verdict`, the rule in `dynax._diagnose._verdict`), and a quick
subset of the calibration battery (`tests/hidden_cases.py`: records made by scipy's DOP853 with the effects
written out apart from dynax's terms; `experiments/calibration_battery.py` runs all of them).

The rule's tests are arithmetic; the end-to-end cases are heavy (in `make test`, not `make quick`), and the
known-mode impossible nominal is slow. A helicopter control and a helicopter drag the record cannot show (the
battery's quadratic drag on `w`: fitted right, named by no other cause) are among them."""

import numpy as np
import pytest
import scipy.stats

import dynax
from dynax import Verdict
from dynax.internal import decide_verdict as decide
from dynax.internal import (
    log_ratio_differences,
    MIN_PRACTICAL_GAIN,
    paired_block_test,
    PairedTest,
    power_of,
    PRACTICAL_R2,
    Structure,
)
from tests.hidden_cases import Case, CASES, diagnose_case, outcome, records


def _structure(significant, r2, p=1e-3):
    return Structure(significant=significant, r2=r2, p_value=p, top_features=(), worst_times=(), by_state={})


def _results(gain, p, std_error, df=40.0, n_tested=10, typical=None):
    """One refitted candidate as `judge_round` reports it: `gain` the held-out runs' pooled, `typical` the typical
    window's (by default the same: an effect alike on every window). The test is batch means' on one run:
    `df + 1` batches, one degree of freedom lost to the mean whatever the length (`df_offset`)."""
    typical = gain if typical is None else typical
    mean = -np.log(1.0 - typical)  # the mean log ratio of window errors
    test = PairedTest(mean, std_error, df, p, 5, {0: mean}, "nbm", 1.0)
    rules = {"significance": p < 0.001, "min_gain": True, "sign": True, "agreement": True, "held_out": gain > 0}
    return {
        3: {"gain_held_out": gain, "gain_typical": typical, "p": p, "test": test, "n_tested": n_tested, "rules": rules}
    }


def _gains(scales, factors, n=60, seed=3):
    """Window errors of runs of error scale `scales` (`ref`), and a candidate's that multiplies them by `factors`
    (`new`, 5 % noise)."""
    rng = np.random.default_rng(seed)
    runs = np.repeat(np.arange(len(scales)), n)
    ref = rng.uniform(1.0, 2.0, runs.size) * np.asarray(scales, float)[runs]
    new = ref * np.asarray(factors, float)[runs] * rng.uniform(0.95, 1.05, runs.size)
    return ref, new


def test_the_practical_size_is_the_typical_windows_not_the_run_of_largest_error():
    """Held-out runs of very different error scale. Two whose window error the best candidate cuts by 60 % and 40 %
    and a third whose windows score thirty times theirs and which it helps by 1 %: a few per cent pooled, nearly
    40 % on the typical window. Not established (p = 0.02 over ten candidates), it is an effect of practical size
    seen and not decided, `inconclusive`, not `none`. The other way round, a candidate whose pooled gain comes from
    four windows of a stretch the nominal model loses while every other window gets 12 % worse is no effect of
    practical size: with the power to see 25 %, `none`. And a candidate that cuts two runs' error by 70 % and makes
    the run of thirty times their error 15 % worse (its pooled held-out error grows, the `held_out` rule stops it)
    leaves the nominal model not shown adequate: `inconclusive`."""
    labels, flat = {3: ("coulomb_friction", "q2")}, _structure(False, 0.0)

    def typical(ref, new):  # one minus the geometric mean of the windows' error ratios
        return 1.0 - float(np.exp(-np.mean(np.log(ref / new))))

    def pooled(ref, new):
        return 1.0 - float(np.sum(new) / np.sum(ref))

    ref, new = _gains((1.0, 1.0, 30.0), (0.4, 0.6, 0.99))
    assert pooled(ref, new) < 0.05 and typical(ref, new) > 0.3
    scaled = power_of(_results(pooled(ref, new), 0.02, 0.05, typical=typical(ref, new)), labels, 0.01, 20.0)
    assert scaled.enough and decide(False, flat, False, scaled) == Verdict.INCONCLUSIVE
    assert scaled.undecided and scaled.best["gain"] == pytest.approx(pooled(ref, new))

    ref, new = _gains((1.0, 1.0), (1.12, 1.12))
    ref[20:24] *= 100.0
    new[20:24] = ref[20:24] * 0.1
    assert pooled(ref, new) > 0.5 and typical(ref, new) < 0
    stretch = power_of(_results(pooled(ref, new), 0.4, 0.05, typical=typical(ref, new)), labels, 0.01, 20.0)
    assert stretch.enough and decide(False, flat, False, stretch) == Verdict.NONE

    ref, new = _gains((1.0, 1.0, 30.0), (0.3, 0.3, 1.15))
    assert pooled(ref, new) < 0 and typical(ref, new) > 0.25
    harmful = power_of(_results(pooled(ref, new), 0.3, 0.05, typical=typical(ref, new)), labels, 0.01, 20.0)
    assert decide(False, flat, False, harmful) == Verdict.INCONCLUSIVE
    assert harmful.best["stopped_by"] == ["significance", "held_out"] and not harmful.undecided


def test_verdict_is_one_string_enumeration_with_the_contracts_names():
    assert [v.value for v in Verdict] == ["explained", "unexplained", "none", "inconclusive"]
    assert Verdict.NONE == "none" and str(Verdict.INCONCLUSIVE) == "inconclusive"


def test_a_large_effect_with_a_small_significant_leftover_is_explained():
    """A cause found with a 96 % gain whose extended model's probe still explains 14 % (p = 0.0014): a further
    term could lower the residuals by 7 % at most, not of practical size."""
    left = _structure(True, 0.14, p=0.0014)
    assert decide(True, left, False, power_of({}, {}, 0.01, 10.0)) == Verdict.EXPLAINED
    assert (
        decide(True, _structure(True, PRACTICAL_R2 + 0.01), False, power_of({}, {}, 0.01, 10.0)) == Verdict.UNEXPLAINED
    )


def test_none_needs_the_power_to_see_the_smallest_gain_that_matters():
    labels = {3: ("coulomb_friction", "q2")}
    # A precise test (standard error 0.05 of the mean log ratio) that saw a 3 % gain: the model is adequate.
    precise = power_of(_results(0.03, 0.4, 0.05), labels, 0.01, 20.0)
    assert precise.enough and precise.detectable_gain < MIN_PRACTICAL_GAIN
    assert decide(False, _structure(False, 0.0), False, precise) == Verdict.NONE
    # The same gain seen by a test four times less precise: it could not have seen 25 %.
    vague = power_of(_results(0.03, 0.4, 0.2), labels, 0.01, 5.0)
    assert not vague.enough
    assert decide(False, _structure(False, 0.0), False, vague) == Verdict.INCONCLUSIVE
    # The held-out length that would decide: the standard error shrinks as 1/sqrt(length), the batches grow with it.
    assert vague.needed_s > 5.0
    r = vague.needed_s / 5.0
    at_needed = power_of(_results(0.03, 0.4, 0.2 / np.sqrt(r), df=r * 41.0 - 1.0), labels, 0.01, vague.needed_s)
    assert at_needed.detectable_gain == pytest.approx(MIN_PRACTICAL_GAIN, abs=0.01)
    # A candidate that gains 59 % without being established is never `none`, however precise the test.
    seen = power_of(_results(0.59, 0.02, 0.05), labels, 0.01, 20.0)
    assert decide(False, _structure(False, 0.0), False, seen) == Verdict.INCONCLUSIVE
    assert seen.best["cause"] == "coulomb_friction" and seen.best["gain"] == pytest.approx(0.59)


def test_the_power_speaks_the_unit_of_the_gains():
    """Held-out window log ratios (60 windows of one run, made here) whose best candidate gains 3 % on the typical
    window, and whose standard error lets the test see a gain of about 30 % in mean squared window error: a
    25 % gain (the unit of every reported gain) could have gone unseen, so the answer is `inconclusive`, not
    `none`. Read as an RMS gain the same power is about 17 %, under 25 %: the reading that let `none` through."""
    rng = np.random.default_rng(2)
    ref = rng.lognormal(0.0, 0.5, 60)
    new = ref * np.exp(rng.normal(-0.03, 0.85, 60))
    d = log_ratio_differences(ref, new)
    test = paired_block_test(d, np.zeros(60, int), 1)
    results = _results(0.03, test.p_value, test.std_error, df=test.df, typical=1 - float(np.exp(-np.mean(d))))
    results[3]["test"] = test
    power = power_of(results, {3: ("coulomb_friction", "q2")}, 0.01, 10.0)
    assert power.best["gain_typical"] < MIN_PRACTICAL_GAIN and not power.practical
    # the gain the test sees with 80 % power, in mean squared error, from the shift -log(1 - g) of the mean log ratio
    assert MIN_PRACTICAL_GAIN < power.detectable_gain < 1 - (1 - MIN_PRACTICAL_GAIN) ** 2
    assert 1 - np.sqrt(1 - power.detectable_gain) < MIN_PRACTICAL_GAIN  # what the RMS reading would have said
    assert not power.enough
    assert decide(False, _structure(False, 0.0), False, power) == Verdict.INCONCLUSIVE
    # With the power to see 25 % it is `none`: the same windows four times as many times over.
    more = paired_block_test(np.tile(d, 4), np.zeros(240, int), 1)
    results[3]["test"] = more
    enough = power_of(results, {3: ("coulomb_friction", "q2")}, 0.01, 40.0)
    assert enough.enough and decide(False, _structure(False, 0.0), False, enough) == Verdict.NONE


def test_the_length_that_would_decide_gives_the_power_it_promises():
    """`needed_s` checked by simulating the test it speaks of, not by its formula: windows at the needed length
    whose log ratios shift by a 25 % gain in mean squared error, tested one-sided at the best candidate's level
    (0.01 over 10 candidates) on batch means of the length the test had (6 batches, 5 degrees of freedom, in the
    tested 5 s; as many more as the record is longer), are detected in 80 % of 20,000 draws. Holding the degrees
    of freedom at 5 stated 3.1 times that length; half the length does not suffice."""
    se, df, tested_s = 0.2, 5.0, 5.0
    power = power_of(_results(0.03, 0.4, se, df=df), {3: ("coulomb_friction", "q2")}, 0.01, tested_s)
    assert power.needed_s is not None and power.needed_s > tested_s
    level, shift = 0.01 / 10, -np.log(1 - MIN_PRACTICAL_GAIN)
    rng = np.random.default_rng(7)

    def detected(length_s):
        # batches of the tested length, as many as fit; the overall mean's standard error shrinks as
        # 1/sqrt(length), and each of the equal batch means has sqrt(batches) times it
        batches = int(round((df + 1) * length_s / tested_s))
        sd = se * np.sqrt(tested_s / length_s) * np.sqrt(batches)
        means = rng.normal(shift, sd, (20_000, batches))
        t = means.mean(axis=1) / (means.std(axis=1, ddof=1) / np.sqrt(batches))
        return float(np.mean(t > scipy.stats.t.isf(level, batches - 1)))

    assert detected(power.needed_s) == pytest.approx(0.8, abs=0.015)  # the power `none` asks for
    assert detected(power.needed_s / 2) < 0.5


def test_the_power_leaves_out_candidates_whose_test_is_undefined():
    """A candidate refitted to its neutral value (a motor delay of 0 on a quadrotor flight) scores every window as
    the nominal does: its paired test has no variance (infinite standard error, no degrees of freedom, p = 1). It
    says nothing about how the windows vary, so the power is the defined candidates' alone; with it in the median,
    half such candidates made every test powerless (detectable gain 100 %) and an effect-free control
    `inconclusive`. With no defined test at all there is no power."""
    flat = _structure(False, 0.0)
    labels = {i: ("input_lag", f"m{i + 1}") for i in range(4)}
    defined = {**_results(0.01, 0.8, 0.011, df=14.0), 4: _results(0.0, 0.9, 8e-5, df=14.0)[3]}
    undefined = _results(0.0, 1.0, np.inf, df=0.0)[3]
    alone = power_of({3: defined[3], 4: defined[4]}, labels | {4: ("body_bias", "w")}, 0.01, 19.2)
    both = power_of(
        {0: undefined, 1: undefined, 3: defined[3], 4: defined[4]}, labels | {4: ("body_bias", "w")}, 0.01, 19.2
    )
    assert both.detectable_gain == pytest.approx(alone.detectable_gain) and both.detectable_gain < MIN_PRACTICAL_GAIN
    assert decide(False, flat, False, both) == Verdict.NONE
    nothing = power_of({0: undefined, 1: undefined}, labels, 0.01, 19.2)
    assert nothing.detectable_gain == 1.0 and decide(False, flat, False, nothing) == Verdict.INCONCLUSIVE


def test_structure_of_practical_size_or_a_diverging_nominal_is_unexplained():
    precise = power_of(_results(0.03, 0.4, 0.05), {3: ("input_delay", "tau2")}, 0.01, 20.0)
    assert decide(False, _structure(True, 0.995), False, precise) == Verdict.UNEXPLAINED
    assert decide(False, _structure(False, 0.0), True, precise) == Verdict.UNEXPLAINED
    assert decide(False, _structure(True, 0.2), False, precise) == Verdict.NONE  # significant, not of practical size


def test_structure_a_candidate_would_remove_but_significance_alone_stopped_is_inconclusive():
    """A rotor inertia that gains 96 % on the held-out run at p = 0.0019, short of Benjamini-Hochberg's 0.001 over
    ten candidates, with the nominal's probe at R2 = 0.51: the candidates do explain it, the data do not yet
    decide it; the length that would is from the candidate's own window-to-window variation."""
    labels = {3: ("rotor_inertia", "q2")}
    undecided = power_of(_results(0.96, 0.0019, 0.05), labels, 0.01, 10.0)
    assert undecided.undecided and undecided.needed_s is not None
    # Its own 96 % improvement needs far less record to be established than a 25 % one would.
    assert undecided.observed_needed_s is not None and undecided.observed_needed_s < undecided.needed_s
    assert decide(False, _structure(True, 0.51), False, undecided) == Verdict.INCONCLUSIVE
    results = _results(0.96, 0.0019, 0.05)
    results[3]["rules"]["sign"] = False  # a negative inertia is no explanation
    assert decide(False, _structure(True, 0.51), False, power_of(results, labels, 0.01, 10.0)) == Verdict.UNEXPLAINED
    # A hidden joint spring: the probe's structure is significant but small (R2 = 0.22), and only a negative rotor
    # inertia helps (39 %): structure of practical size in simulation that no physical candidate explains.
    spring = _results(0.39, 0.09, 0.05)
    spring[3]["rules"]["sign"] = False
    assert decide(False, _structure(True, 0.22), False, power_of(spring, labels, 0.01, 10.0)) == Verdict.UNEXPLAINED


# --- end to end, on records dynax did not make --------------------------------------------------------


@pytest.mark.heavy  # an end-to-end diagnosis: in `make test`, not `make quick`
def test_effect_free_control_claims_no_cause():
    case = Case("control", "acrobot", None, None, 0.0, "none", "refit", 300)
    j = diagnose_case(case).to_json()
    o = outcome(case, j)
    assert not o["false_claim"], (j["verdict"], j["findings"], j["structure"])
    assert j["verdict"] in ("none", "inconclusive")
    assert not o["none_with_gain"], j["candidates"][:3]


@pytest.mark.heavy  # an end-to-end diagnosis: in `make test`, not `make quick`
def test_one_dead_time_on_both_drives_is_named_once_at_motors():
    # Both torques of a double pendulum 20 ms late (DOP853, the recorded inputs shifted in time): one latency of
    # the rig's command chain. Per input it was named as two lags, one at each torque.
    case = next(c for c in CASES if c.name == "double_pendulum-motor_delay@motors-0.02-dead_time")
    j = diagnose_case(case).to_json()
    assert j["verdict"] == "explained", (j["verdict"], j["findings"])
    assert [(f["cause"], f["where"]) for f in j["findings"]] == [("motor_delay", "motors")], j["findings"]
    assert abs(j["findings"][0]["coefficient"] - 0.02) < 0.002


@pytest.mark.slow  # about 3 min; the suite's helicopter control: test_helicopter_candidates.py
def test_a_helicopter_control_claims_no_cause():
    case = next(c for c in CASES if c.name == "helicopter-control-known-9")
    j = diagnose_case(case).to_json()
    o = outcome(case, j)
    assert j["verdict"] == "none" and not o["false_claim"], (j["verdict"], j["findings"], j["test"].get("power"))


@pytest.mark.heavy
def test_a_hover_drag_is_fitted_right_where_the_record_cannot_show_it():
    """The battery's quadratic drag of 0.5 on the helicopter's `w` (body frame, air-relative, written out in numpy):
    the record of a hover at under 1 m/s cannot show it (the truth itself, scored and tested as the diagnosis scores
    and tests a candidate, passes the test at no horizon where it gains the 5 % that counts:
    `experiments/heli_drag_horizons.py`). The candidate must still be the right one at the right size, and no other
    cause may be named in its place."""
    case = next(c for c in CASES if c.name == "helicopter-quadratic_drag@w-0.5-body_frame")
    j = diagnose_case(case).to_json()
    o = outcome(case, j)
    assert o["best_candidate"] == "quadratic_drag@w", j["candidates"][:3]
    assert o["best_coefficient"] == pytest.approx(0.5, rel=0.05)
    assert not o["extra"], j["findings"]
    if j["findings"]:  # the day the test has the power to name it, it must be named right
        assert o["named_first"] and j["verdict"] == "explained", (j["findings"], j["verdict"])
    else:
        assert j["verdict"] == "none", (j["verdict"], j["test"].get("power"))


@pytest.mark.heavy
def test_a_short_held_out_record_is_inconclusive_not_none():
    """A Coulomb friction near the threshold, judged on 1.5 s of held-out record: the test cannot see a 25 % gain
    there, so the answer is `inconclusive` with the best candidate and the length that would decide."""
    case = Case("short", "acrobot", "coulomb_friction", "q2", 0.05, "tanh", "refit", 104, near=True)
    train, held_out = records(case)
    short = held_out.slice(0, 151)
    j = diagnose_case(case, (train, short)).to_json()
    assert j["verdict"] != "none", (j["verdict"], j["test"])
    if j["verdict"] == "inconclusive":
        power = j["test"]["power"]
        assert power["best_candidate"] is not None
        assert any(n.startswith("Inconclusive:") for n in j["notes"]), j["notes"]
        assert not (
            power["detectable_gain"] <= MIN_PRACTICAL_GAIN and power["best_candidate"]["gain"] < MIN_PRACTICAL_GAIN
        )
    else:  # found anyway: then it must be the right cause
        assert j["findings"][0]["cause"] == "coulomb_friction", j["findings"]


@pytest.mark.heavy  # an end-to-end diagnosis: in `make test`, not `make quick`
def test_a_cause_found_with_a_leftover_probe_structure_is_explained():
    """A Stribeck friction (static level 1.5 times the Coulomb level) is named as Coulomb friction; the curve's
    hump stays in the residuals as small structure, which must not make the verdict `unexplained`."""
    case = Case("stribeck", "acrobot", "coulomb_friction", "q1", 0.3, "stribeck", "refit", 102)
    j = diagnose_case(case).to_json()
    assert (j["findings"][0]["cause"], j["findings"][0]["where"]) == ("coulomb_friction", "q1"), j["findings"]
    assert j["verdict"] == "explained", (j["verdict"], j["structure"]["extended"])
    assert j["gain"] > 0.5


@pytest.mark.slow  # about 40 s
def test_known_mode_with_an_impossible_nominal_is_not_none():
    """`--mode known` with theta1 and theta4 of the wrong sign: the model cannot simulate the held-out record, and
    the answer must say so, never `none` (model adequate)."""
    case = Case("bad-nominal", "acrobot", None, None, 0.0, "none", "known", 301)
    train, held_out = records(case)
    try:
        nominal = dynax.Acrobot.from_base_parameters(
            {
                "theta1": -1.333,
                "theta2": 1.33,
                "theta3": 1.0,
                "theta4": -14.715,
                "theta5": 9.81,
                "theta6": 0.1,
                "theta7": 0.1,
            }
        )
    except ValueError as refused:  # a located refusal of the impossible parameters is a right answer too
        assert "theta1" in str(refused) or "theta4" in str(refused), refused
        return
    selection = dynax.Selection(max_terms=2)
    j = dynax.diagnose(nominal, train, held_out, mode=dynax.Known(), selection=selection, progress=False).to_json()
    assert j["verdict"] != "none", (j["verdict"], j["structure"]["nominal"], j["nominal"]["sim_error"])


@pytest.mark.slow  # about 3 min; the suite hides delay and lag in test_hidden_effects.py
def test_a_dead_time_shorter_than_a_sample_is_named_and_told_apart_from_a_lag():
    # A 5 ms dead time at 100 Hz (DOP853, the input shifted in time). The windowed rollouts shift the recorded input by
    # the fitted delay, so the dead time is simulated as one at half a sample, and the record tells it from a 5 ms lag
    # (its truth gains 95 % over the closest lag on the held-out windows: `tests.hidden_cases.look_alike_gain`).
    case = Case("short-delay", "linear_axis", "input_delay", "force", 0.005, "dead time", "refit", 136, near=True)
    j = diagnose_case(case).to_json()
    first = j["findings"][0]
    assert (first["cause"], j["verdict"]) == ("input_delay", "explained"), (j["findings"], j["verdict"])
    assert abs(first["coefficient"] - 0.005) < 0.0005
    other = [a for a in first["look_alikes"] if a["cause"] == "input_lag"]
    assert other and other[0]["told_apart"] and other[0]["resolved"]
