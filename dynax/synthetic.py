"""Synthetic measured data: `dynax.synthetic.HelicopterTruth`, `FlightController`, `generate_helicopter_flight`,
`helicopter_flight`, `synthetic_trajectory`, `demo_data`, `hidden_effect`, `multisine`, `filtered_noise`.

Truth simulators and data generators for demos, tests and docs, kept apart from the models that are
fitted (`dynax/_synthetic/`). The same names at the top level (`dynax.HelicopterTruth`, ...) still work.
"""

from ._synthetic import (
    DEMO_TRUTH_PHYSICAL as DEMO_TRUTH_PHYSICAL,
    demo_data as demo_data,
    filtered_noise as filtered_noise,
    FlightController as FlightController,
    fly as fly,
    generate_helicopter_flight as generate_helicopter_flight,
    helicopter_flight as helicopter_flight,
    hidden_effect as hidden_effect,
    HelicopterTruth as HelicopterTruth,
    multisine as multisine,
    synthetic_trajectory as synthetic_trajectory,
    WIND_NAMES as WIND_NAMES,
)
