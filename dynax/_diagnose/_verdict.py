r"""The verdict of `diagnose`: one enumeration, and the rule that chooses it from effect size and power.

A verdict is an answer to "is the nominal model adequate on these data, and if not, do the named
causes account for what it gets wrong?". Significance alone cannot answer it: with enough held-out
windows a negligible leftover is significant, and with too few a large effect is not. So every
verdict rests on an effect size, and `none` also on the test's power:

- `explained`: causes were named, and what their extended model leaves is small in practical terms:
  the residual probe finds no structure, or structure a further term could remove less than
  `MIN_PRACTICAL_GAIN` of (see `practical_structure`)
- `unexplained`: structure of practical size is left that the named causes (if any) do not account
  for, or the nominal model cannot simulate the held-out windows at all; with nothing named:
  structure of practical size that no candidate gaining `MIN_PRACTICAL_GAIN` would remove, or
  significant structure that only a candidate the physical rules stopped would (a hidden spring,
  fitted by a negative rotor inertia)
- `none`: no cause was named, no structure of practical size is left, no candidate's typical window
  gained `MIN_PRACTICAL_GAIN` (see below), and the test had the power (`POWER`) to detect that gain at
  its level: the nominal model is adequate
- `inconclusive`: no cause was named, and either nothing of practical size is seen but the test
  could not have seen it (its detectable gain exceeds `MIN_PRACTICAL_GAIN`, or the best candidate
  gains at least that much without being established), or structure of practical size is left that a
  candidate gaining at least `MIN_PRACTICAL_GAIN` would remove and that only the significance test
  stopped (`Power.undecided`). The report names the best candidate (gain, p) and the held-out length
  that would decide

The contract's three verdicts keep their meaning; `inconclusive` is the answer the old rules gave
as `none` where the data could not have shown an effect (one 8 s held-out run).

**The smallest gain that matters**, `MIN_PRACTICAL_GAIN` = 25 % of the held-out windows' mean squared
simulation error (13 % of its RMS), is a practical margin in the sense of equivalence testing (Wellek 2010;
Lakens 2017): a term that removes less than a quarter of the mean squared error changes no decision a user
makes with the model. Every part of the rule reads it in that one unit: the candidates' gains, the power, the
held-out length that would decide and the probe's $R^2$ (the report's headline `gain`, of the position RMSE
at the reference horizon, is another measure). It is not the selection's `min_gain` (5 %), the least gain a
named cause must show to be *named*; it is the least gain whose absence the verdict `none` must be able to
assert.

**Which gain is of practical size.** A candidate gains `MIN_PRACTICAL_GAIN` when its typical window does
(`typical_gain`: one minus the geometric mean of the test's windows' error ratios, the gain the paired
test's mean log ratio implies, in mean squared window error like the pooled gain). The pooled gain (one
minus the ratio of mean errors) weighs windows by their error, so where runs differ in error scale it
reads the largest run's scale: a Coulomb friction that gains 75 % and 32 % on two held-out runs gains 3 %
pooled beside a run whose windows score ten times theirs, and a term that mends a few windows of very large
error gains much pooled and nothing on the typical window. The typical gain answers the question the test
does. The other way round, a term that wins big on runs of small error and loses on one of large error has
a typical gain of practical size and a pooled loss: the selection's `held_out` and `agreement` rules keep
it from being named, and the verdict does not call the nominal model adequate (`none`) beside it, but
`inconclusive` (an effect of practical size seen, not established; `unexplained` where the residuals keep
significant structure), naming it with both gains. The best
candidate (`Power.best`) is the one with the largest typical gain. The power below speaks the same unit:
`none` asks for the power to see a 25 % gain in mean squared window error and for no candidate gaining as
much.

**Structure of practical size.** The residual probe reports $R^2 = 1 - \text{SSE}/\text{SS}_0$, the share of the
held-out one-step residuals' mean square its fitted regression removes: itself a gain in mean squared error.
A term that captured all of it would lower the residuals' mean square by $R^2$; this is of practical size
when it reaches `MIN_PRACTICAL_GAIN`, $R^2 \ge 0.25$ (`PRACTICAL_R2`). So a Coulomb friction found with a
96 % held-out gain whose extended model's probe still explains 14 % of what is left is `explained`; a nominal
model whose residuals the probe explains to 99 % is `unexplained`, whatever the candidates did.

**Power and the held-out length that would decide.** The paired test's standard error $s$ (on
the mean log ratio of window errors, with $\nu$ degrees of freedom) detects, with probability
`POWER` at level $a$, a shift of $\delta\,s$, where the noncentral t with noncentrality $\delta$ exceeds
$t_{1-a,\nu}$ with probability `POWER` (`dynax._diagnose._statistics.detectable_shift`; the shortcut
$\delta \approx t_{1-a,\nu} + t_{P,\nu}$ promises 80 % where 73 % is true at $\nu = 5$, $a = 0.001$). A gain $g$
in mean squared window error is a shift of $-\log(1-g)$ (`detectable_gain`). The standard error of a mean over
windows of a stationary record shrinks as $1/\sqrt{T}$ with the tested length $T$ (Cohen 1988, ch. 2), and
the degrees of freedom grow with it, $\nu(r) = r(\nu + c) - c$ for runs $r$ times longer ($c$ the test's
`df_offset`, one batch per run). The length at which `MIN_PRACTICAL_GAIN` would be detected is $T^\ast = rT$ where
$\delta_{\nu(r)}\, s/\sqrt r = -\log 0.75$ (`length_for_shift`); holding $\nu$ instead overstates it, by half
again on three runs of 40 windows at a strict level, where that length detected the gain 96 % of the time, not 80 %
(`experiments/power_length.py`: 79-85 % at the stated length across one to eight runs). The level $a$ is
the one the best candidate faced: `alpha` over the number of candidates tested (Benjamini-Hochberg's
threshold for the smallest p-value). The standard error and degrees of freedom are the refitted candidates' median
(their improvements vary from window to window as an effect's would), except where the best candidate itself shows
how an effect of the size in question varies: where it gains `MIN_PRACTICAL_GAIN`, or gains as much as the median's
test would detect and significance refused it, they are its own test's. Otherwise the statement could contradict
the test: on a quadrotor's battery sag whose typical window gains 50 % at p = 0.0024 (refused at 0.01 over 23
candidates), the median of candidates that change little claimed a detectable gain of 46 %; the candidate's own
test detects 71 %, and at its threshold no refused gain can lie below what it detects with 80 % power.

??? cite

    J. Cohen, *Statistical Power Analysis for the Behavioral Sciences*, 2nd ed., 1988, ch. 2.
    S. Wellek, *Testing Statistical Hypotheses of Equivalence and Noninferiority*, 2nd ed., 2010.
    D. Lakens, "Equivalence tests: a practical primer for t tests, correlations, and meta-analyses",
    Social Psychological and Personality Science 8(4), 2017.
"""

