from ._identify import (
    Dynamic as Dynamic,
    Energy as Energy,
    identify as identify,
    Identification as Identification,
    Power as Power,
)
from ._least_squares import (
    IdentifiabilityError as IdentifiabilityError,
    least_squares as least_squares,
    LeastSquaresFit as LeastSquaresFit,
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
    SimulationFitResult as SimulationFitResult,
)
