"""Model extensions: candidate physical effects that compose with a nominal system (see `Extended`)."""

from ._discovered import Discovered as Discovered
from ._discovered import Feature as Feature
from ._extended import Extended as Extended
from ._inputs import (
    AbstractInputTerm as AbstractInputTerm,
)
from ._inputs import (
    InputDelay as InputDelay,
)
from ._inputs import (
    InputGain as InputGain,
)
from ._inputs import (
    InputLag as InputLag,
)
from ._inputs import (
    InputOffset as InputOffset,
)
from ._inputs import (
    MotorDelay as MotorDelay,
)
from ._inputs import (
    MotorLag as MotorLag,
)
from ._stiction import Stiction as Stiction
from ._terms import (
    AbstractJointTerm as AbstractJointTerm,
)
from ._terms import (
    AbstractTerm as AbstractTerm,
)
from ._terms import (
    CoulombFriction as CoulombFriction,
)
from ._terms import (
    JointSpring as JointSpring,
)
from ._terms import (
    QuadraticDrag as QuadraticDrag,
)
from ._terms import (
    RotorInertia as RotorInertia,
)
from ._terms import (
    ViscousFriction as ViscousFriction,
)
from ._vehicle_terms import (
    AbstractVehicleTerm as AbstractVehicleTerm,
)
from ._vehicle_terms import (
    BatterySag as BatterySag,
)
from ._vehicle_terms import (
    BodyBias as BodyBias,
)
from ._vehicle_terms import (
    BodyQuadraticDrag as BodyQuadraticDrag,
)
from ._vehicle_terms import (
    GroundEffect as GroundEffect,
)
from ._vehicle_terms import (
    PlanarRotorDrag as PlanarRotorDrag,
)
from ._vehicle_terms import (
    RotorDrag as RotorDrag,
)
from ._vehicle_terms import (
    Wind as Wind,
)
