"""The one result type of every fit, after optimistix's `Solution`."""

import equinox as eqx
from jaxtyping import Array, Float, PyTree
import numpy as np
import optimistix as optx

from ._parameters import Parameters


def _reduced_row_echelon(rows, tol=1e-6):
    rows = np.array(rows, dtype=float)
    if rows.size == 0:
        return rows
    rows = rows / np.max(np.abs(rows), axis=1, keepdims=True)
    lead = 0
    for r in range(rows.shape[0]):
        while lead < rows.shape[1]:
            pivot = r + int(np.argmax(np.abs(rows[r:, lead])))
            if abs(rows[pivot, lead]) > tol:
                break
            lead += 1
        else:
            break
        rows[[r, pivot]] = rows[[pivot, r]]
        rows[r] = rows[r] / rows[r, lead]
        for other in range(rows.shape[0]):
            if other != r:
                rows[other] = rows[other] - rows[other, lead] * rows[r]
        lead += 1
    rows[np.abs(rows) < tol] = 0.0
    return rows


def _combination(direction, names, tol=1e-3):
    text = ""
    for c, n in zip(direction, names):
        if abs(c) < tol:
            continue
        coef = "" if np.isclose(abs(c), 1.0, rtol=1e-3) else f"{abs(c):.3g} "
        if not text:
            text = ("-" if c < 0 else "") + coef + n
        else:
            text += (" - " if c < 0 else " + ") + coef + n
    return text or "(none)"


class AbstractStatistics(eqx.Module):
    """What a solve adds to its `Solution` beyond the estimate (`solution.statistics`): `Statistics`
    (linear least squares), and the statistics of the output-error fit, the refinement and the
    vehicle criteria."""

    def unidentified(self, names: tuple[str, ...]) -> tuple[str, ...]:
        """The parameter combinations the data leave undetermined; `()` where the solve does not say."""
        del names
        return ()


class Statistics(AbstractStatistics):
    r"""How well the data determine an estimate: the singular value decomposition of the column-scaled
    (weighted) regressor or Jacobian at the solution.

    **Fields:**

    - `condition_number`: largest over smallest singular value.
    - `rank`: numerical rank (singular values above `rcond` times the largest).
    - `singular_values`: descending.
    - `directions`: right singular vectors mapped back to parameter units, as rows, each scaled to
      unit max-norm; row `i` belongs to `singular_values[i]`, so the rows from `rank` on span what
      the data leave undetermined.
    - `residual_rms`: root-mean-square of the (weighted) residual at the solution.
    - `n_rows`: number of equations.
    """

    condition_number: Float[Array, ""]
    rank: Array
    singular_values: Float[Array, " n"]
    directions: Float[Array, "n n"]
    residual_rms: Float[Array, ""]
    n_rows: int = eqx.field(static=True)

    def unidentified(self, names: tuple[str, ...]) -> tuple[str, ...]:
        """The parameter combinations the data leave undetermined, e.g. `("theta1 + theta2 - theta3", "theta7")`.

        A basis of the null space in reduced row-echelon form, so the answer does not depend on
        how the SVD happened to rotate a multi-dimensional null space: each combination starts
        with a parameter of coefficient 1 that the others do not contain.
        """
        rank = int(self.rank)
        basis = _reduced_row_echelon(np.asarray(self.directions)[rank:])
        return tuple(_combination(row, names) for row in basis)


def _result_name(result) -> str | None:
    if np.ndim(result._value) != 0:
        return None
    message = optx.RESULTS[result]
    return "successful" if message == "" else message


