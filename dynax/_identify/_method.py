r"""`AbstractMethod`: what an identification method is, and what `identify` asks of one.

A method is a small `eqx.Module` of settings with one abstract method, `fit(system, records) ->
Solution`, as an optimistix solver is `init`/`step`/`terminate` and a diffrax solver `step`: the
driver (`identify`, `fit_vehicle`) calls the method and never checks its class. Everything else
`identify` asks of a method is a method or attribute here with a default that suits a method
which only fits: the least-squares methods (`Dynamic`, `Power`, `Energy`) override the hooks of
the least-squares stage, `SimulationFit` how its stage is named.
"""

import abc
from collections.abc import Callable, Sequence
from typing import ClassVar, Literal

import equinox as eqx
from jaxtyping import Array, Float

from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._fit import Solution


class FitSettings(eqx.Module):
    """What a run of a method sets beyond the method's own settings (as diffrax's `SaveAt`: grouped,
    so that `fit` keeps one signature for every method). A method reads what applies to it.

    **Fields:**

    - `friction`: least squares and `SimulationFit` on the systems the regressors know:
      `"viscous"` (default) or `"coulomb"` (adds the Coulomb friction coefficients).
    - `weights`: least squares: optional row weights, one per stacked equation.
    - `breaks`: vehicle criteria: the sample indices where a joined record's next flight begins
      (no window of the criteria crosses one).
    - `warm_start`: `Lagged`, `Backprop`: start from the system's weights, not the one-step fit.
    - `callback`: iterative vehicle criteria: `callback(iteration, loss)` after each iteration.
    - `progress`: iterative vehicle criteria: a bar per iteration (`None`: when stderr is a terminal).
    """

    friction: Literal["viscous", "coulomb"] = eqx.field(static=True, default="viscous")
    weights: Float[Array, " rows"] | None = None
    breaks: Sequence[int] | None = eqx.field(static=True, default=None)
    warm_start: bool = eqx.field(static=True, default=False)
    callback: Callable | None = eqx.field(static=True, default=None)
    progress: bool | None = eqx.field(static=True, default=None)


def as_records(records) -> list[Trajectory]:
    """`records` as a non-empty list of `Trajectory` (one record alone is a list of one)."""
    if isinstance(records, Trajectory):
        return [records]
    if isinstance(records, Sequence) and records and all(isinstance(r, Trajectory) for r in records):
        return list(records)
    raise UsageError(f"`records` must be a Trajectory or a non-empty list of Trajectory, got {type(records).__name__}")


class AbstractMethod(eqx.Module):
    """An identification method: `fit(system, records, settings) -> Solution`.

    Subclass it, give the method's settings as fields and implement `fit` with the engine
    (`dynax.fit_least_squares`, `dynax.fit_minimise`, or a linear solve returning a `Solution`);
    `identify(system, records, method=YourMethod())` then runs it, checks the estimate's physical
    consistency where the system has conditions, and validates the fitted model on held-out data.
    The hooks below have defaults for such a method; the built-in least-squares methods override
    them to run `identify`'s least-squares stage (force offsets, angle zeros, friction at rest, the
    consistency constraint and the output-error refinement).

    **Class attributes** (what `identify` asks):

    - `least_squares_stage`: whether `identify` runs its least-squares stage (the method builds the
      linear equations of `equations`) rather than calling `fit` once (default `False`).
    - `refits_without_loaded_rests`: least squares: refit without the rows where a joint rests
      under load (default `False`).

    **Properties:** `adds_static_friction`, whether the model gets `Stiction` where the records rest
    under load (default `False`: the rests are read and reported, the model is left as it is).
    """

    least_squares_stage: ClassVar[bool] = False
    refits_without_loaded_rests: ClassVar[bool] = False

    @property
    def adds_static_friction(self) -> bool:
        return False

    @abc.abstractmethod
    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """Fit `system`'s parameters to `records` (a `Trajectory` or a list of them).

        **Returns:** a `Solution` whose `model` is the fitted system and whose `names` name its
        estimate.
        """

    @property
    def label(self) -> str:
        """The method's name in `identify`'s output (the contract's `method`)."""
        return type(self).__name__.lower()

    @property
    def stage_kind(self) -> str:
        """The `StageKind` value of the stage `identify` reports this method's fit as."""
        return "fit"

    def n_samples(self, solution: Solution, records: list[Trajectory]) -> int:
        """The samples that entered `solution` (default: every sample of `records`)."""
        del solution
        return sum(len(r) for r in records)

    def equations(self, system, trajectories, friction):
        """Least squares: the method's stacked linear equations (see `stacked_equations`)."""
        raise UsageError(
            f"identify: `method` must be Dynamic(), Power(), Energy() or SimulationFit(), got {type(self).__name__}"
        )

    @property
    def force_offsets(self) -> bool | str:
        """Least squares: whether each record's constant force offset is fitted (`Dynamic`'s `offsets`)."""
        return False

    @property
    def joint_weighted(self) -> bool:
        """Least squares: whether each joint's equations are weighted by its residual variance."""
        return False

    @property
    def angle_zeros_mode(self) -> Literal["compare", "always"] | None:
        """Least squares: whether `identify` fits each record's angle zeros where every joint of the
        system is a driven angle: `"compare"` (kept where they fit better than force offsets),
        `"always"` (refused on other systems) or `None` (default)."""
        return None
