from ._helicopter import (
    AbstractBodyModel as AbstractBodyModel,
)
from ._helicopter import (
    AccelerationModel as AccelerationModel,
)
from ._helicopter import (
    Helicopter as Helicopter,
)
from ._helicopter import (
    hover_state as hover_state,
)
from ._helicopter import (
    LinearVelocityModel as LinearVelocityModel,
)
from ._helicopter import (
    RICH_FEATURES as RICH_FEATURES,
)
from ._helicopter import (
    TEMPEST_FEATURES as TEMPEST_FEATURES,
)
from ._linear_axis import LinearAxis as LinearAxis
from ._system import AbstractManipulator as AbstractManipulator
from ._system import AbstractSystem as AbstractSystem
from ._two_link import (
    AbstractTwoLink as AbstractTwoLink,
)
from ._two_link import (
    Acrobot as Acrobot,
)
from ._two_link import (
    BASE_PARAMETER_NAMES as BASE_PARAMETER_NAMES,
)
from ._two_link import (
    base_parameters_from_physical as base_parameters_from_physical,
)
from ._two_link import (
    DoublePendulum as DoublePendulum,
)
