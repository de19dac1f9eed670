"""The diagnosis reads a candidate term through the term protocol (`AbstractTerm.hidden_names`, `initial_hidden`,
`hidden_vector_field`, `smooth_at_neutral`) and nothing else of its class: a term written here, which dynax has never
heard of, is screened as its protocol says.

The record is made outside dynax's model code: the linear axis with a lagged damping, a linear ODE under a held
force, stepped exactly by the matrix exponential of its zero-order-hold discretisation (scipy)."""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import expm

from dynax import (
    AbstractJointTerm,
    diagnose,
    Extended,
    Horizons,
    InputLag,
    LinearAxis,
    Refit,
    Selection,
    Trajectory,
    ViscousFriction,
)
from dynax.internal import (
    candidate_family,
    complete_state,
    first_screening,
    make_windows,
    names_to_refit,
    prepare_problem,
    rankable,
)
from tests.stateful_terms import LaggedDamping

MASS, VISCOUS, OFFSET = 95.0, 200.0, -3.0  # the linear axis, without Coulomb friction (a linear ODE)
B, TAU = 300.0, 0.2  # the lagged damping: force -B z, TAU z' = dq - z
DT = 0.01


class _Kinked(AbstractJointTerm):
    """A dead band of half-width `coefficient` on the speed's damping, $-d\\,(\\dot q - \\mathrm{clip}(\\dot q, -c,
    c))$: at $c = 0$ not differentiable in $c$ (`smooth_at_neutral` false), and no `Stiction`."""

    joint: int = eqx.field(static=True)
    coefficient: jax.Array
    cause: ClassVar[str] = "dead_band"
    prefix: ClassVar[str] = "db"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1
    smooth_at_neutral: ClassVar[bool] = False

    def force(self, q, dq):
        return 50.0 * jnp.clip(dq, -self.coefficient, self.coefficient)


def _exact(seed: int, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`(ts, xs, us, noise)`: the axis with the lagged damping under a multisine force held between samples, stepped
    exactly from rest (`xs` is `(q, dq, z)`, `z` the lagged speed), and an encoder's and a speed sensor's noise."""
    rng = np.random.default_rng(seed)
    ts = np.arange(int(round(duration / DT)) + 1) * DT
    freqs = np.geomspace(0.2, 4.0, 8)
    us = sum(120.0 * np.sin(2 * np.pi * f * ts + rng.uniform(0, 2 * np.pi)) for f in freqs)[:, None]
    # x = (q, dq, z), input (u, 1) (the constant 1 carries the offset)
    A = np.array([[0, 1, 0], [0, -VISCOUS / MASS, -B / MASS], [0, 1 / TAU, -1 / TAU]])
    Bu = np.array([[0, 0], [1 / MASS, -OFFSET / MASS], [0, 0]])
    block = expm(np.block([[A, Bu], [np.zeros((2, 5))]]) * DT)
    Ad, Bd = block[:3, :3], block[:3, 3:]
    x = np.zeros(3)
    xs = [x]
    for u in us[:-1, 0]:
        x = Ad @ x + Bd @ np.array([u, 1.0])
        xs.append(x)
    return ts, np.asarray(xs), us, rng.normal(0.0, [1e-5, 1e-4], (len(ts), 2))


def _record(seed: int, duration: float, name: str) -> Trajectory:
    """The axis with the lagged damping (`_exact`), its position and speed measured with noise."""
    ts, xs, us, noise = _exact(seed, duration)
    xs = xs[:, :2] + noise
    return Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), ("q", "dq"), ("force",), "linear_axis", name)


NOMINAL = LinearAxis(mass=MASS, viscous=VISCOUS, coulomb=0.0, offset=OFFSET)


def test_the_rollout_screening_ranks_what_the_protocol_says_has_a_derivative_at_neutral():
    # The lag (an input's dynamics) and the dead band (not smooth at neutral) have no informative derivative there;
    # the viscous friction and the lagged damping (a state of its own, its force linear in its coefficient) have.
    candidates = (
        ViscousFriction(0),
        InputLag(0),
        _Kinked(0, jnp.asarray(0.0)),
        LaggedDamping(0, jnp.asarray(0.0), TAU),
    )
    train = _record(1, 5.0, "train")
    family, _, _ = candidate_family(NOMINAL, candidates, names_to_refit(NOMINAL, Refit()), [train])
    ranked = [candidates[k].cause for k in rankable(family, range(len(candidates)))]
    assert ranked == ["viscous_friction", "lagged_damping"]


def test_a_term_with_a_state_of_its_own_is_screened_along_the_measured_states():
    # The one-step screening reads the lagged damping's state integrated along the measured speeds
    # (`hidden_vector_field` from `initial_hidden`): its direction is the lagged speed, and it explains the record
    # far better than a damping on the speed itself.
    train, held_out = _record(2, 20.0, "train"), _record(3, 10.0, "held_out")
    candidates = (ViscousFriction(0), LaggedDamping(0, jnp.asarray(0.0), TAU))
    problem = prepare_problem(NOMINAL, train, [held_out], candidates, Refit(), Horizons(), Selection(max_terms=1))
    screened = first_screening(problem)
    gain, delta = screened["lagged_damping@q"]
    assert gain > 0.9, screened
    assert gain > screened["viscous_friction@q"][0] + 0.2, screened
    assert abs(delta - B) < 0.05 * B, screened  # the screening's step is about the damping's size


def test_a_window_starts_a_terms_own_state_where_the_record_puts_it():
    # The windowed rollouts (the refit, the held-out score) integrate the lagged speed along the measured states
    # and inputs before each window (`Windows.xs_before`): it starts near the exact lagged speed there, where the
    # lag at rest at the window's first state (`initial_hidden`, the start before) is off by the whole lag.
    ts, exact, _, _ = _exact(3, 10.0)
    windows = make_windows([_record(3, 10.0, "held_out")], 50, 25)
    truth = Extended(NOMINAL, (LaggedDamping(0, jnp.asarray(B), TAU),))
    start = jax.vmap(lambda x, u, tb, ub, xb: complete_state(truth, x, u, tb, ub, xs_before=xb))(
        windows.xs[:, 0], windows.us[:, 0], windows.ts_before, windows.us_before, windows.xs_before
    )
    k = np.asarray(windows.starts)[:, 1]
    z = exact[k, 2]
    off = np.sqrt(np.mean((np.asarray(start)[:, 2] - z) ** 2))
    lag = np.sqrt(np.mean((exact[k, 1] - z) ** 2))  # the error of a start at rest at the window's first speed
    assert off < 0.1 * lag, (off, lag)  # half a second of history forgets all but e^(-0.5 / TAU) = 8 % of a start


@pytest.mark.slow  # about 55 s of CPU
def test_the_diagnosis_names_a_lagged_damping_at_its_size():
    # With each window's lagged speed started where the record puts it, the simulation-error refit names the
    # damping at its size and the held-out gain is nearly all of the error. Started at rest at each window's first
    # state, the refit made up for the wrong start: 255, held-out gain 0.83 (the viscous friction's 0.82).
    train, held_out = _record(2, 20.0, "train"), _record(3, 10.0, "held_out")
    candidates = (ViscousFriction(0), LaggedDamping(0, jnp.asarray(0.0), TAU))
    report = diagnose(
        NOMINAL, train, [held_out], candidates=candidates, selection=Selection(max_terms=1, discovery=False)
    )
    finding = report.findings[0]
    assert (finding["cause"], finding["where"]) == ("lagged_damping", "q"), report.findings
    assert abs(finding["coefficient"] - B) < 0.03 * B, finding
    assert finding["gain"] > 0.95, finding
