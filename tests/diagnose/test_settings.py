"""A diagnosis's settings (`dynax.Horizons`, `dynax.Selection`): a value that cannot work is refused when the settings
are made, with an error naming the field, before any record is read or any fit compiled."""

import pytest

from dynax import Acrobot, diagnose, Horizons, Selection, UsageError


@pytest.mark.parametrize(
    "make, field",
    [
        (lambda: Selection(max_terms=0), "max_terms"),
        (lambda: Selection(alpha=1.0), "alpha"),
        (lambda: Selection(min_gain=-0.1), "min_gain"),
        (lambda: Selection(shortlist=0), "shortlist"),
        (lambda: Selection(holdout_fraction=1.0), "holdout_fraction"),
        (lambda: Selection(velocities="smoothed"), "velocities"),
        (lambda: Horizons(horizons_s=()), "horizons_s"),
        (lambda: Horizons(horizons_s=(0.1, -0.5)), "horizons_s"),
        (lambda: Horizons(reference_s=0.0), "reference_s"),
        (lambda: Horizons(fraction=1.5), "fraction"),
        (lambda: Horizons(fit_window_s=float("nan")), "fit_window_s"),
    ],
)
def test_a_setting_that_cannot_work_is_refused_by_name(make, field):
    with pytest.raises(UsageError, match=f"`{field}`"):
        make()


def test_settings_keep_what_is_given_and_say_the_defaults():
    assert Horizons(horizons_s=[1, 0.5]).horizons_s == (1.0, 0.5)
    assert Horizons().reported() == (0.1, 0.25, 0.5, 1.0, 2.0)  # the default where none are given
    assert Horizons(horizons_s=(0.25,)).reported((0.1, 0.5)) == (0.25,)
    s = Selection(max_terms=1, cross_fit=False)
    assert (s.max_terms, s.alpha, s.min_gain, s.shortlist, s.cross_fit, s.discovery) == (1, 0.01, 0.05, 4, False, True)
    assert hash(s) == hash(Selection(max_terms=1, cross_fit=False))  # static: usable as a jit-static argument


@pytest.mark.wrong_types
def test_diagnose_refuses_settings_of_the_wrong_type_before_reading_the_records():
    with pytest.raises(UsageError, match="`selection` must be a dynax.Selection"):
        diagnose(Acrobot(), [], selection={"max_terms": 2})  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="`horizons` must be a dynax.Horizons"):
        diagnose(Acrobot(), [], horizons=(0.1, 0.5))  # type: ignore[arg-type]
