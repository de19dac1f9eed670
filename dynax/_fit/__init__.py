"""The fitting engine: one way to say what to fit (`Parameters`), one solve (`fit_least_squares`,
`fit_minimise`), one result (`Solution`). Identification and diagnosis are built on it."""

from ._covariance import (
    clustered_covariance as clustered_covariance,
    jackknife_covariance as jackknife_covariance,
    serial_covariance as serial_covariance,
)
from ._engine import fit_least_squares as fit_least_squares, fit_minimise as fit_minimise
from ._levenberg_marquardt import levenberg_marquardt as levenberg_marquardt, StrictTrustRegion as StrictTrustRegion
from ._parameters import Parameters as Parameters
from ._solution import Solution as Solution, Statistics as Statistics
from ._solvers import History as History, monitor as monitor, notify as notify, OptaxLBFGS as OptaxLBFGS
