"""The problem one diagnosis solves: the modes (`Refit`, `Known`), the settings (`Horizons`, `Selection`), and the
prepared records, candidate family, identifiable candidates and windows (`prepare_problem`, step 0 of `diagnose`).
"""

from collections.abc import Callable
import contextlib
import contextvars
import dataclasses
import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._context import set_within
from .._errors import UsageError
from .._identify._record_friction import compare_records
from .._model._extensions import Extended
from .._model._linear_in_parameters import friction_parameter_names
from .._model._system import AbstractSystem
from ._candidates import (
    candidate_scales,
    default_candidates,
    held_partners,
    host_nominal_values,
    look_alikes,
    sampled_sensitivities,
    stiction_not_proposed,
    structurally_absorbed,
    structurally_equivalent,
)
from ._fit import Family, make_windows, nominal_parameter_names, Windows
from ._records import (
    fit_window,
    horizon_grid,
    MIN_BLOCK_HORIZONS,
    MIN_CROSS_FIT_RUNS,
    prepare_records,
    velocity_estimates,
)
from ._selection import on_physical_side
from ._settings import DEFAULT_HORIZONS_S, Horizons, Selection

# A static friction level counts as stiction when it stands this share above the joint's Coulomb level (and two
# standard errors): a breakaway within a tenth of the sliding level is not told from Coulomb friction by data.
STATIC_MARGIN = 0.1


FIT_WINDOW_STARTS = contextvars.ContextVar("dynax_fit_window_starts", default=1)  # `overlapping_fit_windows`


@contextlib.contextmanager
def overlapping_fit_windows(starts: int):
    """Within the block, `diagnose` cuts its records into fit windows that start every `1 / starts` of a window
    (the training windows, and the held-out runs cut alike for the output-error screening) instead of end to
    end: each sample then enters `starts` windows. For trying whether overlapping windows determine more."""
    if not (isinstance(starts, int) and starts >= 1):
        raise UsageError(f"overlapping_fit_windows: `starts` must be a positive integer, got {starts!r}")
    with set_within(FIT_WINDOW_STARTS, starts):
        yield


