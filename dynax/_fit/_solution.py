"""The one result type of every fit, after optimistix's `Solution`."""

import equinox as eqx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PyTree

from ._parameters import Parameters


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
      (`fit_least_squares(..., covariance=True)`); `None` otherwise.
    - `residuals`, `initial_residuals`: the residual vector $r$ at the solution and at the start
      (least squares; non-finite entries already replaced as `nonfinite` says); `None` for a scalar loss.
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

    @property
    def names(self) -> tuple[str, ...]:
        return self.parameters.names

    @property
    def succeeded(self) -> bool:
        return bool(self.result == optx.RESULTS.successful)

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
