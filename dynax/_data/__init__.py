from ._columns import columns_for as columns_for, SYSTEM_COLUMNS as SYSTEM_COLUMNS
from ._derivatives import (
    backward_difference as backward_difference,
    butterworth_filtfilt as butterworth_filtfilt,
    central_difference as central_difference,
    resample as resample,
    savitzky_golay as savitzky_golay,
)
from ._io import load_trajectory as load_trajectory, parse_assignments as parse_assignments, save_trajectory as save_trajectory
from ._trajectory import Trajectory as Trajectory
from ._sampling import check_time_stamps as check_time_stamps, split_at_gaps as split_at_gaps
from ._sanity import (
    check_record as check_record,
    check_records as check_records,
    Check as Check,
    DataCheck as DataCheck,
    DataWarning as DataWarning,
    exclude_stretches as exclude_stretches,
    Finding as Finding,
    parse_exclude as parse_exclude,
)
