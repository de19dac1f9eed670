"""The demo's data: the acrobot rig with one effect hidden in it (`dynax demo`, the tutorials, tests)."""

import numpy as np

from .._data._trajectory import Trajectory
from .._model._extensions import (
    AbstractTerm,
    CoulombFriction,
    Extended,
    InputDelay,
    InputLag,
    InputOffset,
    QuadraticDrag,
    RotorInertia,
)
from .._model._two_link import Acrobot
from ._excitation import Multisine
from ._trajectory import synthetic_trajectory

# The rig the data comes from differs a little from the datasheet model the user starts with.
DEMO_TRUTH_PHYSICAL = dict(m1=1.05, m2=0.97, lc2=1.02, Ic2=0.32)

# (cause, where, term from a size in [0, 1]): the effects the demo hides, picked by its seed.
_EFFECTS = (
    ("coulomb_friction", "q2", lambda s: (CoulombFriction, 1, 0.15 + 0.25 * s)),
    ("rotor_inertia", "q2", lambda s: (RotorInertia, 1, 0.08 + 0.12 * s)),
    ("input_delay", "tau2", lambda s: (InputDelay, 0, 0.03 + 0.03 * s)),
    ("quadratic_drag", "q2", lambda s: (QuadraticDrag, 1, 0.08 + 0.08 * s)),
    ("input_lag", "tau2", lambda s: (InputLag, 0, 0.04 + 0.04 * s)),
    ("coulomb_friction", "q1", lambda s: (CoulombFriction, 0, 0.2 + 0.3 * s)),
    ("input_offset", "tau2", lambda s: (InputOffset, 0, 0.15 + 0.15 * s)),
)


def hidden_effect(seed: int) -> AbstractTerm:
    """The term `dynax demo --seed` hides: the effect cycles with the seed (seven causes), its size is
    drawn from it (rounded to 3 digits)."""
    rng = np.random.default_rng(seed)
    cause, where, factory = _EFFECTS[seed % len(_EFFECTS)]
    term_class, index, size = factory(rng.uniform())
    return term_class(index, round(float(size), 3))


def demo_data(
    term: AbstractTerm, *, seed: int, train_s: float = 20.0, validation_s: float = 10.0
) -> tuple[Extended, Trajectory, Trajectory]:
    """Training and validation records of the demo's truth acrobot with `term` hidden.

    One run of `train_s + validation_s` seconds at 100 Hz under a random multisine elbow torque,
    with measurement noise; the first `train_s` seconds train, the rest is held out. The truth's
    base parameters (`DEMO_TRUTH_PHYSICAL`) differ a little from the nominal `Acrobot()`.

    **Returns:** `(truth, train, validation)`.
    """
    truth = Extended(Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL), (term,))
    run = synthetic_trajectory(
        truth,
        duration=train_s + validation_s,
        dt=0.01,
        excitation=Multisine(amplitude=2.0),
        seed=seed,
        system_name="acrobot",
    )
    k = int(round(train_s / 0.01)) + 1
    train = Trajectory(run.ts[:k], run.xs[:k], run.us[:k], run.state_names, run.input_names, "acrobot", "train.csv")
    validation = Trajectory(
        run.ts[k:], run.xs[k:], run.us[k:], run.state_names, run.input_names, "acrobot", "validation.csv"
    )
    return truth, train, validation
