"""What `identify` returns: `Identification` (both stages, validation, settings, the contract's JSON)
and the warnings that qualify it."""


import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from .._fit import Solution
from .._model._system import AbstractSystem
from ._consistency import Consistency
from ._angle_zeros import AngleZeros
from ._offsets import RecordOffsets
from ._record_friction import RecordFriction
from ._validation import HeldOutError



class NoValidationWarning(UserWarning):
    """`identify` held nothing out to validate on: the records are too short for even the shortest
    horizon, so the answer carries no open-loop error (see `Identification.validation`)."""


class RecordsDisagreeWarning(UserWarning):
    """Leaving one record out moves some parameters much more than the standard errors estimated
    within the records allow (`Identification.record_std_errors`): the recordings differ."""


class Identification(eqx.Module):
    r"""The result of `identify`.

    **Fields:**

    - `system`: the system with the fitted parameters (for two-link arms with
      `friction="coulomb"`, `Extended` with `CoulombFriction` at both joints; after the output-error
      refinement also with `RotorInertia` at the elbow).
    - `estimate`, `std_errors`: parameter values and standard errors, in the order of `names`.
      The least-squares stage's errors are robust to rows correlated in time (`serial_covariance`;
      `stages["least_squares"]["serial_correlation"]` says by how much they grew); the output-error
      stage's are clustered over blocks of segments.
    - `names`: parameter names (the contract's; `Ir2` for the elbow's rotor inertia).
    - `condition_number`: of the column-scaled regressor (least-squares methods) or of the
      Jacobian at the solution (`SimulationFit`).
    - `rank`: numerical rank.
    - `n_samples`: samples that entered the fit.
    - `residual_rms`: root-mean-square residual of the fitted equations.
    - `relative_error`: $\lVert A\hat\theta - y\rVert / \lVert y\rVert$ of the (unweighted)
      equations: for `Dynamic` the relative force/torque error (EMPS reports 4.08 %); for
      `SimulationFit` the relative simulation error of the states.
    - `method`, `friction`, `system_name`: as in the contract's output.
    - `fit`: the least-squares stage's `Solution` (least-squares methods; its `std_errors` and `covariance` the
      robust ones above) or `None`.
    - `settings`: per record, the filter and derivative settings used and why (`Dynamic`).
    - `consistency`: the `Consistency` of the returned estimate: violated conditions, and which
      the constrained fit had to enforce.
    - `validation`: the `HeldOutError` of the returned model (open-loop simulation error against
      horizon on held-out data), or `None` when nothing could be held out.
    - `stages`: per stage (`"least_squares"`, and `"output_error"` after a refinement), its
      parameters, equation error and held-out simulation error, as a JSON-ready dict.
    - `solution`: for the iterative method (`SimulationFit`), the engine's `Solution` this result
      is built from (the same names, estimate, standard errors and covariance, plus the result
      code, steps and losses); `None` for the least-squares methods, whose `fit` holds the same.
    - `record_offsets`: for `Dynamic` on two records or more, each record's constant offset on each
      joint's recorded force (from each half of the record too) and whether they differ between
      records (`RecordOffsets`, see `dynax._identify._offsets`): a sensor zero that changes from one
      recording to the next, which no model term carries; `None` otherwise.
    - `angle_zeros`: for `Dynamic` with the settings chosen from the data on an arm whose every
      joint is a driven angle, each record's zero of each angle fitted with the parameters (an
      encoder zeroed where the arm stood when the recording began), whether both stages fitted the
      records less them (`chosen`: they left a smaller equation error than force offsets) and why
      (`AngleZeros`, see `dynax._identify._angle_zeros`); `None` otherwise.
    - `record_friction`: for `Dynamic` on two records or more with `friction="coulomb"`, each
      record's Coulomb friction coefficients (from each of four parts of the record too) and whether they
      differ between records (`RecordFriction`, see `dynax._identify._record_friction`): a friction
      that changed between recordings, which a held-out record keeps as error; `None` otherwise.
    - `poorly_determined`: the size parameters (inertias, gravity terms, mass) of the returned
      estimate whose relative standard error is above 25 %, name -> that ratio
      (`poorly_determined`; also warned as a `PoorlyDeterminedWarning`): after the output-error
      refinement judged on its standard errors, or the leave-one-record-out ones where larger
      (each stage's own is in `stages`); `{}` when the data determine them all, `None` for
      methods and systems it does not apply to.
    - `record_std_errors`: after the output-error refinement on three records or more, each
      parameter's standard error from the delete-one-record jackknife (how far it moves when one
      record is left out; `Refinement.record_std_errors`), in the order of `names`: the spread from
      one recording to the next (a friction or offset of that day) that `std_errors`, estimated
      within records, cannot carry; `None` otherwise.
    - `refined_covariance`: after the output-error refinement, the whole covariance behind
      `std_errors` (`Refinement.covariance`; what `covariance` returns then), e.g. for the error of
      a combination such as $M_{22} = \theta_2 + I_{r2}$; `None` otherwise.
    - `jointly_determined`: the parameters of the returned estimate that the data determine mostly
      in combination with others (`jointly_determined`: over 99 % of their variance shared), name ->
      `{"with": partners, "correlations": ..., "inflation": ratio}`; `{}` when none, `None` without
      a covariance.

    **Properties** in `Solution`'s spelling: `value` (= `estimate`), `covariance`; and
    `parameters` / `standard_errors` as `{name: value}` (`Solution.estimates()` /
    `Solution.standard_errors()`).
    """

    system: AbstractSystem
    estimate: Float[Array, " n_params"]
    std_errors: Float[Array, " n_params"]
    condition_number: Float[Array, ""]
    rank: Array
    residual_rms: Float[Array, ""]
    relative_error: Float[Array, ""]
    fit: Solution | None
    names: tuple[str, ...] = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    method: str = eqx.field(static=True)
    friction: str = eqx.field(static=True)
    system_name: str = eqx.field(static=True)
    settings: tuple = ()
    consistency: Consistency | None = None
    validation: HeldOutError | None = None
    stages: dict | None = None
    solution: Solution | None = None
    record_offsets: RecordOffsets | None = None
    angle_zeros: AngleZeros | None = None
    record_friction: RecordFriction | None = None
    poorly_determined: dict[str, float] | None = None
    record_std_errors: Float[Array, " n_params"] | None = None
    refined_covariance: Float[Array, "n_params n_params"] | None = None
    jointly_determined: dict[str, dict] | None = None

    @property
    def value(self) -> Float[Array, " n_params"]:
        """The estimate (`Solution`'s name for it)."""
        return self.estimate

    @property
    def covariance(self) -> Float[Array, "n_params n_params"] | None:
        """The estimate's covariance: from the solution (iterative), the refinement (after the
        output-error refinement: the cluster-robust one behind `std_errors`), or the least-squares
        fit; `None` where none applies."""
        if self.refined_covariance is not None:
            return self.refined_covariance
        if self.solution is not None:
            return self.solution.covariance
        if self.fit is not None and self.fit.covariance.shape[0] == self.estimate.shape[0] and "simulation" not in self.method:
            return self.fit.covariance
        return None

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
        if self.stages:
            out["stages"] = self.stages
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
