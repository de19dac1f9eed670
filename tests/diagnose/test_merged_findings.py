"""A wind found in two rounds is reported once, and keeps the test each round's component rests on."""

import numpy as np

from dynax.internal import merge_repeated_causes


def _finding(parameter, coefficient, p_value, named_for=None):
    finding = {
        "cause": "wind",
        "where": "world",
        "coefficient": coefficient,
        "std_error": 0.1,
        "gain": 0.5,
        "parameter": parameter,
        "p_value": p_value,
        "look_alikes": [],
        "confidence": "high",
    }
    return finding | ({"named_for": named_for} if named_for else {})


def test_a_component_named_for_its_look_alike_keeps_the_test_it_rests_on():
    established = {"cause": "body_bias", "where": "u", "p_value": 3e-6}
    merged = merge_repeated_causes([_finding("wind_north", 3.0, 1e-9), _finding("wind_east", 4.0, 0.2, established)])
    assert len(merged) == 1
    (wind,) = merged
    assert np.isclose(wind["coefficient"], 5.0) and np.isclose(wind["gain"], 0.75)
    # the merged p is the weaker round's own p, which only its look-alike's test makes significant
    assert wind["p_value"] == 0.2
    assert wind["named_for"] == established
    assert wind["component_named_for"] == {"wind_east": established}


def test_components_found_on_their_own_tests_carry_no_look_alike():
    merged = merge_repeated_causes([_finding("wind_north", 3.0, 1e-9), _finding("wind_down", -1.0, 1e-4)])
    assert "named_for" not in merged[0] and "component_named_for" not in merged[0]
    assert merged[0]["p_value"] == 1e-4
