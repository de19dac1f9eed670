r"""Per-record Coulomb friction: do the records agree on the friction, or does each have its own?

Dry friction is not a constant of a machine: it changes with the lubricant's temperature, with wear,
with the load on the bearings and from one start-up to the next (Armstrong-Hélouvry, Dupont and
Canudas de Wit, *Automatica* 30(7), 1994, sec. 2.3). A model fitted on some records carries their
friction to another record, and a held-out record whose friction differs keeps the difference as
simulation error, whatever the fit: a model fitted on records whose friction is low predicts a
record with a higher friction worse, and no fit on the others can know that record's value
(measured on a real rig: `experiments/dfki_record_friction.py`, docs/devdocs/record_friction.md).

`record_friction` asks the same question of the friction as `record_offsets` asks of a sensor's
zero, on the stacked inverse-dynamics equations of `identify`'s `Dynamic()` stage: each record's
constant offset per joint is removed first (Frisch-Waugh-Lovell, as there), then each Coulomb
friction column is split into one column per record (the records' values) and, in a second fit,
into one per record and *part* of the record (four consecutive parts by default; the other
parameters stay shared in both), and per column a one-way analysis of variance asks whether the
records' values differ by more than the parts of a record do
(`parts_anova`, $F$ on $(R-1, R(K-1))$ degrees of freedom; Scheffé 1959, ch. 7). The parts of one
record are measurements of the same friction under the same excitation, so a friction that changed
between recordings passes the test. Why four parts and not the two halves `record_offsets` uses:
on synthetic records of the rig (`experiments/record_friction_calibration.py`, 200 sets of four
records) four parts flagged records that share one friction no more often than the level says (1
of 200 at the 1 % level; halves 3) and saw a 0.02 N m spread between records three times as often
(38 of 200 against 13): more degrees of freedom within the records outweigh each part's noisier
value. The offsets are removed per record, not per part: within a part whose motion keeps one
direction, a per-part offset would be the friction itself. What it cannot tell apart: a model
error that looks like $\operatorname{sign}(\dot q)$ and that differs between differently
excited records (a wrong friction *shape*) passes it too. Either way the records disagree on the
Coulomb coefficient, and a held-out record's value is not known from the others.

Reported, not used: the model `identify` returns has one friction per joint.
"""

import dataclasses

import numpy as np

from .._errors import DataError, UsageError
from .._model._extensions import CoulombFriction
from ._equations import Dynamic, stacked_equations
from ._offsets import (
    ALPHA,
    joint_weighted_least_squares,
    parts_anova,
    record_labels,
    record_offsets,
    record_rows,
    RecordOffsets,
    without_offsets,
)
from ._regressors import split_terms

PARTS = 4  # parts per record (see the module)


@dataclasses.dataclass(frozen=True)
class RecordFriction:
    r"""Each record's Coulomb friction coefficients, and whether the records differ.

    **Fields:** `records` (labels: file names where known), `columns` (the coefficients' names,
    e.g. `fc1`, `fc2`), `values` `(record, column)` in the force's unit, one per record; `parts`
    `(record, K, column)` one per each of the record's $K$ consecutive parts (what the test compares); `shared`
    `(column,)` the value one coefficient for all records takes in the same equations; `f_statistic`, `p_value`
    `(column,)` the one-way analysis of variance of the parts' values across records (see the
    module); `relative_error` the relative equation error of the fit with a value per record
    (against
    `shared_relative_error` with one per column); `alpha` the level at which `differ` says so.
    """

    records: tuple[str, ...]
    columns: tuple[str, ...]
    values: np.ndarray
    parts: np.ndarray
    shared: np.ndarray
    f_statistic: np.ndarray
    p_value: np.ndarray
    relative_error: float
    shared_relative_error: float
    alpha: float = ALPHA

    def differ(self) -> tuple[str, ...]:
        """The coefficients whose records' values differ (p < `alpha`)."""
        return tuple(c for c, p in zip(self.columns, self.p_value) if p < self.alpha)

    def note(self) -> str | None:
        """A sentence for the user where the records' friction differs; `None` where it does not."""
        differ = self.differ()
        if not differ:
            return None
        parts = []
        for name in differ:
            k = self.columns.index(name)
            values = ", ".join(f"{label} {self.values[r, k]:.3g}" for r, label in enumerate(self.records))
            parts.append(
                f"{name} ({values}; one for all {self.shared[k]:.3g}; F = {self.f_statistic[k]:.3g}, "
                f"p = {self.p_value[k]:.2g})"
            )
        return (
            "The Coulomb friction differs from record to record: " + "; ".join(parts) + ". The records differ "
            "by more than the parts of a record do, as a friction that changed between recordings (or a "
            "friction whose shape the model lacks) would: a held-out record's friction is not known from the "
            "others, and its simulation carries the difference as error."
        )

    def to_json(self) -> dict:
        return {
            "records": list(self.records),
            "columns": list(self.columns),
            "values": self.values.tolist(),
            "parts": self.parts.tolist(),
            "shared": self.shared.tolist(),
            "f_statistic": self.f_statistic.tolist(),
            "p_value": self.p_value.tolist(),
            "alpha": self.alpha,
            "differ": list(self.differ()),
            "relative_equation_error": self.relative_error,
            "shared_relative_equation_error": self.shared_relative_error,
            "note": self.note(),
        }


