from ._columns import columns_for as columns_for
from ._columns import SYSTEM_COLUMNS as SYSTEM_COLUMNS
from ._derivatives import (
    backward_difference as backward_difference,
)
from ._derivatives import (
    butterworth_filtfilt as butterworth_filtfilt,
)
from ._derivatives import (
    central_difference as central_difference,
)
from ._derivatives import (
    resample as resample,
)
from ._derivatives import (
    savitzky_golay as savitzky_golay,
)
from ._io import (
    load_trajectory as load_trajectory,
)
from ._io import (
    parse_assignments as parse_assignments,
)
from ._io import (
    Sampling as Sampling,
)
from ._io import (
    save_trajectory as save_trajectory,
)
from ._rest import Rest as Rest
from ._rest import rest_stretches as rest_stretches
from ._rest import speed_noise_at_rest as speed_noise_at_rest
from ._rest import speeds_zeroed_at_rest as speeds_zeroed_at_rest
from ._sampling import check_time_stamps as check_time_stamps
from ._sampling import split_at_gaps as split_at_gaps
from ._sanity import (
    Check as Check,
)
from ._sanity import (
    check_record as check_record,
)
from ._sanity import (
    check_records as check_records,
)
from ._sanity import (
    DataCheck as DataCheck,
)
from ._sanity import (
    DataWarning as DataWarning,
)
from ._sanity import (
    exclude_stretches as exclude_stretches,
)
from ._sanity import (
    Finding as Finding,
)
from ._sanity import (
    parse_exclude as parse_exclude,
)
from ._trajectory import Trajectory as Trajectory
