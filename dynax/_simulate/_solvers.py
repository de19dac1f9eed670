"""Solvers that diffrax does not ship."""

from typing import ClassVar

import diffrax
import numpy as np


class RK4(diffrax.AbstractERK):
    r"""The classical fourth-order Runge-Kutta method (MuJoCo's `RK4` integrator).

    diffrax ships no classical RK4; this is its Butcher tableau as a diffrax `AbstractERK`, for
    `FixedGrid(dynax.RK4(), substeps=1)` when a comparison with RK4-based simulators (MuJoCo,
    gymnasium) wants the same scheme. The embedded error weights (RK4 minus the midpoint rule) are
    only a crude estimate: prefer `Tsit5` or `Dopri5` for adaptive stepping.

    ??? cite

        W. Kutta, "Beitrag zur näherungsweisen Integration totaler Differentialgleichungen",
        Zeitschrift für Mathematik und Physik 46, 1901.
    """

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.ButcherTableau(
        c=np.array([0.5, 0.5, 1.0]),
        b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
        b_error=np.array([1 / 6, 1 / 3 - 1, 1 / 3, 1 / 6]),
        a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
    )
    interpolation_cls: ClassVar = diffrax.ThirdOrderHermitePolynomialInterpolation.from_k

    def order(self, terms):
        return 4