class Solution(eqx.Module):
    r"""The result of a fit: the fitted model, its estimate with names and uncertainty, and how it went.

    **Fields:**

    - `model`: the fitted model (the input model with its free elements replaced).
    - `value`: the estimate, flattened in `parameters.names` order.
    - `parameters`: what was fitted (`Parameters`: names and selection).
    - `covariance`: Gauss-Newton covariance of `value`, $\hat\sigma^2 (J^\top J)^{+}$ with
      $\hat\sigma^2 = \lVert r \rVert^2 / (m - \operatorname{rank} J)$ (least squares), or the
      inverse Hessian approximation where the solver has one; NaN where not computed, and in the
      row and column of an unknown the data do not determine (a part in the null space of
      $J^\top J$; `dynax._fit._engine.undetermined_unknowns`). With residuals correlated in time
      it is too small: read it as a lower bound.
    - `std_errors`: square roots of its diagonal; `inf` for an unknown the data do not determine,
      0 for one frozen by a zero scale.
    - `result`: an `optimistix.RESULTS` code (`successful`, `max_steps_reached`, `nonlinear_divergence`, ...).
    - `loss`, `initial_loss`: $\tfrac12\lVert r\rVert^2$ (least squares) or the scalar loss, at the end and the start.
    - `steps`: iterations taken.
    - `n_residuals`: residual count (0 for a scalar loss).
    - `jacobian`: the Jacobian of the residuals in the solver's scaled unknowns $z$ ($p = p_0 + s
      \odot z$) at the solution, where a least-squares solver of the Gauss-Newton kind holds it
      (`LeastSquaresOptions(covariance=True)`); `None` otherwise.
    - `residuals`, `initial_residuals`: the residual vector $r$ at the solution and at the start
      (least squares; non-finite entries already replaced as `nonfinite` says); `None` for a scalar loss.
    - `statistics`: what the solve adds (an `AbstractStatistics`): for linear least squares a
      `Statistics` (the singular values and directions of the scaled problem, its condition number,
      rank and residual RMS), for the output-error fit, the refinement and the vehicle criteria
      their own; `None` otherwise.
    - `loss_history`, `time_history`: where the solver records them (`OptaxLBFGS`, the EM-free
      iteration): the loss after each step (entry 0 at the start) and the seconds since the start at
      which it was reached, NaN past the last step; `None` otherwise.
    """

    model: PyTree
    value: Float[Array, " n"]
    parameters: Parameters
    covariance: Float[Array, "n n"]
    std_errors: Float[Array, " n"]
    result: optx.RESULTS
    loss: Float[Array, ""]
    initial_loss: Float[Array, ""]
    steps: Array
    n_residuals: int = eqx.field(static=True, default=0)
    loss_history: Float[Array, " history"] | None = None
    time_history: Float[Array, " history"] | None = None
    jacobian: Float[Array, "m n"] | None = None
    residuals: Float[Array, " m"] | None = None
    initial_residuals: Float[Array, " m"] | None = None
    statistics: AbstractStatistics | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return self.parameters.names

    @property
    def succeeded(self) -> bool:
        return bool(self.result == optx.RESULTS.successful)

    @property
    def unidentified(self) -> tuple[str, ...]:
        """The parameter combinations the data leave undetermined (`Statistics.unidentified`); `()` when
        the solve formed no statistics."""
        return () if self.statistics is None else self.statistics.unidentified(self.names)

    @property
    def history(self) -> tuple[tuple[float, float], ...]:
        """`(seconds since start, loss)` at the start and after each step, where the solver records
        them (`loss_history`, `time_history`); `()` otherwise."""
        if self.loss_history is None or self.time_history is None:
            return ()
        losses, seconds = np.asarray(self.loss_history), np.asarray(self.time_history)
        keep = ~np.isnan(losses)
        return tuple((float(t), float(v)) for t, v in zip(seconds[keep], losses[keep]))

    def estimates(self) -> dict[str, float]:
        """`{name: value}`."""
        return self.parameters.named(self.value)

    def standard_errors(self) -> dict[str, float]:
        """`{name: standard error}`."""
        return self.parameters.named(self.std_errors)

    def to_json(self) -> dict:
        """A JSON-ready summary: estimates and standard errors by name, the result code and the losses."""
        return {
            "estimates": self.estimates(),
            "std_errors": self.standard_errors(),
            "result": _result_name(self.result),
            "steps": int(self.steps) if np.ndim(self.steps) == 0 else None,
            "loss": float(self.loss) if np.ndim(self.loss) == 0 else None,
            "initial_loss": float(self.initial_loss) if np.ndim(self.initial_loss) == 0 else None,
        }
