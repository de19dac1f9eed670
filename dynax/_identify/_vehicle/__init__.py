"""Vehicle dynamics learning (Abbeel, Ganapathi and Ng 2005): one-step, frequency-domain, lagged, backprop."""

from ._criteria import (
    auto_stride as auto_stride,
    EMFree as EMFree,
    Backprop as Backprop,
    fit_backprop as fit_backprop,
    fit_lagged as fit_lagged,
    fit_one_step as fit_one_step,
    Lagged as Lagged,
    lagged_loss_gradient_norm as lagged_loss_gradient_norm,
    lagged_loss_of as lagged_loss_of,
    OneStep as OneStep,
    VehicleFit as VehicleFit,
)
from ._windows import lagged_loss as lagged_loss, prediction_error as prediction_error, STATE_GROUPS as STATE_GROUPS
from ._fit import (
    CRITERIA as CRITERIA,
    fit_vehicle as fit_vehicle,
    initial_helicopter as initial_helicopter,
    model_from_json as model_from_json,
    model_to_json as model_to_json,
)
from ._frequency import fit_frequency as fit_frequency, FrequencyDomain as FrequencyDomain, frequency_responses as frequency_responses
