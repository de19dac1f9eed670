"""Moved to `dynax/_synthetic/` (public as `dynax.synthetic`); this old private path re-exports it."""

from .._synthetic import FlightController, generate_helicopter_flight, HelicopterTruth  # noqa: F401
