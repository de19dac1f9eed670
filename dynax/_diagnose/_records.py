"""The records of a diagnosis: training and held-out runs checked and put on one grid, the hold-out cut,
velocities from the encoders, and the horizons read from the training runs (the reference horizon and
the fit windows). Everything here looks at the data's layout or at the training runs, never at the
held-out runs' errors.
"""

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import resample
from .._data._spectra import position_fit_window, with_velocities_from_positions
from .._data._trajectory import Trajectory
from .._data._velocities import check_trajectory_velocities
from .._errors import DataError, UsageError
from .._validate import Horizon, position_spread, predictability_horizon, relative_position_error
from ._residuals import sg_window

MIN_BATCHES = 10  # the data-driven reference horizon leaves the paired test at least this many batches

# Cross-fitting needs every fold to fit two runs or more (see `_forward._cross_fit`); a single training run is cut
# into this many contiguous blocks instead, each at least this many of the longest candidate horizon long.
MIN_CROSS_FIT_RUNS = 3
MIN_BLOCK_HORIZONS = 8


# The part of each training record held out when no validation record is given.
HOLDOUT_FRACTION = 0.3


def as_records(data, name) -> list[Trajectory]:
    if isinstance(data, Trajectory):
        return [data]
    if isinstance(data, Sequence) and data and all(isinstance(t, Trajectory) for t in data):
        return list(data)
    raise UsageError(
        f"diagnose: `{name}` must be a Trajectory or a non-empty sequence of them, got {type(data).__name__}"
    )


def prepare_records(system, train, validation, holdout_fraction, notes):
    """The training and held-out runs, checked against `system`, on one uniform grid, in the default float type.

    Runs are kept apart (never concatenated): every window lies inside one run.
    """
    train_records = as_records(train, "train")
    for rec in train_records:
        if tuple(rec.state_names) != tuple(system.state_names) or tuple(rec.input_names) != tuple(system.input_names):
            raise UsageError(
                f"diagnose: the record {rec.source or ''} has states {rec.state_names} and inputs {rec.input_names}, "
                f"but {type(system).__name__} has {system.state_names} and {system.input_names}"
            )
        check_trajectory_velocities(rec)  # a velocity in other units than its position: refused, named
    if validation is None:  # `holdout_fraction` in (0, 1): `Selection` checks it
        train_records, validation_records = map(
            list, zip(*(holdout_split(rec, holdout_fraction) for rec in train_records))
        )
        notes.append(
            f"No validation record was given: the last {holdout_fraction:.0%} of each training record was held out."
        )
    else:
        validation_records = as_records(validation, "validation")
        for rec in validation_records:
            check_trajectory_velocities(rec)
    dt = float(np.median(np.concatenate([np.diff(np.asarray(r.ts)) for r in train_records + validation_records])))
    if not all(r.is_uniform for r in train_records + validation_records):
        train_records = [resample(r, dt) for r in train_records]
        validation_records = [resample(r, dt) for r in validation_records]
        notes.append(
            f"The sampling was irregular; the records were resampled to {dt * 1000:.3g} ms (states linearly, inputs "
            "as held)."
        )
    # One-step residuals drop a smoothing window (about 0.1 s) at each end of a record; a record needs
    # room for that and as much again to be judged on.
    need = 4 * sg_window(dt)
    for kind, records in (("training", train_records), ("held-out", validation_records)):
        for rec in records:
            if len(rec) < need:
                what = (
                    f"the held-out part of the record (its last {holdout_fraction:.0%})"
                    if validation is None and kind == "held-out"
                    else f"the {kind} record"
                )
                raise DataError(
                    f"diagnose: {what} has {len(rec)} samples ({len(rec) * dt:.3g} s); "
                    f"the diagnosis needs at least {need} ({need * dt:.3g} s) per record",
                    path=rec.source or None,
                )
    dtype = jnp.result_type(float)

    return [_cast(r, dtype) for r in train_records], [_cast(r, dtype) for r in validation_records], dt


def velocity_estimates(system, train_records, validation_records, velocities, notes):
    """With `velocities="auto"`, the records of a system with joint positions and velocities get the
    velocities of a local cubic fit of their positions wherever their measured velocities are noisy."""
    joints = tuple(system.joint_names)
    if velocities == "measured" or not joints or tuple(system.state_names) != joints + tuple(f"d{q}" for q in joints):
        return train_records, validation_records, "as measured"
    out, windows, noise, count = [], [], [], 0
    for rec in train_records + validation_records:
        smoothed, choice, replaced = with_velocities_from_positions(rec)
        out.append(smoothed)
        if replaced:
            count += 1
            windows.append(position_fit_window(choice.cutoff_hz, rec.dt) * rec.dt)
            noise.append(max(choice.noise_std[name] for name in replaced))
    if not count:
        return train_records, validation_records, "as measured"
    how = (
        f"from positions: the derivative of a local cubic fit (Savitzky-Golay over {min(windows) * 1000:.3g} to "
        f"{max(windows) * 1000:.3g} ms) in {count} of {len(out)} records, whose measured velocities carry white "
        f"noise of up to {max(noise):.3g} (state units per second) that the fit removes at a smaller bias"
    )
    notes.append(
        f"Velocities {how}; the windows start from them and are compared with them (velocities='measured' keeps them)."
    )
    n = len(train_records)
    return out[:n], out[n:], how


