"""Synthetic measured data: `dynax.synthetic.HelicopterTruth`, `FlightController`, `generate_helicopter_flight`,
`helicopter_flight` (and its `FlightPlan`), `synthetic_trajectory` (and its `Multisine` excitation), `demo_data`,
`hidden_effect`, `multisine`, `filtered_noise`.

Truth simulators and data generators for demos, tests and docs, kept apart from the models that are
fitted (`dynax/_synthetic/`). The same names at the top level (`dynax.HelicopterTruth`, ...) still work.
"""

from ._synthetic import (
    demo_data as demo_data,
)
from ._synthetic import (
    DEMO_TRUTH_PHYSICAL as DEMO_TRUTH_PHYSICAL,
)
from ._synthetic import (
    filtered_noise as filtered_noise,
)
from ._synthetic import (
    FlightController as FlightController,
)
from ._synthetic import (
    FlightPlan as FlightPlan,
)
from ._synthetic import (
    fly as fly,
)
from ._synthetic import (
    generate_helicopter_flight as generate_helicopter_flight,
)
from ._synthetic import (
    helicopter_flight as helicopter_flight,
)
from ._synthetic import (
    HelicopterTruth as HelicopterTruth,
)
from ._synthetic import (
    hidden_effect as hidden_effect,
)
from ._synthetic import (
    Multisine as Multisine,
)
from ._synthetic import (
    multisine as multisine,
)
from ._synthetic import (
    synthetic_trajectory as synthetic_trajectory,
)
from ._synthetic import (
    WIND_NAMES as WIND_NAMES,
)
