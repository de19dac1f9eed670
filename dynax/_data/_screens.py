"""The data checks' cheap screens, and the switch that turns them off.

The glitch search bounds how far any sample can lie from its running median before it takes the median,
the wrap search skips an angle none of whose steps comes near half a turn, and the velocity-unit check
reads a velocity's gain from numpy's sums with their rounding bound before it asks BLAS. Each screen skips
only work whose answer it has proven, so the findings are the same with the screens off: `screens_off`
runs the checks in full, for the tests that hold them to that and for pricing what they save.
"""

from collections.abc import Iterator
import contextlib
import contextvars

from .._context import set_within

SCREENS = contextvars.ContextVar("dynax_data_check_screens", default=True)  # False: every search in full


@contextlib.contextmanager
def screens_off() -> Iterator[None]:
    """Within the block, the data checks (`check_records`, `check_trajectory_velocities`) run every glitch,
    wrap and velocity-gain search in full, without the screens that skip the ones whose answer is proven.
    The findings do not change; the time does."""
    with set_within(SCREENS, False):
        yield