import dataclasses
import enum

import numpy as np

from ._residuals import Structure
from ._statistics import detectable_gain, length_for_shift

MIN_PRACTICAL_GAIN = 0.25  # the smallest gain in mean squared window error that matters (see the module)
POWER = 0.8  # the power at which `none` must have been able to see it
PRACTICAL_R2 = MIN_PRACTICAL_GAIN  # probe R^2: the share of the residuals' mean square a term capturing it removes


class Verdict(str, enum.Enum):  # noqa: UP042 -- StrEnum would change str()/format() of members in JSON and reports
    """The verdicts of `diagnose`, in one place (see the module for the rule that chooses them).

    A `str` enumeration: `Verdict.NONE == "none"`, and `report.json` writes the value.
    """

    EXPLAINED = "explained"
    UNEXPLAINED = "unexplained"
    NONE = "none"
    INCONCLUSIVE = "inconclusive"

    def __str__(self) -> str:
        return self.value

    @property
    def text(self) -> str:
        """A sentence for `report.md`."""
        return _TEXT[self]


_TEXT = {
    Verdict.EXPLAINED: "**explained**: the named causes (and any discovered terms) account for what the nominal model "
    "got wrong; what the extended model leaves has no structure of practical size.",
    Verdict.NONE: "**none**: the nominal model is adequate: no candidate improves it, its errors show no structure of "
    "practical size, and the test had the power to see a gain of 25 % had there been one.",
    Verdict.UNEXPLAINED: "**unexplained**: the errors have structure of practical size that the candidate causes "
    "do not (fully) explain. Partial findings, if any, are listed, but they are not an explanation.",
    Verdict.INCONCLUSIVE: "**inconclusive**: no cause passed the test, but the held-out data cannot decide: "
    "a candidate of practical size was seen and not established, or the test could not have seen one; the notes name "
    "the best candidate and the held-out length that would decide.",
}


def practical_structure(structure: Structure) -> bool:
    """Structure of practical size: significant, and a term capturing it would lower the residuals' mean square
    by at least `MIN_PRACTICAL_GAIN` (probe $R^2 \\ge$ `PRACTICAL_R2`)."""
    return bool(structure.significant and structure.r2 >= PRACTICAL_R2)


