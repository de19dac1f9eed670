from ._consistency import (
    check_consistency as check_consistency,
)
from ._consistency import (
    Consistency as Consistency,
)
from ._consistency import (
    consistency_conditions as consistency_conditions,
)
from ._consistency import (
    consistent_least_squares as consistent_least_squares,
)
from ._consistency import (
    ConsistentParametrisation as ConsistentParametrisation,
)
from ._consistency import (
    InconsistentEstimateWarning as InconsistentEstimateWarning,
)
from ._equations import Dynamic as Dynamic
from ._equations import Energy as Energy
from ._equations import Power as Power
from ._identify import identify as identify
from ._least_squares import (
    IdentifiabilityError as IdentifiabilityError,
)
from ._least_squares import (
    least_squares as least_squares,
)
from ._least_squares import (
    poorly_determined as poorly_determined,
)
from ._least_squares import (
    PoorlyDeterminedWarning as PoorlyDeterminedWarning,
)
from ._method import AbstractMethod as AbstractMethod
from ._method import FitSettings as FitSettings
from ._offsets import record_offsets as record_offsets
from ._offsets import RecordOffsets as RecordOffsets
from ._record_friction import record_friction as record_friction
from ._record_friction import RecordFriction as RecordFriction
from ._refine import (
    ConsistentSystem as ConsistentSystem,
)
from ._refine import (
    refine_by_simulation as refine_by_simulation,
)
from ._refine import (
    RefinementStatistics as RefinementStatistics,
)
from ._regressors import (
    dynamic_regressor as dynamic_regressor,
)
from ._regressors import (
    energy_regressor as energy_regressor,
)
from ._regressors import (
    friction_power_regressor as friction_power_regressor,
)
from ._regressors import (
    parameter_names as parameter_names,
)
from ._regressors import (
    with_friction as with_friction,
)
from ._result import (
    Identification as Identification,
)
from ._result import (
    NoValidationWarning as NoValidationWarning,
)
from ._result import (
    RecordsDisagreeWarning as RecordsDisagreeWarning,
)
from ._result import (
    Stage as Stage,
)
from ._result import (
    StageKind as StageKind,
)
from ._simulation_fit import (
    fit_simulation_error as fit_simulation_error,
)
from ._simulation_fit import (
    OutputErrorStatistics as OutputErrorStatistics,
)
from ._simulation_fit import (
    SimulationFit as SimulationFit,
)
from ._static_friction import (
    JointStaticFriction as JointStaticFriction,
)
from ._static_friction import (
    RestUnderLoad as RestUnderLoad,
)
from ._static_friction import (
    StaticFriction as StaticFriction,
)
from ._validation import (
    held_out_error as held_out_error,
)
from ._validation import (
    split_for_validation as split_for_validation,
)
from ._validation import (
    Validate as Validate,
)