def record_friction(
    a, y, counts, names, columns, records=None, alpha: float = ALPHA, parts: int = PARTS
) -> RecordFriction | None:
    """Per-record, per-part values of the Coulomb friction `columns` of stacked inverse-dynamics
    equations, and their analysis of variance.

    **Arguments:** `a`, `y` the equations stacked joint by joint (all records' rows of the first
    joint, then of the second, ...) as `identify`'s `Dynamic()` stage builds them, before any offset
    is removed; `counts` each record's rows per joint (`a` holds as many such blocks as joints);
    `names` the columns of `a`; `columns` those to test (their names); `records` labels (default
    `record 0`, ...); `parts` per record (fewer where the shortest record has under 8 rows per part,
    at least 2).

    **Returns:** a `RecordFriction`, or `None` with fewer than two records, a record too short to
    halve, or no column to test.
    """
    a, y = np.asarray(a, float), np.asarray(y, float)
    names, columns = list(names), tuple(c for c in columns if c in names)
    n_records, total = len(counts), sum(counts)
    if n_records < 2 or min(counts) < 4 or not columns or a.shape[0] % total:
        return None
    n_joints = a.shape[0] // total  # the rows are stacked joint by joint, `total` per joint
    k = int(max(2, min(parts, min(counts) // 8)))
    whole = [record_rows(counts, r, 0) for r in range(n_records)]
    pieces = [p for rows in whole for p in np.array_split(rows, k)]
    # Each record's offset per joint removed, as `identify` fits them: a sensor zero is not friction. (Per
    # part it would be, within a part whose motion keeps one direction, the friction itself.)
    a, y, _, _ = without_offsets(a, y, None, [rows + j * total for rows in whole for j in range(n_joints)])
    joint_of_row = np.repeat(np.arange(n_joints), total)
    tested = [names.index(c) for c in columns]
    kept = [i for i in range(len(names)) if i not in tested]

    def split(blocks):
        """One column per (tested column, block of rows): the column on that block's rows, zero elsewhere."""
        out = []
        for i in tested:
            for rows in blocks:
                column = np.zeros(len(y))
                for j in range(n_joints):
                    column[rows + j * total] = a[rows + j * total, i]
                out.append(column)
        return np.column_stack([a[:, kept]] + out)

    shared_theta, shared_residual = joint_weighted_least_squares(a, y, joint_of_row, n_joints)
    by_record, residual = joint_weighted_least_squares(split(whole), y, joint_of_row, n_joints)
    by_part, _ = joint_weighted_least_squares(split(pieces), y, joint_of_row, n_joints)
    values = by_record[len(kept) :].reshape(len(columns), n_records).T
    by_part = by_part[len(kept) :].reshape(len(columns), n_records, k).transpose(1, 2, 0)
    f, p = parts_anova(by_part, tiny=(1e-9 * float(np.sqrt(np.mean(y**2)))) ** 2)
    norm = float(np.linalg.norm(y))
    records = tuple(records) if records is not None else tuple(f"record {r}" for r in range(n_records))
    return RecordFriction(
        records,
        columns,
        values,
        by_part,
        shared_theta[tested],
        f,
        p,
        float(np.linalg.norm(residual)) / norm,
        float(np.linalg.norm(shared_residual)) / norm,
        alpha,
    )


def coulomb_columns(system, friction) -> tuple[str, ...]:
    """The names of the Coulomb friction coefficients among the equations' columns (`fc1`, `fc2` of an
    arm, `coulomb` of a linear axis) when `friction="coulomb"`; `record_friction` keeps those present."""
    if friction != "coulomb":
        return ()
    base, terms = split_terms(system)
    coulomb = [t for t in tuple(base.coulomb_friction_terms()) + tuple(terms) if isinstance(t, CoulombFriction)]
    return tuple(dict.fromkeys(t.parameter_name(base) for t in coulomb)) + ("coulomb",)


def compare_records(system, records, friction="coulomb") -> tuple[RecordOffsets | None, RecordFriction | None]:
    """`record_offsets` and `record_friction` of the inverse-dynamics equations that `identify(system,
    records, Dynamic(), friction=friction)` builds (filter settings chosen from each record's spectra),
    built once for both.

    **Returns:** `(None, None)` where the system has no such equations (it is not a two-link arm or a
    linear axis), a record is too short for them, or there are fewer than two records.
    """
    records = list(records)
    if len(records) < 2:
        return None, None
    try:
        base = split_terms(system)[0]
        _, a, y, _, names, _, _, _, counts, _ = stacked_equations(base, records, Dynamic(), friction, None, 1e-7)
    except (DataError, UsageError):  # not a system least squares knows, or a record too short for its filter
        return None, None
    labels = record_labels(records)
    return (
        record_offsets(a, y, counts, base.joint_names, labels),
        record_friction(a, y, counts, names, coulomb_columns(base, friction), labels),
    )
