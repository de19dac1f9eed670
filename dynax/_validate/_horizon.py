r"""The reference horizon from the data: how far ahead the nominal model still predicts the training runs.

A simulation-error comparison is only informative while the simulated trajectory still follows the
measured one. Past that point (on a chaotic double pendulum within a second at large amplitude)
both models' errors saturate at the size of the motion itself and the comparison measures chaos,
not physics. The *predictability horizon* is the longest horizon at which the nominal model's
open-loop position error on the **training** runs is still at most `fraction` of the positions'
spread (their standard deviation over the training runs; for an angle, about its circular mean and
wrapped to within half a turn of it, see `position_spread`); held-out runs are never looked at, so
the choice cannot favour a candidate.

??? cite

    E. N. Lorenz, "Atmospheric predictability as revealed by naturally occurring analogues",
    Journal of the Atmospheric Sciences 26(4), 1969 (the predictability horizon: the lead time at
    which forecast errors reach a set fraction of the natural variability).
    L. A. Smith, "Disentangling uncertainty and error: on the predictability of nonlinear
    systems", in *Nonlinear Dynamics and Statistics*, 2001.
"""

import numpy as np

DEFAULT_FRACTION = 0.1


class Horizon:
    """The chosen reference horizon and how it was chosen (`to_json()` goes into `report.json`)."""

    def __init__(self, seconds: float, rule: str, fraction: float | None, horizons_s, relative_error):
        self.seconds, self.rule, self.fraction = float(seconds), rule, fraction
        self.horizons_s = [float(h) for h in horizons_s]
        self.relative_error = [float(e) if np.isfinite(e) else None for e in relative_error]

    def to_json(self) -> dict:
        return {
            "seconds": self.seconds,
            "rule": self.rule,
            "fraction": self.fraction,
            "candidate_horizons_s": self.horizons_s,
            "training_relative_error": self.relative_error,
        }


def position_spread(positions, angles) -> np.ndarray:
    r"""Each position's spread, the natural variability the predictability horizon is measured against.

    `positions (sample, position)`; `angles` one flag per position, true for an angle (a revolute
    joint). A linear position's spread is its standard deviation. An angle's is the standard deviation
    of the angle wrapped to within half a turn of its circular mean $\arg \sum_t e^{i q_t}$: the same
    number while the angle stays within half a turn of its mean, but bounded (by $\pi/\sqrt 3$, the
    standard deviation of a uniform angle) when the joint turns over. The standard deviation of the
    unwrapped angle grows with every turn a record makes, so it would set the horizon by how long the
    arm kept spinning rather than by how the configuration varies, and a long horizon over which a
    chaotic arm's windows drift apart leaves the held-out test without power.
    """
    q = np.asarray(positions, float)
    spread = q.std(axis=0)
    for k in np.flatnonzero(np.asarray(angles, bool)):
        centre = np.angle(np.mean(np.exp(1j * q[:, k])))
        spread[k] = np.std(np.mod(q[:, k] - centre + np.pi, 2 * np.pi) - np.pi)
    return np.maximum(spread, 1e-12)


def relative_position_error(errors, position_index, spread) -> np.ndarray:
    """Position RMSE over windows divided by the positions' spread, per step, RMS over positions.

    **Arguments:** `errors (window, step, state)` simulated minus measured; `position_index` the
    position states; `spread` their spread on the same runs (`position_spread`).
    """
    e = np.asarray(errors)[:, :, position_index] / np.asarray(spread)[None, None, :]
    finite = np.isfinite(e).all(axis=(1, 2))
    out = np.full(e.shape[1], np.inf)
    if finite.mean() >= 0.95:
        out = np.sqrt(np.mean(e[finite] ** 2, axis=(0, 2)))
    return out


def predictability_horizon(relative_error, dt: float, candidates_s, fraction: float = DEFAULT_FRACTION) -> Horizon:
    """The longest of `candidates_s` at which `relative_error` (per step, from `relative_position_error`)
    is still at most `fraction`; the shortest candidate if none is (the report says so)."""
    if not 0 < fraction < 1:
        raise ValueError(f"predictability_horizon: `fraction` must be in (0, 1), got {fraction}")
    candidates_s = np.sort(np.asarray(candidates_s, float))
    steps = np.minimum(np.maximum(np.round(candidates_s / dt).astype(int), 1), len(relative_error) - 1)
    at = np.asarray(relative_error)[steps]
    ok = np.flatnonzero(np.isfinite(at) & (at <= fraction))
    # The longest horizon before the error first exceeds the fraction (not one past a lucky dip).
    first_bad = np.flatnonzero(~(np.isfinite(at) & (at <= fraction)))
    last = (first_bad[0] - 1) if first_bad.size else len(at) - 1
    if last < 0 or not ok.size:
        rule = (
            f"the nominal model's training error exceeds {fraction:.0%} of the position spread already at "
            f"{candidates_s[0]:g} s: the shortest candidate horizon"
        )
        return Horizon(candidates_s[0], rule, fraction, candidates_s, at)
    rule = (
        f"predictability horizon: the longest horizon at which the nominal model's open-loop position RMSE on "
        f"the training runs is at most {fraction:.0%} of the positions' spread"
    )
    return Horizon(candidates_s[last], rule, fraction, candidates_s, at)
