"""The fitting engine: one way to say what to fit (`Parameters`), one solve (`fit_least_squares`,
`fit_minimise`), one result (`Solution`). Identification and diagnosis are built on it."""

from ._covariance import (
    clustered_covariance as clustered_covariance,
)
from ._covariance import (
    jackknife_covariance as jackknife_covariance,
)
from ._covariance import (
    serial_covariance as serial_covariance,
)
from ._engine import fit_least_squares as fit_least_squares
from ._engine import fit_minimise as fit_minimise
from ._engine import LeastSquaresOptions as LeastSquaresOptions
from ._levenberg_marquardt import levenberg_marquardt as levenberg_marquardt
from ._levenberg_marquardt import StrictTrustRegion as StrictTrustRegion
from ._parameters import Parameters as Parameters
from ._solution import AbstractStatistics as AbstractStatistics
from ._solution import Solution as Solution
from ._solution import Statistics as Statistics
from ._solvers import History as History
from ._solvers import monitor as monitor
from ._solvers import notify as notify
from ._solvers import OptaxLBFGS as OptaxLBFGS