@dataclasses.dataclass(frozen=True)
class Power:
    """What the held-out test could see where no cause was named.

    Every gain here is in mean squared window error, the unit of the candidates' gains.

    **Fields:** `detectable_gain` (the typical gain detected with probability `POWER` at the best candidate's
    level, with window-to-window variation like the refitted candidates' median, or like the best candidate's own
    where it gains `MIN_PRACTICAL_GAIN` or as much as the median's test detects without being established: never
    a gain at or below one the same test refused; `None` without a refitted candidate); `best` (the refitted
    candidate with the largest typical gain: `cause`, `where`, `gain` (the held-out runs' pooled), `gain_typical`,
    `p_value`, `stopped_by`; `None` without one); `tested_s` (the record time the test's windows cover: held-out
    runs, and cross-fitted runs where they are pooled); `needed_s` (the tested time at which `MIN_PRACTICAL_GAIN`
    would be detected, same power, level and window-to-window variation as `detectable_gain`); `variation` (whose
    window-to-window variation that is), `level` (the threshold the best candidate's p-value faced) and `df` (the
    degrees of freedom the power is computed with); `observed_needed_s` (where the best candidate gains that much:
    the tested time at which its own observed mean improvement would be detected, same power and level: what would
    decide that candidate).
    """

    detectable_gain: float | None
    best: dict | None
    tested_s: float
    needed_s: float | None
    observed_needed_s: float | None = None
    variation: str = "the refitted candidates'"  # whose window-to-window variation: or "the best candidate's"
    level: float | None = None  # the threshold the best candidate's p-value faced
    df: float | None = None  # the degrees of freedom of the test the power is computed for

    @property
    def practical(self) -> bool:
        """The best candidate's typical gain is of practical size (see the module)."""
        return self.best is not None and self.best["gain_typical"] >= MIN_PRACTICAL_GAIN

    @property
    def undecided(self) -> bool:
        """The best candidate gains `MIN_PRACTICAL_GAIN` or more and only significance (and the smallest typical
        gain, which more data settle too) stopped it: more held-out data would decide."""
        return self.best is not None and self.practical and set(self.best["stopped_by"]) <= {"significance", "min_gain"}

    @property
    def enough(self) -> bool:
        """The test could have seen the smallest gain that matters."""
        return self.detectable_gain is not None and self.detectable_gain <= MIN_PRACTICAL_GAIN

    def to_json(self) -> dict:
        return {
            "detectable_gain": self.detectable_gain,
            "power": POWER,
            "min_practical_gain": MIN_PRACTICAL_GAIN,
            "best_candidate": self.best,
            "tested_s": self.tested_s,
            "needed_s": self.needed_s,
            "observed_needed_s": self.observed_needed_s,
            "variation": self.variation,
            "level": self.level,
            "df": self.df,
        }


def power_of(results: dict, labels: dict, alpha: float, tested_s: float) -> Power:
    """The `Power` of a round's test from its refitted candidates (`judge_round`'s `results`).

    The standard error is the median over the refitted candidates (their improvements vary from window
    to window as an effect's would), or the best candidate's own test's where it gains `MIN_PRACTICAL_GAIN` or as
    much as the median's test detects without being established (see the module); the level is `alpha` over the
    candidates tested (the threshold the best candidate faced). `labels` maps a candidate index to `(cause, where)`.
    """
    if not results:
        return Power(None, None, tested_s, None)
    first = next(iter(results.values()))
    level = alpha / max(int(first["n_tested"]), 1)
    # A candidate whose windows all score as the nominal's (refitted to its neutral value: a delay or lag of 0)
    # has no variance to test, and its test says so (an infinite standard error, no degrees of freedom): it says
    # nothing about how the windows vary, so the median is over the candidates whose test is defined.
    defined = [r["test"] for r in results.values() if np.isfinite(r["test"].std_error) and r["test"].df > 0]
    reference = defined[0] if defined else first["test"]
    df, offset = max(float(reference.df), 1.0), float(reference.df_offset)
    se = float(np.median([t.std_error for t in defined])) if defined else np.inf
    detectable = detectable_gain(se, df, level, POWER) if np.isfinite(se) else 1.0
    k = max(results, key=lambda k: results[k]["gain_typical"])
    practical = results[k]["gain_typical"] >= MIN_PRACTICAL_GAIN
    # An effect as large as the best candidate's varies from window to window as the one seen does: where it gains
    # MIN_PRACTICAL_GAIN or more, or as much as the median's test would detect while significance refused it, the
    # power is its own test's (standard error and degrees of freedom), the test it was refused by. The median's
    # would claim a detectable gain smaller than one the test just refused (a quadrotor's battery sag: 46 % stated,
    # 50 % on the typical window refused).
    own = results[k]["test"]
    refused = not results[k]["rules"].get("significance", True)
    if (
        np.isfinite(own.std_error)
        and own.std_error > 0
        and own.df > 0
        and (practical or (refused and results[k]["gain_typical"] >= detectable))
    ):
        se, df, offset = float(own.std_error), max(float(own.df), 1.0), float(own.df_offset)
        detectable = detectable_gain(se, df, level, POWER)
        variation = "the best candidate's"
    else:
        variation = "the refitted candidates'"
    # The length that would decide: with that same window-to-window variation, and the degrees of freedom the
    # longer runs would give (`length_for_shift`).
    needed = observed = None
    if np.isfinite(se) and se > 0:
        target = -np.log1p(-MIN_PRACTICAL_GAIN)  # a gain g is a shift -log(1 - g)
        needed = float(tested_s * length_for_shift(target, se, df, offset, level, POWER))
        mean = float(results[k]["test"].mean)
        if practical and mean > 0:  # its own observed effect, detected with POWER
            observed = float(tested_s * length_for_shift(mean, se, df, offset, level, POWER))
    cause, where = labels[k]
    best = {
        "cause": cause,
        "where": where,
        "gain": float(results[k]["gain_held_out"]),
        "gain_typical": float(results[k]["gain_typical"]),
        "p_value": float(results[k]["p"]),
        "stopped_by": [name for name, ok in results[k]["rules"].items() if not ok],
    }
    return Power(float(detectable), best, float(tested_s), needed, observed, variation, level, df)


