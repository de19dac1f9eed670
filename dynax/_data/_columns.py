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
OPTIONAL_STATES: dict[str, dict[str, tuple[str, str]]] = {
    "linear_axis": {"dq": ("q", "central")},
    "acrobot": {"dq1": ("q1", "central"), "dq2": ("q2", "central")},
    "double_pendulum": {"dq1": ("q1", "central"), "dq2": ("q2", "central")},
}


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
