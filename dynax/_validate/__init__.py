"""Validation: fit percentages, residual whiteness and cross-correlation tests, information criteria,
cross-validation splits, the predictability horizon and the comparison figures."""

from ._horizon import DEFAULT_FRACTION as DEFAULT_FRACTION
from ._horizon import Horizon as Horizon
from ._horizon import position_spread as position_spread
from ._horizon import predictability_horizon as predictability_horizon
from ._horizon import relative_position_error as relative_position_error
from ._metrics import aic as aic
from ._metrics import cross_correlation_test as cross_correlation_test
from ._metrics import cross_validate as cross_validate
from ._metrics import CrossCorrelationTest as CrossCorrelationTest
from ._metrics import fpe as fpe
from ._metrics import horizon_fit as horizon_fit
from ._metrics import kfold_splits as kfold_splits
from ._metrics import leave_one_out_splits as leave_one_out_splits
from ._metrics import nrmse_fit as nrmse_fit
from ._metrics import whiteness_test as whiteness_test
from ._metrics import WhitenessTest as WhitenessTest
from ._plots import plot_compare as plot_compare
from ._plots import plot_error_horizon as plot_error_horizon
from ._plots import plot_residuals as plot_residuals
