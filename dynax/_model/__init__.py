from ._linear_axis import LinearAxis as LinearAxis
from ._system import AbstractManipulator as AbstractManipulator, AbstractSystem as AbstractSystem
from ._two_link import (
    AbstractTwoLink as AbstractTwoLink,
    Acrobot as Acrobot,
    BASE_PARAMETER_NAMES as BASE_PARAMETER_NAMES,
    base_parameters_from_physical as base_parameters_from_physical,
    DoublePendulum as DoublePendulum,
)
from ._helicopter import (
    AbstractBodyModel as AbstractBodyModel,
    AccelerationModel as AccelerationModel,
    Helicopter as Helicopter,
    hover_state as hover_state,
    LinearVelocityModel as LinearVelocityModel,
    RICH_FEATURES as RICH_FEATURES,
    TEMPEST_FEATURES as TEMPEST_FEATURES,
)
