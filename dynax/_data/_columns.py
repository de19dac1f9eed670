"""The contract's column names per system (CONTRACT.md section 1)."""

SYSTEM_COLUMNS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "acrobot": (("q1", "q2", "dq1", "dq2"), ("tau2",)),
    "double_pendulum": (("q1", "q2", "dq1", "dq2"), ("tau1", "tau2")),
    "linear_axis": (("q", "dq"), ("force",)),
    "helicopter": (
        ("x", "y", "z", "qw", "qx", "qy", "qz", "u", "v", "w", "p", "q", "r"),
        ("u1", "u2", "u3", "u4"),
    ),
    "quadrotor": (
        ("x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "p", "q", "r"),
        ("m1", "m2", "m3", "m4", "vbat"),
    ),
}

# Input columns that may be absent from a file: the trajectory then has the other inputs only
# (a quadrotor logged without its battery voltage).
OPTIONAL_INPUTS: dict[str, tuple[str, ...]] = {"quadrotor": ("vbat",)}

# Velocity columns that may be absent from a file (encoder positions alone) and are then estimated
# from the named position column, by the named difference (see `load_trajectory`) on the times the
# positions were read at (`sample_times_from_positions`): central differences, which do not lag (a
# backward difference lags half a sample, which biases every parameter fitted to it; `choose_filter`
# reads such a velocity's noise floor from the angle's backward difference, as a logger's velocity
# reads). Estimated only when the file has none of a system's velocities and none is mapped.
# A quadrotor log may lack its world velocities (estimated from x, y, z) or its body rates (a motion-capture
# log of poses alone: estimated from the attitude, `ATTITUDE`, by central differences of its body-frame
# steps); each group is estimated only when the file has none of it.
ATTITUDE = "attitude"
OPTIONAL_STATES: dict[str, dict[str, tuple[str, str]]] = {
    "linear_axis": {"dq": ("q", "central")},
    "acrobot": {"dq1": ("q1", "central"), "dq2": ("q2", "central")},
    "double_pendulum": {"dq1": ("q1", "central"), "dq2": ("q2", "central")},
    "quadrotor": {
        "vx": ("x", "central"),
        "vy": ("y", "central"),
        "vz": ("z", "central"),
        "p": (ATTITUDE, "central"),
        "q": (ATTITUDE, "central"),
        "r": (ATTITUDE, "central"),
    },
}


def optional_groups(system: str) -> list[dict[str, tuple[str, str]]]:
    """The optional states of `system` (`OPTIONAL_STATES`) in groups that a file has whole or not at all: those
    estimated from the attitude, and those estimated from positions."""
    optional = OPTIONAL_STATES.get(system, {})
    groups = [{n: s for n, s in optional.items() if (s[0] == ATTITUDE) is kind} for kind in (False, True)]
    return [g for g in groups if g]


def columns_for(system: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """State and input column names of a system named as in the contract."""
    if not isinstance(system, str):  # a system instance (`Acrobot()`) is unhashable: name it instead
        from .._errors import UsageError

        raise UsageError(
            f"`system` must be a system's name (one of {sorted(SYSTEM_COLUMNS)}), got {type(system).__name__}"
        )
    if system not in SYSTEM_COLUMNS:
        from .._errors import UsageError

        raise UsageError(f"unknown system '{system}'; expected one of {sorted(SYSTEM_COLUMNS)}")
    return SYSTEM_COLUMNS[system]