def horizon_grid(horizons_s, reference_horizon_s, train_records, validation_records, notes, cross_fit=False):
    """The reported horizons (at most half the shortest held-out record) and the candidates for the reference
    horizon (with `cross_fit`, none so long that a single training run that could be cut into cross-fitting blocks
    is not)."""
    shortest = min(r.duration for r in validation_records)
    horizons = np.asarray([h for h in horizons_s if h <= 0.5 * shortest + 1e-9] or [min(horizons_s)], float)
    if reference_horizon_s is not None:
        if reference_horizon_s > horizons.max():
            notes.append(
                f"The held-out record is short: the reference horizon was lowered from {reference_horizon_s:g} s "
                f"to {horizons.max():g} s."
            )
            reference_horizon_s = float(horizons.max())
        if reference_horizon_s not in horizons:
            horizons = np.sort(np.append(horizons, reference_horizon_s))
        return horizons, np.asarray([reference_horizon_s])
    # The paired test compares batches of windows twice the horizon long: a horizon of at most a
    # twentieth of the held-out time leaves it at least ten batches (their *length* is looked at,
    # never their errors).
    held_out_s = sum(r.duration for r in validation_records)
    longest = min(horizons.max(), 0.5 * min(r.duration for r in train_records), held_out_s / MIN_BATCHES / 2)
    # A single training run is cross-fitted only if it holds `MIN_CROSS_FIT_RUNS` blocks of `MIN_BLOCK_HORIZONS` of
    # the longest candidate horizon (`_problem.cross_fit_folds`). Where the held-out record is long beside it, a
    # candidate a few tenths of a second longer would cost the test the run's windows (a quadratic drag gaining 91 %
    # on a 20 s flight: p = 0.006 at 0.95 s on the held-out run alone, 0.0002 at 0.8 s with the run's blocks beside
    # it), so the candidates stop where the blocks still fit (again their length alone is looked at).
    blocks_s = len(train_records[0]) * float(train_records[0].dt) / (MIN_CROSS_FIT_RUNS * MIN_BLOCK_HORIZONS)
    if cross_fit and len(train_records) == 1 and 0.1 <= blocks_s < longest:
        longest = blocks_s
    candidates_s = np.round(np.arange(0.1, longest + 1e-9, 0.05), 6)
    return horizons, candidates_s if candidates_s.size else np.asarray([horizons.min()])


def reference_horizon(nominal_model, train_records, candidates_s, given, fraction, stride, position_index, dt):
    """The reference horizon: `given`, or the predictability horizon of the nominal model on the training runs."""
    if given is not None:
        return Horizon(float(candidates_s[0]), "given (reference_horizon_s)", None, candidates_s, [np.nan])
    errors = [horizon_errors(nominal_model, rec, candidates_s, stride, dt) for rec in train_records]
    positions = np.concatenate([np.asarray(r.xs)[:, position_index] for r in train_records])
    spread = position_spread(positions, [k in nominal_model.angle_indices for k in position_index])
    relative = relative_position_error(np.concatenate(errors), position_index, spread)
    return predictability_horizon(relative, dt, candidates_s, fraction)


# The longest fit window [s] (`fit_window`): the horizons' rollouts run at least this many steps, so that the fit
# window's and the reference horizon's share one compiled program (`horizon_errors`).
LONGEST_FIT_WINDOW_S = 1.0


