"""`dynax identify --static-friction` turns the static level on in the dynamic model; off by default."""

import pytest

import dynax
from dynax import UsageError
from dynax._cli._identify import _method, with_static_friction  # private: the flag's effect on the method
from dynax.internal import build_parser


def test_the_flag_turns_the_static_level_on():
    parser = build_parser()
    common = ["identify", "double_pendulum", "run.csv", "--out", "out.json"]
    off = parser.parse_args([*common, "--method", "dynamic"])
    on = parser.parse_args([*common, "--method", "dynamic", "--static-friction"])
    assert with_static_friction(_method(off), off) == dynax.Dynamic()
    assert with_static_friction(_method(on), on) == dynax.Dynamic(static_friction=True)
    power = parser.parse_args([*common, "--method", "power", "--static-friction"])
    with pytest.raises(UsageError, match="--static-friction"):
        with_static_friction(_method(power), power)
