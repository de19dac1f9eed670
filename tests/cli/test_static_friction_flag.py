"""`dynax identify --static-friction` turns the static level on in the dynamic model; off by default."""

import dynax
from dynax._cli._identify import _method  # private: the flag's only effect is on the method it builds
from dynax.internal import build_parser


def test_the_flag_turns_the_static_level_on():
    parser = build_parser()
    common = ["identify", "double_pendulum", "run.csv", "--out", "out.json", "--method", "dynamic"]
    off, on = parser.parse_args(common), parser.parse_args([*common, "--static-friction"])
    assert _method(off) == dynax.Dynamic() and not _method(off).adds_static_friction
    assert _method(on).adds_static_friction and _method(on) == dynax.Dynamic(static_friction=True)