def horizon_errors(model, rec: Trajectory, candidates_s, stride: int, dt: float) -> np.ndarray:
    """`window_simulation_errors(model, rec, candidates_s, stride=stride)`, the same rollouts and numbers, through one
    compiled program for the fit window and the reference horizon of a record.

    `window_simulation_errors` compiles `rollouts_from_starts` for each step count and number of starts: the fit
    window's (1 s) and the reference horizon's (a few tenths of a second) were two programs of the same rollout.
    Here every call rolls out `LONGEST_FIT_WINDOW_S` (or the longest candidate, if longer) from a start every
    `stride` samples of the whole record, padded past its end (the last sample repeated), and keeps the windows and
    steps `window_simulation_errors` has: a rollout is causal, so its first steps do not read the padding, and each
    window keeps its index (its place in XLA's vector loop).

    A model with internal states (`history_steps`: an input lag's or delay's filter, `Stiction`'s memory) starts them
    along the `HISTORY_S` of record before each window, the record's first sample repeated before its start
    (`with_history`), as `window_simulation_errors` does; one without takes the program it always took."""
    from .._simulate import FixedGrid, rollouts_from_starts, window_simulation_errors
    from .._simulate._sim_error import history_steps, with_history

    n, steps = len(rec), int(np.max(np.maximum(np.round(np.asarray(candidates_s, float) / dt).astype(int), 1)))
    if jax.device_count() > 1 or n < steps + 1:  # sharded (or too short, for its error): as it was
        return np.asarray(window_simulation_errors(model, rec, candidates_s, stride=stride))
    n_program = max(steps, int(round(LONGEST_FIT_WINDOW_S / dt)))
    kept = len(range(0, n - steps, stride))
    starts = np.arange(0, n - 1, stride)
    ts, xs, us = (np.asarray(a) for a in (rec.ts, rec.xs, rec.us))
    # `filter_jit` keys its cache on weak types too: the starting model (made from Python floats) has weak parameters,
    # the fitted nominal strong ones. Where every array has the record's dtype, weak or strong gives the same types
    # throughout, so the same program; strongly typed through the host (no compiled conversion).
    strong = lambda a: jax.device_put(np.asarray(a)) if _weak(a, xs.dtype) else a  # noqa: E731
    model = jax.tree.map(strong, model)
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], n_program, axis=0)])  # noqa: E731
    ts_pad = np.concatenate([ts, ts[-1] + (ts[-1] - ts[-2]) * np.arange(1, n_program + 1)])
    ts_pad, xs_pad, us_pad = ts_pad, pad(xs), pad(us)
    n_before = history_steps(model, len(rec.state_names), float(rec.dt))
    history = ()
    if n_before:  # the history before each window, as `window_simulation_errors` puts it there
        ts_pad, xs_pad, us_pad = with_history(ts_pad, xs_pad, us_pad, n_before, float(rec.dt))
        history = (n_before,)
    errors, _ = rollouts_from_starts(
        model,
        jax.device_put(ts_pad),
        jax.device_put(xs_pad),
        jax.device_put(us_pad),
        starts,
        n_program,
        FixedGrid(),
        *history,
    )
    return np.asarray(errors)[:kept, : steps + 1]


def _weak(a, dtype) -> bool:
    return isinstance(a, jax.Array) and a.weak_type and a.dtype == dtype


def fit_window(system, train_records, given, fraction, dt, notes) -> float:
    """The fit windows: `given`, or 2.5 times the starting model's predictability horizon on the training runs, in
    [0.25, 1] s."""
    if given is not None:
        return float(given)
    longest = min(1.0, 0.5 * min(r.duration for r in train_records))
    candidates_s = np.round(np.arange(0.1, longest + 1e-9, 0.05), 6)
    if candidates_s.size == 0:
        return longest
    start = reference_horizon(
        system,
        train_records,
        candidates_s,
        None,
        fraction,
        max(1, int(round(0.05 / dt))),
        list(system.position_indices),
        dt,
    )
    window = float(np.clip(2.5 * start.seconds, 0.25, longest))
    if window < longest:
        notes.append(
            f"The starting model predicts the training runs for {start.seconds:g} s only: the simulation-error "
            f"fits use {window:g} s windows (2.5 times that) instead of {longest:g} s."
        )
    return window


def holdout_split(rec: Trajectory, fraction: float = HOLDOUT_FRACTION) -> tuple[Trajectory, Trajectory]:
    """`(fitted, held_out)`: a record cut where `diagnose` cuts it without validation records (its last `fraction` held
    out)."""
    k = int(round(len(rec) * (1 - fraction)))
    return _slice(rec, 0, k), _slice(rec, k, len(rec))


def _slice(rec: Trajectory, a: int, b: int) -> Trajectory:
    # Cut on the host: a slice in JAX compiles a program for each record's length.
    cut = lambda v: jax.device_put(np.asarray(v)[a:b])  # noqa: E731
    return Trajectory(cut(rec.ts), cut(rec.xs), cut(rec.us), rec.state_names, rec.input_names, rec.system, rec.source)


def _cast(rec: Trajectory, dtype) -> Trajectory:
    return Trajectory(
        rec.ts.astype(dtype),
        rec.xs.astype(dtype),
        rec.us.astype(dtype),
        rec.state_names,
        rec.input_names,
        rec.system,
        rec.source,
    )
