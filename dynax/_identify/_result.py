"""What `identify` returns: `Identification` (the fitted system, its typed `Stage`s, validation,
settings, the contract's JSON) and the warnings that qualify it."""

import enum

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._fit import Solution, Statistics
from .._model._system import AbstractSystem
from .._simulate import SimulationError
from ._angle_zeros import AngleZeros
from ._consistency import Consistency
from ._offsets import RecordOffsets
from ._record_friction import RecordFriction
from ._refine import RefinementStatistics
from ._simulation_fit import OutputErrorStatistics
from ._static_friction import StaticFriction


class NoValidationWarning(UserWarning):
    """`identify` held nothing out to validate on: the records are too short for even the shortest
    horizon, so the answer carries no open-loop error (see `Identification.validation`)."""


class RecordsDisagreeWarning(UserWarning):
    """Leaving one record out moves some parameters much more than the standard errors estimated
    within the records allow (`Identification.record_std_errors`): the recordings differ."""


class StageKind(enum.StrEnum):
    """The stages of `identify`: the key of each stage in the JSON output's `stages`."""

    LEAST_SQUARES = "least_squares"
    """The linear equations (`Dynamic`, `Power`, `Energy`) solved and made physically consistent."""
    OUTPUT_ERROR = "output_error"
    """The least-squares model refined through the integrator (`refine_by_simulation`)."""
    SIMULATION = "simulation"
    """An output-error fit from the system's own values (`SimulationFit`)."""
    FIT = "fit"
    """One fit by a method of another kind (an `AbstractMethod` whose `fit` is all it does)."""


