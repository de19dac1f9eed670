"""Per-record angle zeros (`identify(...).angle_zeros`): an encoder zeroed where the arm stood when the
recording began is found, measured, told apart from a torque sensor's offset, and fitted out.

The records are made by scipy's DOP853 (not dynax's integrator) with sensor noise at the DFKI rig's
level (`recorded` in `test_identify_defaults`); the zero is added to the *recorded* angles only, so
the arm moved as the true one did, and its encoder read it from another zero.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import Dynamic, identify, Trajectory
import dynax.internal
from dynax.internal import record_angle_zeros
from tests.identify.test_identify_defaults import dfki, recorded, rig_model
from tests.typecheck import standing_aside

SEEDS = (30, 31, 32)
ZEROS = np.array([[0.06, -0.04], [-0.03, 0.05], [0.0, 0.02]])  # [rad] per record: q1, q2


@pytest.fixture(scope="module")
def records():
    model = rig_model()
    return [recorded(model, 8.0, seed) for seed in SEEDS]


def with_zero(record, zero):
    xs = np.asarray(record.xs) + np.concatenate([zero, np.zeros(2)])[None, :]
    return Trajectory(record.ts, jnp.asarray(xs), record.us, record.state_names, record.input_names)


def with_force_offset(record, offset):
    return Trajectory(
        record.ts, record.xs, record.us + jnp.asarray(offset)[None, :], record.state_names, record.input_names
    )


def _theta(result):
    return np.array([result.to_json()["stages"]["least_squares"]["parameters"][f"theta{i}"] for i in range(1, 6)])


@pytest.mark.heavy
def test_encoder_zeros_that_differ_between_records_are_found_measured_and_fitted_out(records):
    shifted = [with_zero(r, z) for r, z in zip(records, ZEROS)]
    result = identify(
        dynax.DoublePendulum(),
        shifted,
        Dynamic(),
        friction="coulomb",
        refine=False,
        validation=dynax.Validate(holdout=0),
    )
    zeros = result.angle_zeros
    assert zeros is not None and zeros.chosen and zeros.converged, zeros.reason
    # each record's zeros within 12 mrad, where they are 20 to 60 (the elbow's are the less certain: 1 to
    # 10 mrad off when this was written, the shoulder's within 6; the least-squares stage's parameters,
    # at which they are fitted, carry its errors-in-variables bias)
    assert np.max(np.abs(zeros.values - ZEROS)) < 0.012, zeros.values
    # each half of a record (4 s) reads the same zero: a sensor's, not model error that follows the motion
    # (within 30 mrad; record 2's elbow is the least certain, 24 mrad off in its second half)
    assert np.max(np.abs(zeros.halves - ZEROS[:, None, :])) < 0.03, zeros.halves
    # as many force offsets per record leave a larger equation error (0.139 against 0.130): how `identify` chose
    assert zeros.relative_error < 0.95 * zeros.force_relative_error, (zeros.relative_error, zeros.force_relative_error)
    # the base parameters are those of the same records read from their true zero (so are, within 0.5 %,
    # those of force offsets in the zeros' place: near the hanging rest a zero acts as a constant torque)
    truth = identify(
        dynax.DoublePendulum(),
        records,
        Dynamic(),
        friction="coulomb",
        refine=False,
        validation=dynax.Validate(holdout=0),
    )
    np.testing.assert_allclose(_theta(result), _theta(truth), rtol=0.01)
    forced = identify(
        dynax.DoublePendulum(),
        shifted,
        Dynamic(offsets=True),
        friction="coulomb",
        refine=False,
        validation=dynax.Validate(holdout=0),
    )
    assert forced.angle_zeros is None and forced.to_json()["stages"]["least_squares"]["offsets"] is not None
    report = result.to_json()
    assert report["angle_zeros"]["chosen"] and report["stages"]["least_squares"]["offsets"] is None


def test_held_out_tails_are_read_less_their_records_zeros(records):
    # Validation on the last 20 % of each record: a tail is the same recording as the head its zeros are
    # fitted on, so it is simulated less them, and the error is the model's, as on the tails read from the
    # true zero; as recorded, the tails' gravity is that of another angle, and the error is the zeros'.
    big = np.array([[-0.09, 0.11], [0.1, -0.08], [-0.05, 0.1]])  # [rad] as large as DFKI run 00's (-0.09, +0.11)
    shifted = [with_zero(r, z) for r, z in zip(records, big)]
    result = identify(dynax.DoublePendulum(), shifted, Dynamic(), friction="coulomb", refine=False)
    assert result.angle_zeros.chosen and "angle zeros" in result.validation.source, result.validation.source
    true_tails = dynax.internal.split_for_validation(records, 0.2, max(result.validation.horizons_s))[1]
    recorded_tails = dynax.internal.split_for_validation(shifted, 0.2, max(result.validation.horizons_s))[1]
    model = np.asarray(dynax.held_out_error(result.system, true_tails, result.validation.horizons_s).rmse)
    as_recorded = np.asarray(dynax.held_out_error(result.system, recorded_tails, result.validation.horizons_s).rmse)
    np.testing.assert_allclose(np.asarray(result.validation.rmse), model, rtol=0.1)
    assert np.all(as_recorded > 1.3 * model), (as_recorded, model)


def test_a_torque_offset_is_not_read_as_an_encoder_zero(records):
    # The shoulder's torque sensor reads high in one record, low in another (test_record_offsets' case):
    # force offsets explain the equations better, so they are what the fit uses.
    offsets = np.array([[0.12, 0.0], [-0.06, 0.0], [0.05, 0.0]])
    shifted = [with_force_offset(r, o) for r, o in zip(records, offsets)]
    zeros = record_angle_zeros(dynax.DoublePendulum(), shifted, Dynamic(), "coulomb", 1e-7)
    assert not zeros.chosen and zeros.force_relative_error < zeros.relative_error, zeros.reason


def test_records_read_from_their_true_zero_keep_force_offsets(records):
    # Neither the zeros nor force offsets explain anything here (equation errors within 0.2 %): the fit
    # keeps the force offsets, and the zeros it would have fitted are within the 12 mrad above.
    zeros = record_angle_zeros(dynax.DoublePendulum(), records, Dynamic(), "coulomb", 1e-7)
    assert zeros.converged and not zeros.chosen, zeros.reason
    assert np.max(np.abs(zeros.values)) < 0.012, zeros.values


def test_angle_zeros_apply_to_arms_whose_every_joint_is_a_driven_angle(records):
    # the acrobot's shoulder has no motor: its equation has no input, and is left as it is
    one = Trajectory(records[0].ts, records[0].xs, records[0].us[:, 1:], records[0].state_names, ("tau2",))
    result = identify(dynax.Acrobot(), [one], Dynamic(), refine=False, validation=dynax.Validate(holdout=0))
    assert result.angle_zeros is None
    with pytest.raises(dynax.UsageError, match="offsets='angles'"):
        identify(dynax.Acrobot(), [one], Dynamic(offsets="angles"), refine=False, validation=dynax.Validate(holdout=0))
    with standing_aside(), pytest.raises(dynax.UsageError, match="'angles'"):  # no Literal of `offsets` on purpose
        identify(
            dynax.DoublePendulum(),
            records,
            Dynamic(offsets="encoder"),
            refine=False,
            validation=dynax.Validate(holdout=0),
        )


@pytest.mark.heavy
def test_the_dfki_runs_read_their_angles_from_zeros_of_their_own(datasets):
    # Every DFKI run starts at q = (0, 0), to three encoder counts (2e-4 rad each) but run 12's elbow
    # (-0.0044 rad, the arm moving): the encoders are zeroed when a recording begins.
    # With a zero per run and joint the equations of all six runs leave a smaller error than with a
    # torque offset per run and joint (as many unknowns; 0.265 against 0.285 when this was written), and
    # the two halves of each run but the swing-up 12 read the same zeros to 0.01 rad, where the zeros
    # themselves reach 0.11 rad (run 00's elbow).
    runs = ("00", "01", "02", "03", "05", "12")
    records = [dynax.resample(r, r.dt) for r in (dfki(datasets, run) for run in runs)]
    starts = np.array([np.asarray(r.xs)[0, :2] for r in records])
    assert np.max(np.abs(starts)) < 5e-3 and np.sum(np.abs(starts) > 1e-3) == 1, starts
    zeros = record_angle_zeros(dynax.DoublePendulum(), records, Dynamic(), "coulomb", 1e-7)
    assert zeros.chosen and zeros.converged, zeros.reason
    assert zeros.relative_error < 0.95 * zeros.force_relative_error
    spread = np.abs(zeros.halves[:, 0] - zeros.halves[:, 1])
    assert np.max(spread[:5]) < 0.01, spread
    assert np.max(np.abs(zeros.values[:5])) > 0.05, zeros.values
