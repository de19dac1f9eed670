"""Vehicle dynamics learning (Abbeel, Ganapathi and Ng 2005): one-step, frequency-domain, lagged, backprop."""

from ._criteria import (
    auto_stride as auto_stride,
)
from ._criteria import (
    Backprop as Backprop,
)
from ._criteria import (
    EMFree as EMFree,
)
from ._criteria import (
    fit_backprop as fit_backprop,
)
from ._criteria import (
    fit_lagged as fit_lagged,
)
from ._criteria import (
    fit_one_step as fit_one_step,
)
from ._criteria import (
    Lagged as Lagged,
)
from ._criteria import (
    lagged_loss_gradient_norm as lagged_loss_gradient_norm,
)
from ._criteria import (
    lagged_loss_of as lagged_loss_of,
)
from ._criteria import (
    OneStep as OneStep,
)
from ._criteria import (
    recorded_loss as recorded_loss,
)
from ._criteria import (
    VehicleStatistics as VehicleStatistics,
)
from ._fit import (
    CRITERIA as CRITERIA,
)
from ._fit import (
    fit_vehicle as fit_vehicle,
)
from ._fit import (
    initial_helicopter as initial_helicopter,
)
from ._fit import (
    model_from_json as model_from_json,
)
from ._fit import (
    model_to_json as model_to_json,
)
from ._frequency import (
    fit_frequency as fit_frequency,
)
from ._frequency import (
    frequency_responses as frequency_responses,
)
from ._frequency import (
    FrequencyDomain as FrequencyDomain,
)
from ._windows import lagged_loss as lagged_loss
from ._windows import prediction_error as prediction_error
from ._windows import STATE_GROUPS as STATE_GROUPS
