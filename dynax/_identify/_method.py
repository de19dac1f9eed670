r"""`AbstractMethod`: what an identification method is, and what `identify` asks of one.

A method is a small `eqx.Module` of settings with one abstract method, `fit(system, records) ->
Solution`, as an optimistix solver is `init`/`step`/`terminate` and a diffrax solver `step`: the
driver (`identify`, which `fit_vehicle` and `fit_quadrotor` spell for vehicles) calls the method and
never checks its class. `identify` runs
the same steps for every method, given an `IdentifyJob`: `prepare` (default: the records as given),
`fit_stage` (default: the method's `fit` once, checked for consistency), `refine` (default: nothing
to refine), then validates each stage's model itself. The least-squares methods (`Dynamic`,
`Power`, `Energy`) override the three with their stages, `SimulationFit` says how its stage is
named, and the vehicle criteria (`AbstractVehicleCriterion`) join a vehicle's flights in `prepare`.
"""

import abc
from collections.abc import Callable, Sequence
from typing import Any, Literal, TYPE_CHECKING

import equinox as eqx
from jaxtyping import Array, Float

from .._data._trajectory import Trajectory
from .._errors import UsageError
from .._fit import Solution
from ._validation import HeldOut

if TYPE_CHECKING:
    from ._result import Identification


class FitSettings(eqx.Module):
    """What a run of a method sets beyond the method's own settings (as diffrax's `SaveAt`: grouped,
    so that `fit` keeps one signature for every method, and `identify` one argument for all of them:
    `identify(system, data, method, settings=FitSettings(...))`). A method reads what applies to it.

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


class IdentifyJob(eqx.Module):
    """What `identify` hands a method's steps beyond the system and the records to fit.

    **Fields:** `settings` (the `FitSettings` of the fit), `held_out` (the `HeldOut` records every
    stage is validated on), `consistency` (`"constrain"`, `"check"` or `"off"`, as `identify` takes
    it), `refine` (`identify`'s `refine`: `"auto"`, `True`, `False` or a `SimulationFit`; a method
    that has no refinement ignores it), `system_name` (the contract's name of the system).
    """

    settings: FitSettings
    held_out: HeldOut
    consistency: Literal["constrain", "check", "off"] = "constrain"
    refine: object = "auto"
    system_name: str = ""


class Prepared(eqx.Module):
    """What a method's `prepare` hands its fit: the method that fits (a least-squares method without
    force offsets where each record's angle zeros are fitted out), the records to fit, the `job`
    (whose `held_out` records are then read as the fit reads its own), the `angle_zeros`
    (`AngleZeros`, or `None` where not looked for) and a `filter_rule` the first stage runs under
    (`dynax._data._spectra.filter_rule`; `None`: the filters the spectra choose; the refinement follows them)."""

    method: "AbstractMethod"
    records: list[Trajectory]
    job: IdentifyJob
    angle_zeros: Any = None
    filter_rule: Any = None


class Fitted(eqx.Module):
    """What a method's `fit_stage` and `refine` hand on: the `identification` so far, whose stages
    `identify` then validates, the model of each stage it validates (`models`: the stage's model,
    or where the least-squares stage adds friction at rest, that model with its `Stiction`), and the
    method's own `state` between its fit and its refinement (`None` by default)."""

    identification: "Identification"
    models: tuple
    state: Any = None


class AbstractMethod(eqx.Module):
    """An identification method: `fit(system, records, settings) -> Solution`.

    Subclass it, give the method's settings as fields and implement `fit` with the engine
    (`dynax.fit_least_squares`, `dynax.fit_minimise`, or a linear solve returning a `Solution`);
    `identify(system, records, method=YourMethod())` then runs it, checks the estimate's physical
    consistency where the system has conditions, and validates the fitted model on held-out data.
    The steps `identify` runs (`prepare`, `fit_stage`, `refine`) and the methods below have
    defaults for such a method; the built-in least-squares methods override the steps to run their
    stages (angle zeros; force offsets, the consistency constraint and friction at rest; the
    output-error refinement).
    """

    @abc.abstractmethod
    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """Fit `system`'s parameters to `records` (a `Trajectory` or a list of them).

        **Returns:** a `Solution` whose `model` is the fitted system and whose `names` name its
        estimate.
        """

    def prepare(self, system, records: list[Trajectory], job: IdentifyJob) -> Prepared:
        """`identify`'s first step: the records as the fit reads them (default: as given).

        **Returns:** a `Prepared`.
        """
        del system
        return Prepared(self, records, job)

    def fit_stage(self, system, prepared: Prepared) -> Fitted:
        """`identify`'s second step: the first stage on `prepared.records`.

        The default is `fit` once (with `prepared.job.settings`) and the estimate's physical
        consistency checked where the system has conditions (`job.consistency`), reported as one
        stage of kind `stage_kind`.

        **Returns:** a `Fitted`, whose stages `identify` validates.
        """
        from ._stages import fit_once  # the stages build on the methods: imported where they run

        return fit_once(self, system, prepared)

    def refine(self, system, prepared: Prepared, fitted: Fitted) -> Fitted:
        """`identify`'s third step: stages after the first (default: none, `fitted` as it is).

        **Returns:** a `Fitted`.
        """
        del system, prepared
        return fitted

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