class Stage(eqx.Module):
    r"""One stage of `identify`: its estimate, and how that estimate fits and validates.

    **Fields:**

    - `kind`: a `StageKind`.
    - `method`: the contract's name of the stage's method (`"dynamic"`, `"power"`, `"energy"`,
      `"simulation"`).
    - `solution`: the stage's `Solution` (`names`, `value`, `std_errors`, `covariance`); its
      `statistics` are a `Statistics` (least squares: the regressor's singular values, condition
      number and rank), a `RefinementStatistics` (output-error refinement) or an
      `OutputErrorStatistics` (`SimulationFit`). The least-squares stage's errors are robust to
      rows correlated in time (`serial_correlation` says by how much they grew); its value is the
      constrained estimate where the plain one was inconsistent.
    - `relative_equation_error`: $\lVert A\hat\theta - y\rVert / \lVert y\rVert$ of the
      least-squares equations at this stage's estimate; `None` for `SimulationFit`.
    - `validation`: the `SimulationError` on held-out data (`held_out_error`) of this stage's model, or `None`.
    - `consistency`: the `Consistency` of this stage's estimate, or `None`.
    - `poorly_determined`: its size parameters the data determine poorly (see `poorly_determined`).
    - `offsets`: least squares: each record's fitted force offset at each driven joint, JSON-ready
      (`records`, `joints`, `values`), or `None`.
    - `angle_zeros`: least squares: the records' angle zeros (`AngleZeros`), or `None`.
    - `serial_correlation`: least squares: `{"bandwidth_steps", "inflation"}`, how much the errors
      robust to serial correlation grew over those counting every row as independent, or `None`.
    - `records_disagree`: output error: the parameters whose leave-one-record-out error exceeds
      the within-record one `RECORDS_DISAGREE` times, name -> ratio.
    - `joint_weights`: least squares with `Dynamic(weighting="joint")`: the weight of each joint's
      equations (the inverse of its residual variance from a first ordinary fit), joint -> weight; else `None`.
    """

    kind: StageKind = eqx.field(static=True)
    method: str = eqx.field(static=True)
    solution: Solution
    relative_equation_error: float | None = eqx.field(static=True, default=None)
    validation: SimulationError | None = None
    consistency: Consistency | None = None
    poorly_determined: dict[str, float] | None = eqx.field(static=True, default=None)
    offsets: dict | None = eqx.field(static=True, default=None)
    angle_zeros: AngleZeros | None = None
    serial_correlation: dict | None = eqx.field(static=True, default=None)
    records_disagree: dict[str, float] = eqx.field(static=True, default_factory=dict)
    joint_weights: dict[str, float] | None = eqx.field(static=True, default=None)

    @property
    def names(self) -> tuple[str, ...]:
        return self.solution.names

    @property
    def kept_start(self) -> bool:
        """The output-error refinement ended worse than its start, which it returns unrefined."""
        return self.kind == StageKind.OUTPUT_ERROR and self.solution.statistics.kept_start

    def to_json(self) -> dict:
        """The stage's entry in the JSON output's `stages`."""
        names = self.names
        out = {
            "method": self.method,
            "parameters": {n: float(v) for n, v in zip(names, np.asarray(self.solution.value))},
            "std_errors": {n: float(v) for n, v in zip(names, np.asarray(self.solution.std_errors))},
            "relative_equation_error": None
            if self.relative_equation_error is None
            else float(self.relative_equation_error),
            "validation": None if self.validation is None else self.validation.to_json(),
        }
        if self.kind == StageKind.LEAST_SQUARES:
            out.update(
                consistency=self.consistency.to_json(),
                offsets=self.offsets,
                angle_zeros=None if self.angle_zeros is None else self.angle_zeros.to_json(),
                poorly_determined=self.poorly_determined,
                serial_correlation=self.serial_correlation,
                joint_weights=self.joint_weights,
            )
        elif self.kind == StageKind.OUTPUT_ERROR:
            stats = self.solution.statistics
            assert isinstance(stats, RefinementStatistics)
            out.update(
                consistency=self.consistency.to_json(),
                initial_residual_rms=stats.initial_residual_rms,
                residual_rms=stats.residual_rms,
                steps=int(self.solution.steps),
                dt=stats.dt,
                segment_s=stats.segment_s,
                record_std_errors=None
                if stats.record_std_errors is None
                else {n: float(v) for n, v in zip(names, stats.record_std_errors)},
                records_disagree=self.records_disagree,
                model="least-squares model + RotorInertia(joint=1)"
                + "".join(f" + Stiction(joint={int(n[2:]) - 1})" for n in names if n.startswith("fs"))
                + ", consistent parametrisation",
                diverged=stats.kept_start,
                diverged_segments=dict(zip(("at_end", "at_start", "segments"), stats.diverged_segments)),
                input_timing=None
                if stats.input_alpha is None
                else {
                    "alpha": stats.input_alpha,
                    "latency_s": stats.input_latency_s,
                    "meaning": "the inputs that fit best act latency_s after the sample that records them "
                    "(0: sampled without delay; half the record's interval: the zero-order hold as "
                    "recorded)",
                },
                poorly_determined=self.poorly_determined,
            )
        return out


