"""The output-error screening (`dynax.internal.rollout_screen`): the first Gauss-Newton step of each candidate's
simulation-error refit, judged on held-out windows; and how it adds to the equation-error shortlist
(`dynax.internal.with_rollout_evidence`).

The record is made outside dynax's model code (`tests.hidden_cases`: scipy DOP853, the effect written out in numpy,
measurement noise), so the screening's ranking and gain are checked against data no dynax model produced, and its
gain against the converged refit of the same candidate."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import default_candidates, DoublePendulum, Parameters, Refit
from dynax.internal import (
    candidate_family,
    fit_configurations,
    make_windows,
    names_to_refit,
    rankable,
    rollout_screen,
    window_errors,
    with_rollout_evidence,
)
from tests import hidden_cases


def _case(name):
    return next(c for c in hidden_cases.CASES if c.name == name)


@pytest.mark.heavy
def test_the_first_gauss_newton_step_ranks_the_hidden_effect_first_and_predicts_its_refit():
    """A viscous friction of 0.25 at the shoulder, hidden in a DOP853 record with encoder noise: of every candidate
    without internal states, the screening ranks it first, and its held-out gain is within a few percent of what
    the converged simulation-error refit of the same configuration gains on the same held-out windows."""
    case = _case("double_pendulum-viscous_friction@q1-0.25-viscous")
    train, held_out = hidden_cases.records(case)
    system = DoublePendulum()
    wanted = ("viscous_friction@q1", "viscous_friction@q2", "coulomb_friction@q1", "coulomb_friction@q2")
    candidates = tuple(
        t for t in default_candidates(system, [train]) if t.label(system) in wanted + ("input_lag@tau1",)
    )
    family, _, _ = candidate_family(system, candidates, names_to_refit(system, Refit()), [train])
    n_fit = 25  # 0.25 s windows, as a diagnosis of this record fits
    train_w, held_w = make_windows([train], n_fit, n_fit), make_windows([held_out], n_fit, n_fit)
    max_terms = 1
    slots = -np.ones(max_terms, int)
    p0 = np.concatenate([np.asarray(Parameters.of(system).vector(system)), np.zeros(max_terms + 1)])
    ranked = rankable(family, range(len(candidates)))
    labels = [candidates[k].label(system) for k in ranked]
    assert "viscous_friction@q1" in labels and "input_lag@tau1" not in labels  # a lag has no first-order direction
    gains = rollout_screen(family, train_w, held_w, slots, p0, ranked)
    assert labels[int(np.nanargmax(gains))] == "viscous_friction@q1", dict(zip(labels, np.round(gains, 3)))

    # One training window whose rollout diverges (a start at an absurd speed) counts for nothing: every candidate
    # keeps its rank and its gain, rather than the whole screening going unranked.
    xs = np.asarray(train_w.xs).copy()
    xs[3, 0, 2:] = 1e10  # rad/s
    diverged = eqx.tree_at(lambda w: w.xs, train_w, jnp.asarray(xs))
    with_diverged = rollout_screen(family, diverged, held_w, slots, p0, ranked)
    assert np.all(np.isfinite(with_diverged)), dict(zip(labels, with_diverged))
    np.testing.assert_allclose(with_diverged, gains, atol=0.02)

    # The converged refit of the nominal model alone and with the shoulder's viscous friction.
    k = ranked[labels.index("viscous_friction@q1")]
    new = jnp.asarray([-1, k])
    p_init = jnp.asarray(np.tile(p0, (2, 1)))
    p, _, _, _ = fit_configurations(
        family, train_w, jnp.asarray(np.tile(slots, (2, 1))), new, p_init, jnp.ones(len(p0))
    )
    sse = []
    for i in range(2):
        model = family.model_for(jnp.asarray(slots), new[i], p[i])
        e = np.asarray(window_errors(model, held_w))[:, 1:] / np.asarray(family.state_scale)
        sse.append(float(np.nansum(e**2)))
    refit_gain = 1 - sse[1] / sse[0]
    assert refit_gain > 0.5
    assert gains[labels.index("viscous_friction@q1")] == pytest.approx(refit_gain, abs=0.05)


def test_an_outsider_the_refit_would_gain_from_joins_the_shortlist_in_place_of_the_weakest():
    # Candidates 0..5; the equation-error screening shortlisted 0, 1, 2 (0 first; 1 is its look-alike); 3 is a lag
    # this screening cannot rank; 4 gains most by its first Gauss-Newton step, 5 less than the floor.
    remaining = [0, 1, 2, 3, 4, 5]
    one_step = np.array([0.5, 0.1, 0.3, 0.2, 0.01, 0.0])
    short = [0, 1, 2, 3]
    look_alikes = lambda k: [1] if k == 0 else []  # noqa: E731
    ranked = [0, 1, 2, 4, 5]
    rollout = np.array([0.6, 0.0, 0.05, 0.4, 0.02])
    new, promoted = with_rollout_evidence(look_alikes, remaining, one_step, short, ranked, rollout, 2, 0.05)
    # 4 replaces 2 (the weakest rankable that is neither the best nor its look-alike); 5 is under the floor.
    assert promoted == [4] and new == [0, 1, 4, 3]
    # Nothing replaces a candidate that gains more than the outsider.
    stronger = np.array([0.6, 0.0, 0.5, 0.4, 0.02])
    assert with_rollout_evidence(look_alikes, remaining, one_step, short, ranked, stronger, 2, 0.05) == (short, [])
    # At most `n_promote`, and a NaN gain (a sensitivity that is not finite) ranks nothing.
    two = np.array([0.6, 0.0, 0.05, 0.4, 0.3])
    short5 = [0, 1, 2, 3]
    new, promoted = with_rollout_evidence(look_alikes, remaining, one_step, short5, ranked, two, 1, 0.05)
    assert promoted == [4]
    nan = np.array([0.6, 0.0, 0.05, np.nan, 0.02])
    assert with_rollout_evidence(look_alikes, remaining, one_step, short, ranked, nan, 2, 0.05) == (short, [])
