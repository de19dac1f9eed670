"""Synthetic measured data: truth simulators, excitation and the data generators of the demo, tests and docs.

Nothing here is a model to fit: it makes the data a model is fitted to (public as `dynax.synthetic`).
"""

from ._acrobot_demo import (
    demo_data as demo_data,
)
from ._acrobot_demo import (
    DEMO_TRUTH_PHYSICAL as DEMO_TRUTH_PHYSICAL,
)
from ._acrobot_demo import (
    hidden_effect as hidden_effect,
)
from ._excitation import filtered_noise as filtered_noise
from ._excitation import Multisine as Multisine
from ._excitation import multisine as multisine
from ._flight import (
    FlightPlan as FlightPlan,
)
from ._flight import (
    fly as fly,
)
from ._flight import (
    generate_helicopter_flight as generate_helicopter_flight,
)
from ._flight import (
    helicopter_flight as helicopter_flight,
)
from ._flight_controller import FlightController as FlightController
from ._helicopter_truth import HelicopterTruth as HelicopterTruth
from ._helicopter_truth import WIND_NAMES as WIND_NAMES
from ._trajectory import synthetic_trajectory as synthetic_trajectory
