"""The admissibility rules of one selection round (`_judge_round`): a candidate whose joint refit pushes
an earlier finding's coefficient to an unphysical sign is not admissible, however much it helps."""

import numpy as np
import pytest

from dynax._diagnose._diagnose import _judge_round
from dynax._model._extensions import CoulombFriction, InputOffset


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
    results = _judge_round(candidates, [1], [1], [0], n_nom, p, np.full_like(p, 0.01), errors, scores, score_cur,
                           np.repeat([0, 1], n_windows // 2), 1, alpha=0.01, min_gain=0.05,
                           steps=np.asarray([5, 10]), position_index=[0, 1])
    return results[1]


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


def test_terms_of_either_sign_are_not_constrained():
    """An input offset may be negative: a joint refit that moves it there is admissible."""
    r = _round(earlier_fc1=-0.3, new_delta=0.1, earlier=InputOffset(0))
    assert r["physical"] and r["significant"]
