"""dynax: differentiable dynamics, system identification, discrepancy diagnosis and control in JAX."""

from ._model import (
    AbstractManipulator as AbstractManipulator,
    AbstractSystem as AbstractSystem,
    Acrobot as Acrobot,
    base_parameters_from_physical as base_parameters_from_physical,
    DoublePendulum as DoublePendulum,
    LinearAxis as LinearAxis,
)
from ._simulate import Adaptive as Adaptive, FixedGrid as FixedGrid, Simulation as Simulation, simulate as simulate

__version__ = "0.1.0"