def fit_windows(records, n_fit: int) -> Windows:
    """`records` cut into the fit's windows of `n_fit` steps: end to end (inside `overlapping_fit_windows`,
    overlapping)."""
    stride = max(1, n_fit // FIT_WINDOW_STARTS.get()) if n_fit > 1 else n_fit
    return make_windows(records, n_fit, stride)


class Fold(NamedTuple):
    """A cross-fitting fold: the samples `start:stop` of training record `record`, held out in turn."""

    record: int
    start: int
    stop: int


def cross_fit_folds(train_records, n_long: int) -> tuple[Fold, ...]:
    """The cross-fitting folds: each training run with three or more (leave one run out), contiguous blocks of a
    single one, none with two.

    A single training run leaves no run to hold out. It is cut into `MIN_CROSS_FIT_RUNS` contiguous blocks
    (each at least `MIN_BLOCK_HORIZONS` of the longest reference horizon `n_long` long), each held out in turn with the
    fit's windows that share a sample with its test windows left out (`_forward._cross_fit`): the blocked
    cross-validation of time series (Racine 2000; Bergmeir and Benitez 2012), each fold fitting two thirds of
    the run. Two training runs are not cross-fitted (each fold would fit one run alone; see `_cross_fit`).
    Empty where the single run is too short for such blocks.
    """
    sizes = [len(r) for r in train_records]
    if len(sizes) >= MIN_CROSS_FIT_RUNS:
        return tuple(Fold(r, 0, n) for r, n in enumerate(sizes))
    if len(sizes) > 1 or sizes[0] < MIN_CROSS_FIT_RUNS * MIN_BLOCK_HORIZONS * n_long:
        return ()
    edges = np.linspace(0, sizes[0], MIN_CROSS_FIT_RUNS + 1).round().astype(int)
    return tuple(Fold(0, int(lo), int(hi)) for lo, hi in zip(edges[:-1], edges[1:]))


class Refit(eqx.Module):
    """Diagnosis mode: the nominal parameters are refitted on the training data with every candidate.

    By default every nominal parameter is refitted **but the nominal model's friction** (the
    parameters `base_parameter_meanings` puts in the group `"friction"`: `theta6`, `theta7` of a
    two-link arm), which keeps its nominal value: friction is what the diagnosis names, and a
    refit of it would absorb the very effects under test (a refitted viscous coefficient soaks up
    most of a Coulomb friction's effect on short windows). The friction candidates test it
    instead; a viscous friction candidate adds to the nominal's own coefficient and may lower it,
    not below zero. Causes that a change of the refitted parameters reproduces exactly, alone or
    with a change of the kept friction, are not identifiable in this mode (a rotor inertia at the
    acrobot's shoulder adds to theta1; its input gain rescales theta1..theta5 and the friction) and
    are reported as such.

    **Arguments:** `parameters`, the names of the nominal parameters to refit (default all but the
    friction, e.g. `theta1..theta5`; all of them, `theta1..theta7`, to let the refit absorb
    viscous friction too; `("mass", "viscous")` for a linear axis whose nominal
    viscous friction is not trusted).
    """

    parameters: tuple[str, ...] | None = None


class Known(eqx.Module):
    """Diagnosis mode: the nominal parameters are trusted (datasheet, CAD, an earlier identification) and kept.

    Every candidate is identifiable; only the candidates' coefficients are fitted.
    """


@dataclasses.dataclass
class Problem:
    """Everything fixed for one diagnosis: records, candidates, the candidate family, windows."""

    system: AbstractSystem
    train: list
    validation: list
    dt: float
    notes: list
    candidates: tuple
    refit_names: tuple
    family: Family
    scales: np.ndarray
    inits: np.ndarray
    searchable: list
    not_identifiable: list
    partners: list
    fit_window_s: float
    train_windows: Windows
    val_windows: Windows
    window_runs: np.ndarray
    val_stride: int
    horizons: np.ndarray
    candidates_s: np.ndarray
    horizon_settings: Horizons
    selection: Selection
    velocities: str = "as measured"
    # The cross-fitting folds (`cross_fit_folds`): training runs or blocks of them, each held out in turn;
    # empty when off.
    folds: tuple[Fold, ...] = ()
    # Candidates that are one model with a refit of the nominal parameters (`structurally_equivalent`).
    equivalents: dict = dataclasses.field(default_factory=dict)
    # Causes of the default vocabulary the records give no occasion to try (`stiction` without a rest under load).
    not_proposed: list = dataclasses.field(default_factory=list)
    # Where the held nominal values are a one-step fit of the recorded inputs (the quadrotor's motor map): that
    # fit redone with the inputs as given terms with input dynamics pass them on (a tuple of terms at their
    # coefficients -> (nominal values, the fit's loss, its number of residuals)); `None` elsewhere.
    nominal_through: Callable[[tuple], tuple[np.ndarray, float, int]] | None = None

    def look_alikes(self, k: int) -> list[int]:
        """The candidates data could mistake for candidate `k`: its look-alikes and its structural equivalents."""
        return list(
            dict.fromkeys(look_alikes(self.system, self.candidates[k], self.candidates) + self.equivalents.get(k, []))
        )

    @functools.cached_property
    def held_out_fit_windows(self) -> Windows:
        """The held-out records cut as the refit's training windows (the fit's length, not overlapping): the
        output-error screening scores its steps on them, with the training windows' shape, so one compilation
        serves both and every round."""
        n_fit = self.train_windows.ts.shape[1] - 1
        return fit_windows(self.validation, n_fit)

    @property
    def names(self) -> tuple[str, ...]:
        return self.family.names

    @property
    def neutral(self) -> np.ndarray:
        return np.asarray(self.family.neutral)

    @property
    def state_scale(self) -> np.ndarray:
        return np.asarray(self.family.state_scale)

    @property
    def position_index(self) -> list[int]:
        return list(self.system.position_indices)

    @property
    def n_params(self) -> int:
        return len(self.names) + self.selection.max_terms + 1

    def physical(self, k: int, delta: float) -> bool:
        """Whether candidate `k` at `delta` from neutral is physical: on the physical side of neutral
        (friction, inertia, delay), and, where it adds to a nominal parameter that is not refitted,
        with the sum inside that parameter's consistency bound (a viscous coefficient stays non-negative)."""
        return on_physical_side(self.candidates[k], delta, self.partners[k], self.names, self.system)

    def static_level(self, k: int, p_row, std_row, selected, round_levels=None) -> bool | None:
        """Whether each static friction level (`stiction`) of the configuration `selected + [k]` at parameters
        `p_row` stands above the Coulomb level at its joint by `STATIC_MARGIN` of it and by two standard errors;
        `None` without a static level in it.

        A static level at or below the Coulomb level holds the joint at rest and adds nothing in motion: it is
        what a Coulomb friction does at rest (its force is set-valued at zero speed), not a breakaway above it,
        and the finding would name a stiction where the rig has none (the creep of a smoothed Coulomb friction
        is what it mends). The Coulomb level is the configuration's own; for a static level newly added (`k`) at a
        joint without one, the level the Coulomb friction candidate there was refitted to in the same round
        (`round_levels`: candidate index to its coefficient's step from neutral; the look-alikes of a leading
        stiction are always refitted), else zero."""
        n_nom = len(self.names)
        members = [(s, n_nom + m) for m, s in enumerate(selected)] + [(k, len(p_row) - 1)]
        levels: dict = {}
        for c, i in members:
            term = self.candidates[c]
            levels.setdefault(term.cause, {})[getattr(term, "joint", None)] = (
                float(self.neutral[c] + p_row[i]),
                float(std_row[i]),
            )
        static = levels.get("stiction")
        if not static:
            return None
        coulomb = {j: level for j, (level, _) in levels.get("coulomb_friction", {}).items()}
        new = self.candidates[k]
        if new.cause == "stiction" and new.joint not in coulomb:
            for c, step in (round_levels or {}).items():
                if self.candidates[c].cause == "coulomb_friction" and self.candidates[c].joint == new.joint:
                    coulomb[new.joint] = max(float(self.neutral[c] + step), 0.0)
        return all(
            fs - coulomb.get(j, 0.0) > max(STATIC_MARGIN * coulomb.get(j, 0.0), 2.0 * std)
            for j, (fs, std) in static.items()
        )

    def model_of(self, slots, p):
        """The extended model (every candidate; neutral but for `slots`) at parameters `p`."""
        # The coefficients on the host (`Family.host_coefficients`): eagerly, `model_for`'s one-hot product and the
        # unstacking of the coefficients compile a program each.
        p = np.asarray(p, self.family.neutral.dtype)
        values = jax.device_put(p[: len(self.names)])
        return self.family.build(values, self.family.host_coefficients(slots, -1, p))


def check_arguments(system, mode, horizons, selection) -> None:
    if not isinstance(system, AbstractSystem) or isinstance(system, Extended):
        raise UsageError(f"diagnose: `system` must be a nominal dynax system, got {type(system).__name__}")
    if not isinstance(mode, (Refit, Known)):
        raise UsageError(f"diagnose: `mode` must be Refit() or Known(), got {type(mode).__name__}")
    if not isinstance(horizons, Horizons):
        raise UsageError(f"diagnose: `horizons` must be a dynax.Horizons, got {type(horizons).__name__}")
    if not isinstance(selection, Selection):
        raise UsageError(f"diagnose: `selection` must be a dynax.Selection, got {type(selection).__name__}")


def names_to_refit(system, mode) -> tuple[str, ...]:
    names = nominal_parameter_names(system)
    if isinstance(mode, Known):
        return ()
    friction = friction_parameter_names(system)
    refit = tuple(n for n in names if n not in friction) if mode.parameters is None else tuple(mode.parameters)
    unknown = set(refit) - set(names)
    if unknown:
        raise UsageError(
            f"diagnose: Refit(parameters=...) names {sorted(unknown)}, not parameters of {type(system).__name__} "
            f"{names}"
        )
    return refit


def candidate_family(system, candidates, refit_names, train_records):
    """The `Family` (nominal system with every candidate at neutral), the candidates' scales and start values."""
    names = nominal_parameter_names(system)
    dtype = jnp.result_type(float)
    scales, inits = candidate_scales(system, candidates, train_records)
    p0 = np.asarray(host_nominal_values(system, names), float)
    xs_train = np.concatenate([np.asarray(r.xs) for r in train_records])
    family = Family(
        model=Extended(system, candidates),
        names=names,
        refit=jnp.asarray([1.0 if n in refit_names else 0.0 for n in names], dtype),
        nominal_scale=jnp.asarray(np.maximum(np.abs(p0), 1e-2), dtype),
        candidate_scale=jnp.asarray(scales, dtype),
        candidate_init=jnp.asarray(inits, dtype),
        neutral=jnp.asarray(np.asarray([t.neutral for t in candidates], float), dtype),
        state_scale=jnp.asarray(np.maximum(xs_train.std(axis=0), 1e-9), dtype),
    )
    return family, scales, inits


def vehicle_state_groups(system) -> tuple[tuple[int, ...], ...]:
    """A rigid-body vehicle's states in the groups its prediction error is scored by (`flight_state_scale`):
    position, attitude, body velocity, body rates (the system's `position_indices`, the states between them and
    its `velocity_indices`, which are the body axes' `u, v, w` then `p, q, r`) for a vehicle whose class asks for it
    (`score_by_group`: the quadrotor's body-frame system, whose flights carry a noisy gyro); empty otherwise (a
    manipulator, a linear axis, the helicopter), whose states are each scaled by their spread. The helicopter keeps
    the spread: scored by group, the second component of a two-component wind (3.5 m/s north, 2 east) gains 3.2 %
    on the typical window and is stopped by the 5 % smallest gain."""
    if not (system.body_axes and getattr(system, "score_by_group", False)):
        return ()
    position = tuple(system.position_indices)
    velocity = tuple(system.velocity_indices)
    attitude = tuple(i for i in range(system.n_states) if i not in position + velocity)
    half = len(velocity) // 2
    return tuple(g for g in (position, attitude, velocity[:half], velocity[half:]) if g)


# A group's scale is at least this share of its states' spread: an error below it is not one a record shows (a
# noise-free record that the starting model follows to the integrator's precision would otherwise weigh it).
MIN_ERROR_SCALE = 1e-3


def flight_state_scale(system, train_records, horizon_s: float, dt: float, groups) -> np.ndarray | None:
    r"""A rigid-body vehicle's state scale: every state of a group (`vehicle_state_groups`) in units of the
    starting model's typical open-loop error of that group, $s_g^2 = \sum_{i\in g}\overline{e_i^2}$ over the
    windows every 0.05 s of the training records and their steps up to `horizon_s` (the longest candidate
    reference horizon).

    Within a group the error keeps its units (a position error is a distance whatever the axis); across groups
    each counts alike relative to what the starting model misses there, so the window score's gain is about the
    mean of the four groups' gains, and the refit weighs each group by its error variance (the diagonal weighting
    of feasible generalised least squares, by group). The training spread instead puts the position in metres
    against centimetres of error over half a second, and the rates' gyro noise, carried open loop, then carries
    the score (a rotor drag that changes the position at 0.4 s by 76 % moved it by 3 %). `None` where too few
    windows stay finite (the spread is used)."""
    from .._simulate import window_simulation_errors  # `simulation_error`'s rollouts, without its summaries

    # The same windows as `_records.fit_window`'s starting model (one compiled program for both).
    longest = min(1.0, 0.5 * min(r.duration for r in train_records))
    candidates_s = np.round(np.arange(0.1, longest + 1e-9, 0.05), 6)
    if candidates_s.size == 0:
        candidates_s = np.asarray([longest])
    stride = max(1, int(round(0.05 / dt)))
    n = max(1, int(round(horizon_s / dt)))
    errors = np.concatenate(
        [
            np.asarray(window_simulation_errors(system, rec, candidates_s, stride=stride))[:, 1 : n + 1]
            for rec in train_records
        ]
    )
    finite = np.isfinite(errors).all(axis=(1, 2))
    if finite.mean() < 0.5:
        return None
    mse = np.mean(errors[finite] ** 2, axis=(0, 1))
    spread = np.concatenate([np.asarray(r.xs) for r in train_records]).std(axis=0)
    scale = np.maximum(spread, 1e-9)
    for g in groups:
        g = list(g)
        scale[g] = max(float(np.sqrt(np.sum(mse[g]))), MIN_ERROR_SCALE * float(np.sqrt(np.sum(spread[g] ** 2))), 1e-12)
    return scale


def _identifiable(system, candidates, family, refit_names, partners, mode, sensitivities):
    """`(searchable indices, not_identifiable entries)`: candidates a refit of the nominal parameters reproduces are set
    aside.

    In `Refit` mode the kept parameters that candidates test (the nominal friction, `partners`) are not
    trusted either: a candidate that a refit reproduces together with a change of them (the acrobot's input
    gain: rescaling theta1..theta5 *and* the friction) cannot be told from a friction error, and is set aside
    too. The candidates that are those parameters (viscous friction) stay.
    """
    refit = np.asarray(family.refit) > 0
    absorbed = structurally_absorbed(family, refit, sensitivities=sensitivities)
    tested = sorted({p[0] for p in partners if p is not None})
    if isinstance(mode, Refit) and tested:
        with_tested = refit.copy()
        with_tested[tested] = True
        absorbed_with_tested = structurally_absorbed(family, with_tested, sensitivities=sensitivities)
    else:
        absorbed_with_tested = absorbed
    not_identifiable, searchable = [], []
    for k, term in enumerate(candidates):
        if absorbed[k]:
            reason = (
                f"a refit of the nominal parameters ({', '.join(refit_names)}) reproduces it exactly; "
                "diagnose in Known() mode with trusted parameters to test it"
            )
        elif absorbed_with_tested[k] and partners[k] is None:
            kept = ", ".join(family.names[i] for i in tested)
            reason = (
                f"a refit of the nominal parameters ({', '.join(refit_names)}) with a change of the kept ones "
                f"the candidates test ({kept}) reproduces it exactly, so it cannot be told from an error in "
                "those; diagnose in Known() mode with trusted parameters to test it"
            )
        else:
            searchable.append(k)
            continue
        not_identifiable.append({"cause": term.cause, "where": term.where(system), "reason": reason})
    if not searchable:
        raise UsageError("diagnose: no candidate is identifiable in this mode")
    return searchable, not_identifiable


def prepare_problem(system, train, validation, candidates, mode, horizons: Horizons, selection: Selection) -> Problem:
    """Step 0: records on one grid, the candidates and their identifiability, the training and held-out windows."""
    notes: list[str] = []
    train_records, validation_records, dt = prepare_records(
        system, train, validation, selection.holdout_fraction, notes
    )
    _note_record_differences(system, train_records + (validation_records if validation is not None else []), notes)
    train_records, validation_records, velocities = velocity_estimates(
        system, train_records, validation_records, selection.velocities, notes
    )
    not_proposed = stiction_not_proposed(system, train_records) if candidates is None else []
    candidates = tuple(default_candidates(system, train_records) if candidates is None else candidates)
    if not candidates:
        raise UsageError("diagnose: `candidates` is empty")
    Extended(system, candidates)  # checks every candidate fits this system
    refit_names = names_to_refit(system, mode)
    family, scales, inits = candidate_family(system, candidates, refit_names, train_records)
    sensitivities = sampled_sensitivities(family)  # the structural tests' one sample of the vector field's derivatives
    partners = held_partners(family, 1.0 - np.asarray(family.refit), sensitivities=sensitivities)
    searchable, not_identifiable = _identifiable(system, candidates, family, refit_names, partners, mode, sensitivities)
    # Candidates that add to a held nominal parameter (viscous friction) are that parameter, not an equivalent.
    equivalents = structurally_equivalent(
        family, family.refit, [k for k in searchable if partners[k] is None], sensitivities=sensitivities
    )
    _note_held(system, family, refit_names, mode, notes)
    fit_window_s = fit_window(system, train_records, horizons.fit_window_s, horizons.fraction, dt, notes)
    n_fit = max(2, int(round(fit_window_s / dt)))
    grid, candidates_s = horizon_grid(
        horizons.reported(DEFAULT_HORIZONS_S),
        horizons.reference_s,
        train_records,
        validation_records,
        notes,
        cross_fit=selection.cross_fit,
    )
    family = _vehicle_scaled(system, family, train_records, float(candidates_s.max()), dt, notes)
    val_stride = max(1, int(round(0.05 / dt)))
    val_windows = make_windows(validation_records, int(round(grid.max() / dt)), val_stride)
    cross_fit = selection.cross_fit
    folds = cross_fit_folds(train_records, int(round(candidates_s.max() / dt))) if cross_fit else ()
    if cross_fit and len(train_records) == MIN_CROSS_FIT_RUNS - 1:
        notes.append(
            f"Not cross-fitted: with {len(train_records)} training runs each fold would fit one run alone, and "
            "a model refitted on one run is judged for that run's excitation (two-fold cross-validation "
            "penalises every added term); the test is on the held-out runs alone. Three or more training "
            "runs are cross-fitted, and a single one by blocks."
        )
    elif cross_fit and not folds:
        notes.append(
            f"Not cross-fitted: the training run is too short to hold out {MIN_CROSS_FIT_RUNS} blocks of "
            f"{MIN_BLOCK_HORIZONS} times the longest reference horizon; the test is on the held-out runs alone."
        )
    elif folds and len(train_records) >= MIN_CROSS_FIT_RUNS:
        notes.append(
            f"Cross-fitting: besides the held-out runs, each of the {len(folds)} training runs was held out in "
            "turn, every configuration refitted on the other training runs (leave-one-run-out), and the test "
            "pools those windows with the held-out ones; the gains reported are the held-out runs' "
            "(Selection(cross_fit=False) tests on the held-out runs alone)."
        )
    elif folds:
        notes.append(
            f"Cross-fitting: besides the held-out runs, the training run was cut into {len(folds)} contiguous "
            "blocks, each held out in turn and every configuration refitted on the rest (the fit's windows next "
            "to the block left out too: blocked cross-validation), and the test pools those windows with the "
            "held-out ones; the gains reported are the held-out runs' (Selection(cross_fit=False) tests on the "
            "held-out runs alone)."
        )
    return Problem(
        system=system,
        train=train_records,
        validation=validation_records,
        dt=dt,
        notes=notes,
        candidates=candidates,
        refit_names=refit_names,
        family=family,
        scales=scales,
        inits=inits,
        searchable=searchable,
        not_identifiable=not_identifiable,
        partners=partners,
        fit_window_s=fit_window_s,
        train_windows=fit_windows(train_records, n_fit),
        val_windows=val_windows,
        window_runs=np.asarray(val_windows.starts)[:, 0],
        val_stride=val_stride,
        horizons=grid,
        candidates_s=candidates_s,
        horizon_settings=horizons,
        selection=selection,
        velocities=velocities,
        folds=folds,
        equivalents=equivalents,
        not_proposed=not_proposed,
    )


def _vehicle_scaled(system, family, train_records, horizon_s, dt, notes):
    """`family` with a rigid-body vehicle's states scaled by group (`flight_state_scale`); unchanged elsewhere."""
    groups = vehicle_state_groups(system)
    if not groups:
        return family
    scale = flight_state_scale(system, train_records, horizon_s, dt, groups)
    if scale is None:
        notes.append(
            "The starting model diverges on most training windows: the states are scaled by their spread on the "
            "training records, not by the starting model's error per group."
        )
        return family
    return eqx.tree_at(lambda f: f.state_scale, family, jnp.asarray(scale, family.state_scale.dtype))


def _note_record_differences(system, records, notes) -> None:
    """Say so when the runs' recorded forces carry constant offsets that differ from run to run
    (`dynax.internal.record_offsets`, on the inverse-dynamics equations of the nominal model's structure as
    `identify` builds them; the held-out runs too when they are the user's own): a sensor zero that
    no candidate can carry from one run to another, and that stays in each held-out run's error
    whatever is named (a motor driver's current sensor, zeroed anew in each recording). Likewise when
    the runs' Coulomb friction differs (`dynax.internal.record_friction`: it changes with temperature and wear).
    Notes only: they enter no test.

    Only differences that are significant after multiplicity and of practical size are noted
    (`_record_differences_that_matter`)."""
    offsets, friction = compare_records(system, records)
    for check in _record_differences_that_matter(offsets, friction, records):
        notes.append(
            check.note() + f" (p-values Holm-adjusted over the {_n_comparisons(offsets, friction)} "
            "comparisons of records; differences of practical size only.)"
        )


def _n_comparisons(*checks) -> int:
    return sum(len(c.p_value) for c in checks if c is not None)


def _record_differences_that_matter(offsets, friction, records) -> list:
    """The checks of `compare_records` with what is not worth a note taken out, as copies whose `p_value` is
    Holm-adjusted over every comparison made (each joint's offset, each Coulomb coefficient: several tests of one
    family, Holm 1979) and set to 1 where the difference is not of practical size:

    - a Coulomb friction whose records' values spread by less than `MIN_PRACTICAL_GAIN` (a quarter) of the
      value one friction for all records takes, or where that value is not positive (no friction to differ);
    - an offset whose records' values spread by less than `MIN_PRACTICAL_GAIN` of the records' largest RMS
      recorded force (the rig's force scale: a sensor zero that small changes no simulation noticeably).
    """
    from ._statistics import holm_adjusted
    from ._verdict import MIN_PRACTICAL_GAIN

    checks = [c for c in (offsets, friction) if c is not None]
    if not checks:
        return []
    adjusted = holm_adjusted(np.concatenate([np.asarray(c.p_value, float) for c in checks]))
    force_scale = max(
        (float(np.sqrt(np.mean(np.asarray(r.us, float) ** 2, axis=0)).max()) for r in records), default=0.0
    )
    kept, start = [], 0
    for c in checks:
        p = adjusted[start : start + len(c.p_value)].copy()
        start += len(c.p_value)
        if c is offsets:
            spread = np.ptp(np.asarray(c.offsets, float), axis=0)
            p[spread < MIN_PRACTICAL_GAIN * force_scale] = 1.0
        else:
            spread = np.ptp(np.asarray(c.values, float), axis=0)
            shared = np.asarray(c.shared, float)
            p[~((shared > 0) & (spread >= MIN_PRACTICAL_GAIN * np.abs(shared)))] = 1.0
        c = dataclasses.replace(c, p_value=p)
        if c.differ():
            kept.append(c)
    return kept


def _note_held(system, family, refit_names, mode, notes) -> None:
    """Say which nominal parameters a `Refit()` keeps, and why."""
    if not isinstance(mode, Refit):
        return
    held = [n for n, r in zip(family.names, np.asarray(family.refit)) if r == 0]
    if held and mode.parameters is None:
        values = host_nominal_values(system, family.names)
        notes.append(
            "Refit mode refits "
            + ", ".join(refit_names)
            + "; the nominal model's friction ("
            + ", ".join(f"{n} = {float(values[family.names.index(n)]):.4g}" for n in held)
            + ") keeps its value and the friction candidates test it (Refit(parameters=...) "
            "chooses otherwise)."
        )
