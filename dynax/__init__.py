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
from ._identify._vehicle import (
    Backprop as Backprop,
    fit_vehicle as fit_vehicle,
    FrequencyDomain as FrequencyDomain,
    frequency_responses as frequency_responses,
    Lagged as Lagged,
    lagged_loss as lagged_loss,
    OneStep as OneStep,
    prediction_error as prediction_error,
    VehicleFit as VehicleFit,
)
from ._model import (
    AbstractBodyModel as AbstractBodyModel,
    AbstractManipulator as AbstractManipulator,
    AccelerationModel as AccelerationModel,
    FlightController as FlightController,
    generate_helicopter_flight as generate_helicopter_flight,
    Helicopter as Helicopter,
    HelicopterTruth as HelicopterTruth,
    hover_state as hover_state,
    LinearVelocityModel as LinearVelocityModel,
    RICH_FEATURES as RICH_FEATURES,
    TEMPEST_FEATURES as TEMPEST_FEATURES,
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
