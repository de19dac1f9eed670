"""Held-out validation: the median window error and the records whose RMSE a few windows carry."""

import math

import jax.numpy as jnp
import numpy as np

import dynax
from dynax import held_out_error, Trajectory
from dynax.internal import CONCENTRATED
from tests.identify.test_identify_defaults import dfki, recorded, RIG, RIG_IR2, rig_model


def with_glitch(record: Trajectory, start_s: float, stop_s: float, offset: float) -> Trajectory:
    """The record with its encoder positions shifted by `offset` between `start_s` and `stop_s` (a slip)."""
    ts = np.asarray(record.ts)
    xs = np.array(record.xs)
    inside = (ts >= start_s) & (ts < stop_s)
    xs[inside, :2] += offset
    return Trajectory(record.ts, jnp.asarray(xs), record.us, record.state_names, record.input_names)


def test_a_glitch_in_the_data_is_named_as_the_few_windows_that_carry_the_rmse():
    # A record made by scipy's DOP853 with the rig's sensor noise, validated with the model that made it:
    # the windows' errors differ by chance only, so no few of them carry the RMSE.
    record = recorded(rig_model(), 8.0, seed=11)
    clean = held_out_error(rig_model(), [record])
    assert clean.concentrated == {} and clean.note() is None
    assert all(0 < m <= r for m, r in zip(clean.median, clean.rmse))
    # The same record with 0.3 s of encoder positions shifted by 0.5 rad: the windows started in the slip,
    # or ending in it, carry the RMSE, and the report says where they start.
    glitched = held_out_error(rig_model(), [with_glitch(record, 4.0, 4.3, 0.5)])
    assert set(glitched.concentrated) == {"record 0"}
    for entry in glitched.concentrated["record 0"]:
        assert entry["rmse"] > CONCENTRATED * entry["median"]
        assert entry["windows"] < 0.2 * entry["of"]
        # windows that reach into the slip start at most one horizon before it
        assert 4.0 - entry["horizon_s"] - 0.05 <= entry["from_s"] <= entry["to_s"] < 4.3, entry
    assert "record 0: at " in glitched.note() and "windows, starting" in glitched.note()
    # the median window barely notices what the RMSE is made of
    assert glitched.median[-1] < 1.5 * clean.median[-1]


def test_the_balancing_end_of_the_dfki_swing_up_is_named_and_the_gentle_runs_are_not(datasets):
    # The lab's model_3.0 (made without dynax) on real runs. Run 12 swings the pendulum up, and from about
    # 4.2 s it rests upright (held by friction at rest, which neither model has); open loop, every rollout
    # started near the top falls off it, and those windows carry the RMSE at 0.5 s (half of it from about a
    # tenth of the windows).
    lab = dynax.Extended(
        dynax.DoublePendulum.from_base_parameters({**RIG, "theta6": 0.001, "theta7": 0.001}),
        (
            dynax.CoulombFriction(0, 0.093 * math.pi / 2),
            dynax.CoulombFriction(1, 0.078 * math.pi / 2),
            dynax.RotorInertia(1, RIG_IR2),
        ),
    )
    runs = {r: dfki(datasets, r) for r in ("02", "12")}
    swing_up = held_out_error(lab, [runs["12"]])
    (entry,) = [e for e in swing_up.concentrated["trajectory_12.csv"] if e["horizon_s"] == 0.5]
    assert entry["windows"] < 0.15 * entry["of"] and 3.0 <= entry["from_s"] and entry["to_s"] <= 6.0, entry
    assert swing_up.rmse[-1] > 0.5 > 0.2 > swing_up.median[-1]
    gentle = held_out_error(lab, [runs["02"]])
    assert gentle.concentrated == {}
    # pooled over both records, the median keeps the gentle run's scale
    both = held_out_error(lab, list(runs.values()))
    assert both.median[-1] < 0.2 and set(both.concentrated) == {"trajectory_12.csv"}
