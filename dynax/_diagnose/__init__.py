"""Discrepancy diagnosis: what a model's simulation gets wrong, the cause, the extension, the gain."""

from ._candidates import default_candidates as default_candidates, LOOK_ALIKES as LOOK_ALIKES
from ._diagnose import diagnose as diagnose, Known as Known, Refit as Refit, Report as Report
from ._discovery import discover as discover, Discovery as Discovery, propose as propose, Proposal as Proposal
from ._library import feature_library as feature_library, search_period as search_period
from ._sparse import sparse_search as sparse_search, SparseFit as SparseFit, stlsq as stlsq
from ._report import write_report as write_report
from ._result import (
    DataSummary as DataSummary,
    ModelSummary as ModelSummary,
    ResidualTests as ResidualTests,
    SimErrorCurve as SimErrorCurve,
    Validation as Validation,
)
from ._residuals import Structure as Structure, structure_test as structure_test
from ._verdict import Verdict as Verdict
