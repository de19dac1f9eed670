from ._consistency import (
    check_consistency as check_consistency,
    Consistency as Consistency,
    consistency_conditions as consistency_conditions,
    consistent_least_squares as consistent_least_squares,
    ConsistentParametrisation as ConsistentParametrisation,
    InconsistentEstimateWarning as InconsistentEstimateWarning,
)
from ._defaults import (
    choose_filter as choose_filter,
    FilterChoice as FilterChoice,
    measurement_noise_std as measurement_noise_std,
    noise_floor_and_band as noise_floor_and_band,
)
from ._equations import Dynamic as Dynamic, Energy as Energy, Power as Power
from ._identify import identify as identify
from ._offsets import record_offsets as record_offsets, RecordOffsets as RecordOffsets
from ._record_friction import record_friction as record_friction, RecordFriction as RecordFriction
from ._least_squares import (
    IdentifiabilityError as IdentifiabilityError,
    least_squares as least_squares,
    poorly_determined as poorly_determined,
    PoorlyDeterminedWarning as PoorlyDeterminedWarning,
)
from ._result import (
    Identification as Identification,
    NoValidationWarning as NoValidationWarning,
    RecordsDisagreeWarning as RecordsDisagreeWarning,
    Stage as Stage,
    StageKind as StageKind,
)
from ._regressors import (
    dynamic_regressor as dynamic_regressor,
    energy_regressor as energy_regressor,
    friction_power_regressor as friction_power_regressor,
    parameter_names as parameter_names,
    with_friction as with_friction,
)
from ._simulation_fit import (
    fit_simulation_error as fit_simulation_error,
    SimulationFit as SimulationFit,
    OutputErrorStatistics as OutputErrorStatistics,
)
from ._refine import (
    ConsistentSystem as ConsistentSystem,
    refine_by_simulation as refine_by_simulation,
    RefinementStatistics as RefinementStatistics,
)
from ._validation import (
    held_out_error as held_out_error,
    HeldOutError as HeldOutError,
    split_for_validation as split_for_validation,
)
