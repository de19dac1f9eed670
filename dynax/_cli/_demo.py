"""`dynax demo`: the main job on the embedded default, an acrobot with an effect hidden in its data."""

import argparse
import pathlib
import time

import numpy as np

from .._errors import UsageError
from ._output import staged_directory, write_json

# (cause, where, term factory from a size in [0, 1]): the effects the demo hides, picked by --seed.
_EFFECTS = (
    ("coulomb_friction", "q2", lambda s: ("CoulombFriction", 1, 0.15 + 0.25 * s)),
    ("rotor_inertia", "q2", lambda s: ("RotorInertia", 1, 0.08 + 0.12 * s)),
    ("input_delay", "tau2", lambda s: ("InputDelay", 0, 0.03 + 0.03 * s)),
    ("quadratic_drag", "q2", lambda s: ("QuadraticDrag", 1, 0.08 + 0.08 * s)),
    ("input_lag", "tau2", lambda s: ("InputLag", 0, 0.04 + 0.04 * s)),
    ("coulomb_friction", "q1", lambda s: ("CoulombFriction", 0, 0.2 + 0.3 * s)),
    ("input_offset", "tau2", lambda s: ("InputOffset", 0, 0.15 + 0.15 * s)),
)


def hidden_effect(seed: int):
    """The term the demo hides for `seed`: the effect cycles with the seed, its size is drawn from it."""
    from .._model import _extensions

    rng = np.random.default_rng(seed)
    cause, where, factory = _EFFECTS[seed % len(_EFFECTS)]
    name, index, size = factory(rng.uniform())
    return getattr(_extensions, name)(index, round(float(size), 3))


def register(subparsers):
    parser = subparsers.add_parser(
        "demo",
        help="generate acrobot data with a hidden effect and diagnose it",
        description=(
            "Generate measured data for an acrobot with an effect hidden in it (chosen by --seed), "
            "simulate the nominal model against it, diagnose what it gets wrong, and write the report."
        ),
    )
    parser.add_argument("--out", default="dynax-demo", help="output directory (default dynax-demo/)")
    parser.add_argument("--seed", type=int, default=0, help="chooses the hidden effect and its size (default 0)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)  # the CLI identifies in float64; the library does not change config

    from .._data._io import save_trajectory
    from .._diagnose._demo import run_demo
    from ._diagnose import summary

    if args.seed < 0:
        raise UsageError(f"--seed must be a non-negative integer, got {args.seed}")
    start = time.perf_counter()
    out = pathlib.Path(args.out)
    with staged_directory(out) as stage:
        text = run_demo(hidden_effect(args.seed), seed=args.seed, out=stage, save_trajectory=save_trajectory,
                        write_json=write_json, summary=summary)
    print(text)
    print(f"wrote {out}/ in {time.perf_counter() - start:.0f} s")
    return 0
