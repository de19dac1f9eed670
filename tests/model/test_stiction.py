"""`Stiction`: sticking and breakaway against an event-based stick-slip integrator outside dynax's model code."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from tests.reference import stick_slip_arm

ARM = dict(m1=0.642, m2=0.564, l1=0.2, lc1=0.2, lc2=0.321, I1=0.0267, I2=0.0539, b1=0.001, b2=0.001)  # DFKI-like
FC, FS = (0.05, 0.08), (0.12, 0.2)
DT = 0.005


@pytest.fixture(scope="module")
def arm():
    return dynax.DoublePendulum.from_physical(**ARM)


def with_friction(arm, fs=FS, scale=0.01, hold_time=0.01):
    terms = tuple(dynax.CoulombFriction(j, FC[j], velocity_scale=scale) for j in range(2))
    terms += tuple(dynax.Stiction(j, fs[j], velocity_scale=scale, hold_time=hold_time) for j in range(2))
    return dynax.Extended(arm, terms)


def test_converges_to_the_event_based_stick_slip_as_the_smoothing_narrows(arm):
    # Both joints stick and slip many times (the shoulder 4 %, the elbow 38 % of the samples).
    ts = np.arange(0.0, 3.0, DT)
    us = np.stack(
        [0.4 * np.sin(2 * np.pi * 0.4 * ts), 0.25 * np.sin(2 * np.pi * 0.7 * ts + 1) * (1 + 0.5 * np.sin(ts))], 1
    )
    theta = [float(v) for v in arm.base_parameters.values()]
    reference, stuck = stick_slip_arm(theta, np.zeros(4), ts, us, fc=FC, fs=FS, vst=0.05)
    assert stuck[:, 1].mean() > 0.2 and stuck[:, 0].any()
    errors = []
    for scale in (0.01, 0.003, 0.001):
        xs = dynax.simulate(
            with_friction(arm, scale=scale), jnp.zeros(4), ts, us, method=dynax.Adaptive(rtol=1e-9, atol=1e-9)
        ).xs
        errors.append(float(np.sqrt(np.mean((np.asarray(xs)[:, :2] - reference[:, :2]) ** 2))))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.2 * errors[0] and errors[2] < 0.006  # error about proportional to the smoothing
    # Without the static level the same narrow Coulomb friction stays far off (the elbow sticks 38 % of the time).
    coulomb_only = dynax.Extended(arm, tuple(dynax.CoulombFriction(j, FC[j], velocity_scale=0.001) for j in range(2)))
    xs = dynax.simulate(coulomb_only, jnp.zeros(4), ts, us, method=dynax.Adaptive(rtol=1e-9, atol=1e-9)).xs
    assert float(np.sqrt(np.mean((np.asarray(xs)[:, :2] - reference[:, :2]) ** 2))) > 5 * errors[2]
    # The default fixed-step rollout agrees with the adaptive one at the default smoothing.
    fixed = dynax.simulate(with_friction(arm, scale=0.01), jnp.zeros(4), ts, us).xs
    adaptive = dynax.simulate(with_friction(arm, scale=0.01), jnp.zeros(4), ts, us, method=dynax.Adaptive()).xs
    assert float(jnp.max(jnp.abs(fixed - adaptive)[:, :2])) < 1e-3


@pytest.mark.parametrize("method", [dynax.FixedGrid(), dynax.Adaptive(rtol=1e-8, atol=1e-8)], ids=["fixed", "adaptive"])
def test_rests_under_a_torque_below_breakaway_and_breaks_away_above(arm, method):
    # The elbow's torque ramps to 0.9 fs2 and holds, then ramps past fs2; the shoulder is held by its own stiction.
    ts = np.arange(0.0, 4.0, DT)
    tau2 = np.interp(ts, [0.0, 0.5, 2.5, 4.0], [0.0, 0.9 * FS[1], 0.9 * FS[1], 1.3 * FS[1]])
    us = np.stack([np.zeros_like(ts), tau2], 1)
    theta = [float(v) for v in arm.base_parameters.values()]
    reference, stuck = stick_slip_arm(theta, np.zeros(4), ts, us, fc=FC, fs=(0.5, FS[1]), vst=0.05)
    breakaway = ts[np.argmax(~stuck[:, 1])]
    assert 2.5 < breakaway < 4.0
    xs = np.asarray(dynax.simulate(with_friction(arm, fs=(0.5, FS[1])), jnp.zeros(4), ts, us, method=method).xs)
    resting = ts < breakaway - 0.05
    assert np.max(np.abs(xs[resting, :2])) < 1e-4  # held, not creeping
    np.testing.assert_allclose(xs[-1, 1], reference[-1, 1], rtol=0.15)  # the slip, within the smoothing's error
    # It breaks away at the torque the event-based integrator does (the band's edge: within 2 % of fs2).
    leaves = np.argmax(np.abs(xs[:, 3]) > 0.01)
    np.testing.assert_allclose(tau2[leaves], tau2[np.argmax(~stuck[:, 1])], rtol=0.03)
    # A velocity-only friction (no static level) creeps under the same torque.
    creeping = dynax.Extended(arm, tuple(dynax.CoulombFriction(j, (0.5, FS[1])[j]) for j in range(2)))
    xs = np.asarray(dynax.simulate(creeping, jnp.zeros(4), ts, us, method=method).xs)
    assert np.max(np.abs(xs[resting, 1])) > 1e-2


def test_neutral_static_level_is_the_nominal_model_and_the_level_has_a_gradient(arm):
    ts = np.arange(0.0, 1.0, DT)
    us = np.stack([0.3 * np.sin(5 * ts), 0.15 * np.cos(3 * ts)], 1)
    nominal = dynax.Extended(arm, tuple(dynax.CoulombFriction(j, FC[j]) for j in range(2)))
    neutral = dynax.Extended(arm, nominal.terms + (dynax.Stiction(1, 0.0),))
    x0 = jnp.array([0.1, -0.2, 0.0, 0.0])
    np.testing.assert_allclose(
        dynax.simulate(neutral, x0, ts, us).xs, dynax.simulate(nominal, x0, ts, us).xs, atol=1e-12
    )

    def final_angle(fs):
        model = dynax.Extended(arm, nominal.terms + (dynax.Stiction(1, fs),))
        return dynax.simulate(model, x0, ts, us).xs[-1, 1]

    grad = jax.grad(final_angle)(0.12)
    # The rollout is piecewise smooth in fs (the hold switches between its bounds): a step of 1e-4 or more straddles
    # a switch on this record, so the difference quotient is taken on the smooth piece.
    step = 1e-6
    fd = (final_angle(0.12 + step) - final_angle(0.12 - step)) / (2 * step)
    assert np.isfinite(grad) and abs(grad) > 1e-3
    np.testing.assert_allclose(grad, fd, rtol=1e-3)


def test_settings_and_labels(arm):
    term = dynax.Stiction(1, 0.2)
    model = dynax.Extended(arm, (term,))
    assert model.labels == ("stiction@q2",) and set(model.parameters) == {"fs2"}
    with pytest.raises(ValueError, match="hold_time"):
        dynax.Stiction(1, 0.2, hold_time=0.0)
    with pytest.raises(ValueError, match="velocity_scale"):
        dynax.Stiction(0, 0.2, velocity_scale=-1.0)
    # Only the static level is fitted; the speeds and the hold time are settings.
    leaves = jax.tree.leaves(jax.tree.map(lambda f, x: x if f else None, term.parameter_filter(), term))
    assert len(leaves) == 1


def test_the_holding_force_never_pushes_along_the_motion(arm):
    # Before a reversal the other forces decelerate the joint faster than the hold time asks; the hold must not then
    # drive it on towards its turning point (friction does no positive work), and at rest it still holds.
    model = with_friction(arm)
    frictionless = dynax.Extended(arm, ())
    q = jnp.array([0.3, -0.4])
    mass = arm.mass_matrix(q)

    def friction(dq2, tau2):
        x, u = jnp.concatenate([q, jnp.array([0.0, dq2])]), jnp.array([0.0, tau2])
        return mass @ (model.vector_field(0.0, x, u)[2:] - frictionless.vector_field(0.0, x, u)[2:])

    # Inside the band the sign of the speed is noise and the hold may act either way; from twice its width on
    # (0.02 rad/s, where the band's smooth edge still weighs 0.78) the friction all but opposes the motion.
    speeds = jnp.concatenate([jnp.linspace(-0.08, -0.02, 31), jnp.linspace(0.02, 0.08, 31)])
    for tau2 in (-2.0, -0.5, 0.5, 2.0):  # net elbow loads far above the static level, both ways
        along = jax.vmap(lambda v: friction(v, tau2)[1] * jnp.sign(v))(speeds)
        assert float(jnp.max(along)) < 0.05 * FS[1]
    # At rest under a load below the static level the friction balances it (the joint holds).
    gravity = arm.inverse_dynamics(q, jnp.zeros(2), jnp.zeros(2))
    held = friction(0.0, float(gravity[1]) + 0.9 * FS[1])
    np.testing.assert_allclose(held[1], -0.9 * FS[1], rtol=1e-6)


def with_dwell(arm, dwell=0.1, scale=0.01, fs=FS):
    terms = tuple(dynax.CoulombFriction(j, FC[j], velocity_scale=scale) for j in range(2))
    terms += tuple(dynax.Stiction(j, fs[j], velocity_scale=scale, dwell_time=dwell) for j in range(2))
    return dynax.Extended(arm, terms)


def test_with_a_dwell_it_follows_the_event_based_rising_static_friction(arm):
    # A free swing that decays: the shoulder only passes through zero speed (its reversals never stick), the elbow
    # starts at rest and sticks and slips. The reference ages each contact while it sticks and wears it off by
    # sliding (`stick_slip_arm(dwell=...)`); without ageing (the static level there at once) it swings otherwise.
    ts = np.arange(0.0, 3.0, DT)
    us = np.zeros((len(ts), 2))
    x0 = np.array([0.8, -0.5, 0.5, 0.0])
    theta = [float(v) for v in arm.base_parameters.values()]
    aged, stuck = stick_slip_arm(theta, x0, ts, us, fc=FC, fs=FS, dwell=0.1, memory0=(0.0, 1.0))
    at_once, _ = stick_slip_arm(theta, x0, ts, us, fc=FC, fs=FS)
    assert not stuck[:, 0].any() and stuck[:, 1].mean() > 0.2

    def rmse(xs, reference):
        return float(np.sqrt(np.mean((np.asarray(xs)[:, :2] - reference[:, :2]) ** 2)))

    apart = rmse(at_once, aged)
    model = with_dwell(arm)
    assert model.state_names[4:] == ("fs1_rest", "fs2_rest")
    start = model.initial_state(jnp.asarray(x0), jnp.zeros(2))
    np.testing.assert_allclose(start[4:], [0.0, 1.0], atol=1e-12)  # the shoulder moving, the elbow at rest
    xs = dynax.simulate(model, start, ts, us, method=dynax.Adaptive(rtol=1e-9, atol=1e-9)).xs
    adaptive = dynax.Adaptive(rtol=1e-9, atol=1e-9)
    without = dynax.simulate(with_friction(arm), jnp.asarray(x0), ts, us, method=adaptive).xs
    assert rmse(xs, aged) < 0.6 * apart and rmse(without, aged) > 0.9 * apart
    # The shoulder's passages through zero speed leave little memory of rest: it never stuck.
    assert float(jnp.max(xs[:, 4])) < 0.1
    # A fixed-step rollout agrees with the adaptive one (the memory is not stiff: its wear is capped by the hold time).
    # This swing's elbow is fast for the default grid with or without the dwell, hence eight steps per sample.
    fixed = dynax.simulate(model, start, ts, us, method=dynax.FixedGrid(substeps=8)).xs
    assert float(jnp.max(jnp.abs(fixed - xs)[:, :2])) < 1e-4


def test_with_a_dwell_the_memory_builds_at_rest_and_a_rest_holds_as_without(arm):
    # At rest (hanging, no torque) the memory builds as 1 - exp(-t / T_d) from zero.
    ts = np.arange(0.0, 0.3, DT)
    us = np.zeros((len(ts), 2))
    model = with_dwell(arm, dwell=0.1)
    start = model.initial_state(jnp.zeros(4), jnp.zeros(2)).at[4:].set(0.0)
    xs = np.asarray(dynax.simulate(model, start, ts, us, method=dynax.Adaptive(rtol=1e-10, atol=1e-10)).xs)
    np.testing.assert_allclose(xs[:, 4], 1.0 - np.exp(-ts / 0.1), atol=1e-6)
    # From a rest with its memory built, the elbow holds and breaks away at the event-based integrator's torque.
    ts = np.arange(0.0, 4.0, DT)
    tau2 = np.interp(ts, [0.0, 0.5, 2.5, 4.0], [0.0, 0.9 * FS[1], 0.9 * FS[1], 1.3 * FS[1]])
    us = np.stack([np.zeros_like(ts), tau2], 1)
    theta = [float(v) for v in arm.base_parameters.values()]
    _, stuck = stick_slip_arm(theta, np.zeros(4), ts, us, fc=FC, fs=(0.5, FS[1]), dwell=0.1)
    model = with_dwell(arm, fs=(0.5, FS[1]))
    xs = np.asarray(dynax.simulate(model, model.initial_state(jnp.zeros(4), us[0]), ts, us).xs)
    breakaway = ts[np.argmax(~stuck[:, 1])]
    assert np.max(np.abs(xs[ts < breakaway - 0.05, :2])) < 1e-4
    np.testing.assert_allclose(tau2[np.argmax(np.abs(xs[:, 3]) > 0.01)], tau2[np.argmax(~stuck[:, 1])], rtol=0.03)
    with pytest.raises(ValueError, match="dwell_time"):
        dynax.Stiction(1, 0.2, dwell_time=0.0)
