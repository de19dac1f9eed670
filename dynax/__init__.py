"""dynax: differentiable dynamics, system identification, discrepancy diagnosis and control in JAX."""

from ._fit import (
    fit_least_squares as fit_least_squares,
    fit_minimise as fit_minimise,
    Parameters as Parameters,
    Solution as Solution,
    Statistics as Statistics,
)
from ._identify import (
    Consistency as Consistency,
    held_out_error as held_out_error,
    HeldOutError as HeldOutError,
    InconsistentEstimateWarning as InconsistentEstimateWarning,
    Dynamic as Dynamic,
    Energy as Energy,
    fit_simulation_error as fit_simulation_error,
    IdentifiabilityError as IdentifiabilityError,
    Identification as Identification,
    Stage as Stage,
    StageKind as StageKind,
    identify as identify,
    least_squares as least_squares,
    PoorlyDeterminedWarning as PoorlyDeterminedWarning,
    NoValidationWarning as NoValidationWarning,
    RecordsDisagreeWarning as RecordsDisagreeWarning,
    Power as Power,
    SimulationFit as SimulationFit,
)
from ._model._extensions import (
    AbstractJointTerm as AbstractJointTerm,
    AbstractTerm as AbstractTerm,
    BodyBias as BodyBias,
    BodyQuadraticDrag as BodyQuadraticDrag,
    CoulombFriction as CoulombFriction,
    Extended as Extended,
    InputDelay as InputDelay,
    InputGain as InputGain,
    InputLag as InputLag,
    InputOffset as InputOffset,
    JointSpring as JointSpring,
    QuadraticDrag as QuadraticDrag,
    RotorDrag as RotorDrag,
    RotorInertia as RotorInertia,
    ViscousFriction as ViscousFriction,
    Wind as Wind,
)
from ._identify._vehicle import (
    Backprop as Backprop,
    fit_vehicle as fit_vehicle,
    FrequencyDomain as FrequencyDomain,
    Lagged as Lagged,
    OneStep as OneStep,
    VehicleFit as VehicleFit,
)
from ._model import (
    AbstractBodyModel as AbstractBodyModel,
    AbstractManipulator as AbstractManipulator,
    AbstractSystem as AbstractSystem,
    AccelerationModel as AccelerationModel,
    Acrobot as Acrobot,
    DoublePendulum as DoublePendulum,
    Helicopter as Helicopter,
    LinearAxis as LinearAxis,
    LinearVelocityModel as LinearVelocityModel,
)
from ._data import (
    backward_difference as backward_difference,
    butterworth_filtfilt as butterworth_filtfilt,
    central_difference as central_difference,
    resample as resample,
    savitzky_golay as savitzky_golay,
    check_records as check_records,
    DataCheck as DataCheck,
    DataWarning as DataWarning,
    exclude_stretches as exclude_stretches,
    load_trajectory as load_trajectory,
    save_trajectory as save_trajectory,
    Trajectory as Trajectory,
)
from ._diagnose import (
    default_candidates as default_candidates,
    diagnose as diagnose,
    discover as discover,
    Discovery as Discovery,
    Known as Known,
    Refit as Refit,
    Report as Report,
    Verdict as Verdict,
)
# Control beyond the pipeline verbs (the acrobot leaderboard, from-rest swing-up) lives in `dynax.control`.
from . import control as control
from ._control._from_rest import load_controller as load_controller
# Synthetic data (truth simulators, data generators) lives in `dynax.synthetic`; the top-level names stay.
from . import synthetic as synthetic
from ._metrics import (
    kfold_splits as kfold_splits,
    leave_one_out_splits as leave_one_out_splits,
    aic as aic,
    cross_correlation_test as cross_correlation_test,
    cross_validate as cross_validate,
    fpe as fpe,
    nrmse_fit as nrmse_fit,
    whiteness_test as whiteness_test,
)
from ._plots import plot_compare as plot_compare, plot_error_horizon as plot_error_horizon, plot_residuals as plot_residuals
from ._precision import PrecisionWarning as PrecisionWarning
from ._progress import ProgressBar as ProgressBar
from ._errors import DataError as DataError, UsageError as UsageError
from ._distributed import initialize_distributed as initialize_distributed
from ._sim_error import simulation_error as simulation_error, SimulationError as SimulationError
from ._solvers import RK4 as RK4
from ._simulate import Adaptive as Adaptive, FixedGrid as FixedGrid, Simulation as Simulation, simulate as simulate
from ._data._flight import (
    usable_segments as usable_segments,
    FlightChecks as FlightChecks,
    inspect_flight as inspect_flight,
    load_flight as load_flight,
)
from ._model._quadrotor import ConstantVelocity as ConstantVelocity, initial_quadrotor as initial_quadrotor, Quadrotor as Quadrotor
from ._identify._vehicle._quadrotor import fit_quadrotor as fit_quadrotor
from ._identify._vehicle._model_file import load_model as load_model, save_model as save_model
from ._predict import flight_error as flight_error, FlightError as FlightError, predict_ahead as predict_ahead

from ._version import __version__ as __version__
