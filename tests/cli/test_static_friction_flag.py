"""`dynax identify --static-friction` turns the static level on in the dynamic model, off by default;
`--offsets` chooses the dynamic model's per-record offsets, `Dynamic(offsets=...)`."""

import pytest

import dynax
from dynax import UsageError
from dynax.internal import build_parser, method_from_args

COMMON = ["identify", "double_pendulum", "run.csv", "--out", "out.json"]


def test_the_flag_turns_the_static_level_on():
    parser = build_parser()
    off = parser.parse_args([*COMMON, "--method", "dynamic"])
    on = parser.parse_args([*COMMON, "--method", "dynamic", "--static-friction"])
    assert method_from_args(off) == dynax.Dynamic()
    assert method_from_args(on) == dynax.Dynamic(static_friction=True)
    power = parser.parse_args([*COMMON, "--method", "power", "--static-friction"])
    with pytest.raises(UsageError, match="--static-friction"):
        method_from_args(power)


@pytest.mark.parametrize("flag, offsets", [("auto", "auto"), ("forces", True), ("angles", "angles"), ("none", False)])
def test_the_offsets_flag_chooses_the_dynamic_models_offsets(flag, offsets):
    parser = build_parser()
    assert method_from_args(parser.parse_args([*COMMON, "--offsets", flag])) == dynax.Dynamic(offsets=offsets)
    with pytest.raises(UsageError, match="--offsets"):
        method_from_args(
            parser.parse_args([*COMMON, "--method", "power", "--offsets", flag if flag != "auto" else "none"])
        )
