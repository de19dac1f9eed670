"""dynax: differentiable dynamics, system identification, discrepancy diagnosis and control in JAX."""

# Control beyond the pipeline verbs (the acrobot leaderboard, from-rest swing-up) lives in `dynax.control`.
from . import control as control

# Synthetic data (truth simulators, data generators) lives in `dynax.synthetic`; the top-level names stay.
from . import synthetic as synthetic
from ._data import (
    butterworth_filtfilt as butterworth_filtfilt,
)
from ._data import (
    central_difference as central_difference,
)
from ._data import (
    check_records as check_records,
)
from ._data import (
    DataWarning as DataWarning,
)
from ._data import (
    exclude_stretches as exclude_stretches,
)
from ._data import (
    load_trajectory as load_trajectory,
)
from ._data import (
    resample as resample,
)
from ._data import (
    Sampling as Sampling,
)
from ._data import (
    save_trajectory as save_trajectory,
)
from ._data import (
    savitzky_golay as savitzky_golay,
)
from ._data import (
    Trajectory as Trajectory,
)
from ._data._flight import (
    inspect_flight as inspect_flight,
)
from ._data._flight import (
    load_flight as load_flight,
)
from ._data._flight import (
    usable_segments as usable_segments,
)
from ._diagnose import (
    default_candidates as default_candidates,
)
from ._diagnose import (
    diagnose as diagnose,
)
from ._diagnose import (
    discover as discover,
)
from ._diagnose import (
    Horizons as Horizons,
)
from ._diagnose import (
    Known as Known,
)
from ._diagnose import (
    Refit as Refit,
)
from ._diagnose import (
    Report as Report,
)
from ._diagnose import (
    Selection as Selection,
)
from ._diagnose import (
    Verdict as Verdict,
)
from ._distributed import initialize_distributed as initialize_distributed
from ._errors import DataError as DataError
from ._errors import UsageError as UsageError
from ._fit import (
    fit_least_squares as fit_least_squares,
)
from ._fit import (
    fit_minimise as fit_minimise,
)
from ._fit import (
    LeastSquaresOptions as LeastSquaresOptions,
)
from ._fit import (
    Parameters as Parameters,
)
from ._fit import (
    Solution as Solution,
)
from ._identify import (
    AbstractMethod as AbstractMethod,
)
from ._identify import (
    Dynamic as Dynamic,
)
from ._identify import (
    Energy as Energy,
)
from ._identify import (
    fit_simulation_error as fit_simulation_error,
)
from ._identify import (
    held_out_error as held_out_error,
)
from ._identify import (
    IdentifiabilityError as IdentifiabilityError,
)
from ._identify import (
    Identification as Identification,
)
from ._identify import (
    identify as identify,
)
from ._identify import (
    InconsistentEstimateWarning as InconsistentEstimateWarning,
)
from ._identify import (
    NoValidationWarning as NoValidationWarning,
)
from ._identify import (
    PoorlyDeterminedWarning as PoorlyDeterminedWarning,
)
from ._identify import (
    Power as Power,
)
from ._identify import (
    RecordsDisagreeWarning as RecordsDisagreeWarning,
)
from ._identify import (
    SimulationFit as SimulationFit,
)
from ._identify import (
    Stage as Stage,
)
from ._identify import (
    StageKind as StageKind,
)
from ._identify import (
    Validate as Validate,
)
from ._identify._method import FitSettings as FitSettings
from ._identify._vehicle import (
    Backprop as Backprop,
)
from ._identify._vehicle import (
    fit_vehicle as fit_vehicle,
)
from ._identify._vehicle import (
    FrequencyDomain as FrequencyDomain,
)
from ._identify._vehicle import (
    Lagged as Lagged,
)
from ._identify._vehicle import (
    OneStep as OneStep,
)
from ._identify._vehicle._model_file import load_model as load_model
from ._identify._vehicle._model_file import save_model as save_model
from ._identify._vehicle._quadrotor import fit_quadrotor as fit_quadrotor
from ._model import (
    AbstractManipulator as AbstractManipulator,
)
from ._model import (
    AbstractSystem as AbstractSystem,
)
from ._model import (
    AccelerationModel as AccelerationModel,
)
from ._model import (
    Acrobot as Acrobot,
)
from ._model import (
    DoublePendulum as DoublePendulum,
)
from ._model import (
    Helicopter as Helicopter,
)
from ._model import (
    LinearAxis as LinearAxis,
)
from ._model import (
    LinearVelocityModel as LinearVelocityModel,
)
from ._model._extensions import (
    AbstractJointTerm as AbstractJointTerm,
)
from ._model._extensions import (
    AbstractTerm as AbstractTerm,
)
from ._model._extensions import (
    BatterySag as BatterySag,
)
from ._model._extensions import (
    BodyBias as BodyBias,
)
from ._model._extensions import (
    BodyQuadraticDrag as BodyQuadraticDrag,
)
from ._model._extensions import (
    CoulombFriction as CoulombFriction,
)
from ._model._extensions import (
    Extended as Extended,
)
from ._model._extensions import (
    GroundEffect as GroundEffect,
)
from ._model._extensions import (
    InputDelay as InputDelay,
)
from ._model._extensions import (
    InputGain as InputGain,
)
from ._model._extensions import (
    InputLag as InputLag,
)
from ._model._extensions import (
    InputOffset as InputOffset,
)
from ._model._extensions import (
    JointSpring as JointSpring,
)
from ._model._extensions import (
    MotorDelay as MotorDelay,
)
from ._model._extensions import (
    QuadraticDrag as QuadraticDrag,
)
from ._model._extensions import (
    RotorDrag as RotorDrag,
)
from ._model._extensions import (
    RotorInertia as RotorInertia,
)
from ._model._extensions import (
    Stiction as Stiction,
)
from ._model._extensions import (
    ViscousFriction as ViscousFriction,
)
from ._model._extensions import (
    Wind as Wind,
)
from ._model._quadrotor import (
    ConstantVelocity as ConstantVelocity,
)
from ._model._quadrotor import (
    Quadrotor as Quadrotor,
)
from ._precision import PrecisionWarning as PrecisionWarning
from ._simulate import Adaptive as Adaptive
from ._simulate import FixedGrid as FixedGrid
from ._simulate import flight_error as flight_error
from ._simulate import predict_ahead as predict_ahead
from ._simulate import RK4 as RK4
from ._simulate import simulate as simulate
from ._simulate import simulation_error as simulation_error
from ._simulate import SimulationError as SimulationError
from ._validate import (
    aic as aic,
)
from ._validate import (
    cross_correlation_test as cross_correlation_test,
)
from ._validate import (
    cross_validate as cross_validate,
)
from ._validate import (
    fpe as fpe,
)
from ._validate import (
    kfold_splits as kfold_splits,
)
from ._validate import (
    leave_one_out_splits as leave_one_out_splits,
)
from ._validate import (
    nrmse_fit as nrmse_fit,
)
from ._validate import (
    plot_compare as plot_compare,
)
from ._validate import (
    plot_error_horizon as plot_error_horizon,
)
from ._validate import (
    plot_residuals as plot_residuals,
)
from ._validate import (
    whiteness_test as whiteness_test,
)
from ._version import __version__ as __version__
