"""Model extensions: candidate physical effects that compose with a nominal system (see `Extended`)."""

from ._discovered import Discovered as Discovered, Feature as Feature
from ._extended import Extended as Extended
from ._inputs import (
    AbstractInputTerm as AbstractInputTerm,
    InputDelay as InputDelay,
    InputGain as InputGain,
    InputLag as InputLag,
    InputOffset as InputOffset,
)
from ._terms import (
    AbstractJointTerm as AbstractJointTerm,
    AbstractTerm as AbstractTerm,
    CoulombFriction as CoulombFriction,
    JointSpring as JointSpring,
    QuadraticDrag as QuadraticDrag,
    RotorInertia as RotorInertia,
    ViscousFriction as ViscousFriction,
)
from ._vehicle_terms import (
    AbstractVehicleTerm as AbstractVehicleTerm,
    BodyBias as BodyBias,
    BodyQuadraticDrag as BodyQuadraticDrag,
    RotorDrag as RotorDrag,
    Wind as Wind,
)