class Identification(eqx.Module):
    r"""The result of `identify`: the fitted system, the stages that fitted it, and what qualifies it.

    **Fields:**

    - `system`: the system with the fitted parameters (for two-link arms with
      `friction="coulomb"`, `Extended` with `CoulombFriction` at both joints; after the output-error
      refinement also with `RotorInertia` at the elbow).
    - `stages`: the `Stage`s that ran, in order (least squares, then the output-error refinement
      where it ran; or the one `SimulationFit` stage). The last one's estimate is the result's.
    - `n_samples`: samples that entered the fit.
    - `friction`, `system_name`: as in the contract's output.
    - `settings`: per record, the filter and derivative settings used and why (`Dynamic`).
    - `record_offsets`: for `Dynamic` on two records or more, each record's constant offset on each
      joint's recorded force (from each half of the record too) and whether they differ between
      records (`RecordOffsets`): a sensor zero that changes from one recording to the next, which
      no model term carries; `None` otherwise.
    - `angle_zeros`: for `Dynamic` with the settings chosen from the data on an arm whose every
      joint is a driven angle, each record's zero of each angle fitted with the parameters, whether
      both stages fitted the records less them and why (`AngleZeros`); `None` otherwise.
    - `record_friction`: for `Dynamic` on two records or more with `friction="coulomb"`, each
      record's Coulomb friction coefficients and whether they differ between records
      (`RecordFriction`); `None` otherwise.
    - `poorly_determined`: the size parameters (inertias, gravity terms, mass) of the returned
      estimate whose relative standard error is above 25 %, name -> that ratio
      (`poorly_determined`; also warned as a `PoorlyDeterminedWarning`): after the output-error
      refinement judged on its standard errors, or the leave-one-record-out ones where larger;
      `{}` when the data determine them all, `None` for methods and systems it does not apply to.
    - `static_friction`: for two-link arms fitted by least squares, what the records show of friction
      at rest (`StaticFriction`): the stretches where a joint rests and the net torque it holds, the
      `Stiction` level of each joint that rests under load (which `system` then carries: a breakaway
      torque, or a lower bound from the torques held), the dynamic rows at rest or at low speed left out of the fit,
      and a note; with no rest under load, or a method that does not add it (`Dynamic()` by default;
      `Dynamic(static_friction=True)` does), no `Stiction` and a note saying why; `None` otherwise.
    - `jointly_determined`: the parameters of the returned estimate that the data determine mostly
      in combination with others (over 99 % of their variance shared), name ->
      `{"with": partners, "correlations": ..., "inflation": ratio}`; `{}` when none, `None` without
      a covariance.

    **Properties:** `solution` (the last stage's `Solution`), `names`, `value` (= `estimate`),
    `std_errors`, `covariance`, `parameters` / `standard_errors` as `{name: value}`, `validation`
    and `consistency` (the last stage's), `relative_error` (the relative equation error of the
    returned estimate on the least-squares rows; for `SimulationFit` the relative state error),
    `condition_number` and `rank` (of the column-scaled regressor, or for `SimulationFit` of the
    Jacobian at the solution), `residual_rms`, `record_std_errors` (the output-error refinement's
    delete-one-record jackknife on three records or more), `method` (the contract's label:
    `"dynamic"`, `"dynamic+simulation"`, `"simulation"`, ...), and `stage(kind)`.
    """

    system: AbstractSystem
    stages: tuple[Stage, ...]
    n_samples: int = eqx.field(static=True)
    friction: str = eqx.field(static=True)
    system_name: str = eqx.field(static=True)
    settings: tuple = ()
    record_offsets: RecordOffsets | None = None
    angle_zeros: AngleZeros | None = None
    record_friction: RecordFriction | None = None
    poorly_determined: dict[str, float] | None = eqx.field(static=True, default=None)
    jointly_determined: dict[str, dict] | None = eqx.field(static=True, default=None)
    static_friction: StaticFriction | None = eqx.field(static=True, default=None)

    def stage(self, kind: StageKind | str) -> Stage | None:
        """The stage of that kind, or `None` where it did not run."""
        return next((s for s in self.stages if s.kind == kind), None)

    @property
    def solution(self) -> Solution:
        """The returned estimate's `Solution` (the last stage's)."""
        return self.stages[-1].solution

    @property
    def names(self) -> tuple[str, ...]:
        return self.solution.names

    @property
    def estimate(self) -> Float[Array, " n_params"]:
        return jnp.asarray(self.solution.value)

    @property
    def value(self) -> Float[Array, " n_params"]:
        """The estimate (`Solution`'s name for it)."""
        return self.estimate

    @property
    def std_errors(self) -> Float[Array, " n_params"]:
        return jnp.asarray(self.solution.std_errors)

    @property
    def covariance(self) -> Float[Array, "n_params n_params"]:
        """The estimate's covariance: the least-squares one robust to serial correlation, the
        refinement's cluster-robust one carried through its parametrisation, or the output-error fit's."""
        return self.solution.covariance

    @property
    def validation(self) -> SimulationError | None:
        return self.stages[-1].validation

    @property
    def consistency(self) -> Consistency | None:
        return self.stages[-1].consistency

    @property
    def fit(self) -> Solution | None:
        """The least-squares stage's `Solution`, or `None` for `SimulationFit`."""
        first = self.stage(StageKind.LEAST_SQUARES)
        return None if first is None else first.solution

    @property
    def _linear_statistics(self) -> Statistics:
        first = self.stages[0].solution.statistics
        linear = first.jacobian if isinstance(first, OutputErrorStatistics) else first
        assert isinstance(linear, Statistics)
        return linear

    @property
    def condition_number(self) -> Float[Array, ""]:
        """Of the column-scaled regressor (or Jacobian); NaN for a method whose fit reports none (a
        vehicle criterion)."""
        first = self.stages[0].solution.statistics
        if not isinstance(first, (Statistics, OutputErrorStatistics)):
            return jnp.asarray(jnp.nan)
        return self._linear_statistics.condition_number

    @property
    def rank(self) -> Array:
        return self._linear_statistics.rank

    @property
    def residual_rms(self) -> Float[Array, ""]:
        first = self.stages[0].solution.statistics
        assert isinstance(first, (Statistics, OutputErrorStatistics))
        return first.residual_rms

    @property
    def relative_error(self) -> Float[Array, ""]:
        last = self.stages[-1]
        if last.relative_equation_error is None:
            statistics = last.solution.statistics
            return statistics.relative_error if isinstance(statistics, OutputErrorStatistics) else jnp.asarray(jnp.nan)
        return jnp.asarray(last.relative_equation_error)

    @property
    def record_std_errors(self) -> Float[Array, " n_params"] | None:
        last = self.stages[-1]
        if last.kind != StageKind.OUTPUT_ERROR or last.solution.statistics.record_std_errors is None:
            return None
        return jnp.asarray(last.solution.statistics.record_std_errors)

    @property
    def method(self) -> str:
        first, last = self.stages[0], self.stages[-1]
        if last.kind != StageKind.OUTPUT_ERROR:
            return first.method
        return f"{first.method}+simulation" + (
            " (ended worse than its start: least squares kept)" if last.kept_start else ""
        )

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter name -> value."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(self.estimate))}

    @property
    def standard_errors(self) -> dict[str, float]:
        """Parameter name -> standard error."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(self.std_errors))}

    def to_json(self) -> dict:
        """The contract's `identify` output object, extended with `settings`, `consistency`,
        `validation`, `stages`, `record_offsets`, `angle_zeros` and `record_friction` where they apply."""
        out = {
            "system": self.system_name,
            "method": self.method,
            "friction": self.friction,
            "parameters": self.parameters,
            "std_errors": self.standard_errors,
            "condition_number": float(self.condition_number),
            "n_samples": int(self.n_samples),
            "relative_error": float(self.relative_error),
        }
        if self.settings:
            out["settings"] = [_jsonable(s) for s in self.settings]
        if self.consistency is not None:
            out["consistency"] = self.consistency.to_json()
        out["validation"] = None if self.validation is None else self.validation.to_json()
        out["stages"] = {str(s.kind): s.to_json() for s in self.stages}
        if self.record_offsets is not None:
            out["record_offsets"] = self.record_offsets.to_json()
        if self.angle_zeros is not None:
            out["angle_zeros"] = self.angle_zeros.to_json()
        if self.record_friction is not None:
            out["record_friction"] = self.record_friction.to_json()
        if self.poorly_determined is not None:
            out["poorly_determined"] = self.poorly_determined
        if self.jointly_determined is not None:
            out["jointly_determined"] = self.jointly_determined
        if self.static_friction is not None:
            out["static_friction"] = self.static_friction.to_json()
        if self.record_std_errors is not None:
            out["record_std_errors"] = {n: float(v) for n, v in zip(self.names, np.asarray(self.record_std_errors))}
        return out


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, np.integer)) or (hasattr(value, "shape") and np.shape(value) == ()):
        return float(value)
    return value


EQUATIONS_LEFT = 3.0  # the refined estimate's equation error over the least-squares stage's that says it left them
SIZES_LEFT = 3.0  # a size parameter refined to more than this factor of its least-squares value (either way) ...
SIZES_LEFT_ERRORS = 10.0  # ... and this many of the least-squares stage's standard errors away from it


def warn_if_refinement_left_equations(identification: Identification) -> None:
    r"""Warn (`InconsistentEstimateWarning`) where the output-error refinement ended where the least-squares
    equations it started from do not hold: its estimate's equation error on those equations is `EQUATIONS_LEFT`
    times the least-squares stage's or more, or a size parameter (inertia, gravity term, mass) moved by more than
    a factor `SIZES_LEFT` and by `SIZES_LEFT_ERRORS` of the least-squares stage's standard errors. The warning
    names what moved, by how much, and what to check.

    The refinement fits the simulated motion, which a model far from the physics may still follow over short
    windows: a record whose torque is negated part way can refine to a gravity term a thousand times the
    machine's and still simulate the held-out tail well. On clean records the refinement keeps the equations
    (measurements in docs/devdocs/identification_notes.md). A refinement that kept its start (`kept_start`) is
    not judged."""
    import warnings

    from .._model._linear_in_parameters import size_parameter_names
    from ._consistency import InconsistentEstimateWarning
    from ._regressors import split_terms

    ls, refined = identification.stage(StageKind.LEAST_SQUARES), identification.stage(StageKind.OUTPUT_ERROR)
    if ls is None or refined is None or refined.kept_start:
        return
    before, after = ls.relative_equation_error, refined.relative_equation_error
    if before is None or after is None or not np.isfinite(before) or before <= 0:
        return
    ratio = after / before if np.isfinite(after) else np.inf
    start = dict(zip(ls.names, np.asarray(ls.solution.value, dtype=float)))
    std = dict(zip(ls.names, np.asarray(ls.solution.std_errors, dtype=float)))
    end = dict(zip(refined.names, np.asarray(refined.solution.value, dtype=float)))
    sizes = set(size_parameter_names(split_terms(identification.system)[0]))
    moved = []  # (standard errors moved, name, start, end)
    for name, value in start.items():
        if name not in end or not np.isfinite(end[name]):
            continue
        errors = abs(end[name] - value) / std[name] if std[name] > 0 else np.inf
        moved.append((errors, name, value, end[name]))
    moved.sort(reverse=True)

    def far(value, refined_value):
        if value == 0 or refined_value / value <= 0:
            return True
        return max(refined_value / value, value / refined_value) > SIZES_LEFT

    left = [m for m in moved if m[1] in sizes and far(m[2], m[3]) and m[0] > SIZES_LEFT_ERRORS]
    if ratio < EQUATIONS_LEFT and not left:
        return
    shown = (left + [m for m in moved if m not in left])[:3]
    cells = ", ".join(
        f"{name} from {value:.4g} to {refined_value:.4g} ({errors:.3g} standard errors of the least-squares stage)"
        for errors, name, value, refined_value in shown
    )
    warnings.warn(
        f"the output-error refinement ended where the equations it started from do not hold: its estimate leaves "
        f"an equation error of {after:.0%} on the least-squares equations, {ratio:.3g} times the "
        f"least-squares stage's {before:.0%}; it moved {cells}. A simulation can follow the motion over short "
        "windows with a model the recorded inputs contradict. Check the inputs (a sign or a scale that changes "
        "while recording, a column that is not the joint's torque, an offset) and the warnings above; until then "
        "trust the least-squares stage's estimate (`stages.least_squares`), or fit without the refinement "
        "(`--refine no`; in Python `refine=False`).",
        InconsistentEstimateWarning,
        stacklevel=3,
    )