def decide(named: bool, left: Structure, nominal_diverged: bool, power: Power) -> Verdict:
    """The verdict (see the module's table).

    **Arguments:** `named` whether causes were named; `left` the residual probe's `Structure` of the model
    the verdict is about (extended where causes were named, else nominal); `nominal_diverged` whether the
    nominal model's held-out windows diverged at the reference horizon (no simulation to compare);
    `power` the test's `Power` where nothing was named.
    """
    if named:
        return Verdict.UNEXPLAINED if practical_structure(left) else Verdict.EXPLAINED
    if nominal_diverged:
        return Verdict.UNEXPLAINED
    if power.best is None and power.detectable_gain is None:
        # No candidate to test: the probe is the only judge.
        return Verdict.UNEXPLAINED if practical_structure(left) else Verdict.NONE
    if power.practical:
        if power.undecided:
            return Verdict.INCONCLUSIVE  # a candidate of practical size that only the significance test stopped
        # An extra degree of freedom of practical size helps, but no physical candidate: with structure in the
        # residuals that is structure the vocabulary does not explain (a hidden spring, fitted by a negative
        # rotor inertia); without, an effect of practical size seen and not established.
        return Verdict.UNEXPLAINED if left.significant else Verdict.INCONCLUSIVE
    if practical_structure(left):
        return Verdict.UNEXPLAINED
    return Verdict.NONE if power.enough else Verdict.INCONCLUSIVE


def inconclusive_note(power: Power, horizon_s: float, runs: str) -> str:
    """What an `inconclusive` verdict rests on and what would decide it."""
    parts = []
    if power.best is not None:
        b = power.best
        parts.append(
            f"The best candidate, {b['cause']}@{b['where']}, gains {b['gain']:.0%} on the held-out runs at "
            f"{horizon_s:g} s ({b['gain_typical']:.0%} on the typical window; p = {b['p_value']:.2g})"
            + (f", stopped by {', '.join(b['stopped_by'])}" if b["stopped_by"] else "")
            + "."
        )
    if power.detectable_gain is not None:
        bar = "" if power.level is None else f" (p <= {power.level:.2g}"
        bar += "" if power.df is None or not bar else f", {power.df:.3g} degrees of freedom"
        parts.append(
            f"With these {runs} ({power.tested_s:.3g} s of windows) the test would detect a gain of about "
            f"{power.detectable_gain:.0%} in mean squared window error with {POWER:.0%} power at the level the best "
            f"candidate faced{bar + ')' if bar else ''}, with window-to-window variation like {power.variation}"
            + (f", more than the {MIN_PRACTICAL_GAIN:.0%} that matters." if not power.enough else ".")
        )
    if power.needed_s is not None and power.needed_s > power.tested_s:
        like = "its" if power.undecided else power.variation
        parts.append(
            f"With window-to-window variation like {like}, about {power.needed_s:.3g} s of held-out record "
            f"({power.needed_s / power.tested_s:.3g} times as much) would detect a {MIN_PRACTICAL_GAIN:.0%} "
            f"gain at the test's level with {POWER:.0%} power; the verdict is left open until then."
        )
    elif power.best is not None:
        parts.append("More held-out runs, or runs that excite it differently, would decide.")
    if power.undecided and power.observed_needed_s is not None:
        parts.append(
            f"Its own improvement, as large as observed, would be detected with about "
            f"{power.observed_needed_s:.3g} s of such record."
        )
    return "Inconclusive: " + " ".join(parts)
