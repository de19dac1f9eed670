"""Discrepancy diagnosis: what a model's simulation gets wrong, the cause, the extension, the gain."""

from ._at_rest import JointRests as JointRests
from ._at_rest import rests_under_load as rests_under_load
from ._candidates import default_candidates as default_candidates
from ._candidates import LOOK_ALIKES as LOOK_ALIKES
from ._diagnose import diagnose as diagnose
from ._diagnose import Known as Known
from ._diagnose import Refit as Refit
from ._diagnose import Report as Report
from ._discovery import discover as discover
from ._discovery import Discovery as Discovery
from ._discovery import DiscoverySearch as DiscoverySearch
from ._discovery import HeldOutTest as HeldOutTest
from ._discovery import Proposal as Proposal
from ._discovery import propose as propose
from ._library import feature_library as feature_library
from ._library import search_period as search_period
from ._report import write_report as write_report
from ._residuals import Structure as Structure
from ._residuals import structure_test as structure_test
from ._result import (
    DataSummary as DataSummary,
)
from ._result import (
    FlightScores as FlightScores,
)
from ._result import (
    ModelSummary as ModelSummary,
)
from ._result import (
    ResidualTests as ResidualTests,
)
from ._result import (
    Validation as Validation,
)
from ._settings import Horizons as Horizons
from ._settings import Selection as Selection
from ._sparse import FeatureRegression as FeatureRegression
from ._sparse import sparse_search as sparse_search
from ._sparse import SparseSearch as SparseSearch
from ._sparse import SparseStatistics as SparseStatistics
from ._sparse import Stability as Stability
from ._sparse import stlsq as stlsq
from ._verdict import Verdict as Verdict
