"""Moved to `dynax/_synthetic/` (public as `dynax.synthetic`); this old private path re-exports it."""

from .._synthetic import helicopter_flight, multisine, synthetic_trajectory  # noqa: F401
