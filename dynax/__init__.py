"""dynax: differentiable dynamics, system identification, discrepancy diagnosis and control in JAX."""

from ._identify import (
    Dynamic as Dynamic,
    dynamic_regressor as dynamic_regressor,
    Energy as Energy,
    energy_regressor as energy_regressor,
    fit_simulation_error as fit_simulation_error,
    friction_power_regressor as friction_power_regressor,
    IdentifiabilityError as IdentifiabilityError,
    Identification as Identification,
    identify as identify,
    least_squares as least_squares,
    LeastSquaresFit as LeastSquaresFit,
    parameter_names as parameter_names,
    Power as Power,
    SimulationFit as SimulationFit,
    SimulationFitResult as SimulationFitResult,
    with_friction as with_friction,
)
from ._model._extensions import (
    AbstractInputTerm as AbstractInputTerm,
    AbstractJointTerm as AbstractJointTerm,
    AbstractTerm as AbstractTerm,
    CoulombFriction as CoulombFriction,
    Extended as Extended,
    InputDelay as InputDelay,
    InputGain as InputGain,
    InputLag as InputLag,
    InputOffset as InputOffset,
    JointSpring as JointSpring,
    QuadraticDrag as QuadraticDrag,
    RotorInertia as RotorInertia,
    ViscousFriction as ViscousFriction,
)
from ._model import (
    AbstractManipulator as AbstractManipulator,
    AbstractSystem as AbstractSystem,
    Acrobot as Acrobot,
    base_parameters_from_physical as base_parameters_from_physical,
    DoublePendulum as DoublePendulum,
    LinearAxis as LinearAxis,
)
from ._data import (
    butterworth_filtfilt as butterworth_filtfilt,
    central_difference as central_difference,
    load_trajectory as load_trajectory,
    resample as resample,
    save_trajectory as save_trajectory,
    savitzky_golay as savitzky_golay,
    Trajectory as Trajectory,
)
from ._errors import DataError as DataError, UsageError as UsageError
from ._sim_error import simulation_error as simulation_error, SimulationError as SimulationError
from ._solvers import RK4 as RK4
from ._simulate import Adaptive as Adaptive, FixedGrid as FixedGrid, Simulation as Simulation, simulate as simulate

__version__ = "0.1.0"
