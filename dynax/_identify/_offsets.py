r"""Per-record offsets of the recorded forces: does each record carry a constant of its own?

A force or torque sensor (a motor driver's current measurement) can read a constant too much or
too little, and by a different amount in each recording session (its zero is set at start-up, it
drifts with temperature). No model term carries that from one record to the next: an offset fitted
on some records is wrong on another, and a held-out record simulated with its recorded torque
carries its offset as error (measured on a real rig: `experiments/dfki_torque_offsets.py`,
docs/devdocs/record_offsets.md).

`record_offsets` adds to the stacked inverse-dynamics equations of `identify`'s `Dynamic()` stage one
constant per record, joint and *half* of the record (the base parameters stay shared) and asks, per
joint, whether the records' offsets differ by more than the two halves of a record differ from each
other: a one-way analysis of variance with the records as groups and their halves as replicates,
$F = \frac{2 \sum_r (\bar o_r - \bar o)^2 / (R - 1)}{\sum_r \sum_h (o_{rh} - \bar o_r)^2 / R}$ on
$(R-1, R)$ degrees of freedom (Scheffé, *The Analysis of Variance*, 1959, ch. 7, the one-way random
effects model). The halves make the test honest under autocorrelated residuals: each half's
offset is an average over thousands of filtered, correlated rows, whose naive standard error would be
far too small, while two halves of one record are two independent measurements of the same sensor
zero. An offset that is model error rather than a sensor's (it follows the motion) differs between
the halves and weakens the test instead of passing it (on a chaotic run its halves can differ in sign).

Estimating per-experiment offsets as parameters is standard practice (Ljung, *System
Identification*, 2nd ed., 1999, sec. 14.1). Here they are reported, not used: the model `identify`
returns has no offset term, and a held-out record's offset is not known from the others.
"""

import dataclasses
import pathlib

import numpy as np

from ._regressors import split_terms

ALPHA = 0.01  # the offsets "differ between records" below this p-value


@dataclasses.dataclass(frozen=True)
class RecordOffsets:
    r"""Each record's constant offset on each joint's equation, and whether the records differ.

    **Fields:** `records` (labels: file names where known), `joints` (position names), `offsets`
    `(record, joint)` in the force's unit: what the record's recorded force exceeds the model's by
    (positive: the sensor reads high); `halves`
    `(record, 2, joint)` the same from each half of the record; `f_statistic`, `p_value` `(joint,)`
    the one-way analysis of variance of the halves' offsets across records (see the module);
    `estimate` the shared parameters fitted with the offsets (the equations' columns, in order) and
    `relative_error` that fit's relative equation error; `alpha` the level at which `differ` says so.
    """

    records: tuple[str, ...]
    joints: tuple[str, ...]
    offsets: np.ndarray
    halves: np.ndarray
    f_statistic: np.ndarray
    p_value: np.ndarray
    estimate: np.ndarray
    relative_error: float
    alpha: float = ALPHA

    def differ(self) -> tuple[str, ...]:
        """The joints whose records' offsets differ (p < `alpha`)."""
        return tuple(j for j, p in zip(self.joints, self.p_value) if p < self.alpha)

    def note(self) -> str | None:
        """A sentence for the user where the records' offsets differ; `None` where they do not."""
        differ = self.differ()
        if not differ:
            return None
        labels = self.records
        parts = []
        for name in differ:
            j = self.joints.index(name)
            values = ", ".join(f"{label} {self.offsets[r, j]:+.3g}" for r, label in enumerate(labels))
            parts.append(f"at {name} ({values}; F = {self.f_statistic[j]:.3g}, p = {self.p_value[j]:.2g}")
        return (
            "The recorded force or torque carries an offset that differs from record to record "
            + "; ".join(parts)
            + "): the records differ by more than the two halves of a record do, as a "
            "sensor's zero would, which no model term carries to another record; a held-out record simulated "
            "with its recorded force carries its own offset as error."
        )

    def to_json(self) -> dict:
        return {
            "records": list(self.records),
            "joints": list(self.joints),
            "offsets": self.offsets.tolist(),
            "halves": self.halves.tolist(),
            "f_statistic": self.f_statistic.tolist(),
            "p_value": self.p_value.tolist(),
            "alpha": self.alpha,
            "differ": list(self.differ()),
            "relative_equation_error": self.relative_error,
            "note": self.note(),
        }


def record_offsets(a, y, counts, joints, records=None, alpha: float = ALPHA) -> RecordOffsets | None:
    """Per-record, per-half offsets of stacked inverse-dynamics equations, and their analysis of variance.

    **Arguments:** `a`, `y` the equations stacked joint by joint (all records' rows of the first joint,
    then of the second, ...), as `identify`'s `Dynamic()` stage builds them; `counts` each record's rows
    per joint; `joints` the joints' position names; `records` their labels (default `record 0`, ...).

    **Returns:** a `RecordOffsets`, or `None` with fewer than two records or a record too short to halve.
    """
    a, y = np.asarray(a, float), np.asarray(y, float)
    n_records, n_joints = len(counts), len(joints)
    if n_records < 2 or min(counts) < 4 or a.shape[0] != n_joints * sum(counts):
        return None
    # One group per (record, half, joint). Regressing on one indicator column per group is the same as
    # removing each group's mean from `a` and `y` (Frisch-Waugh-Lovell), which needs no indicator matrix.
    joint_of_row = np.repeat(np.arange(n_joints), sum(counts))
    groups = [half for r in range(n_records) for half in np.array_split(record_rows(counts, r, 0), 2)]
    groups = [rows + j * sum(counts) for rows in groups for j in range(n_joints)]
    a_within, y_within, a_means, y_means = without_offsets(a, y, None, groups)
    # The weights are constant within each group, so the group means need no weighting.
    theta, residual = joint_weighted_least_squares(a_within, y_within, joint_of_row, n_joints)
    by_group = y_means - a_means @ theta
    # The equations are model force = recorded force; an offset column fitted into the model side
    # stands for what the recorded force has in excess.
    halves = by_group.reshape(n_records, 2, n_joints)
    offsets = halves.mean(axis=1)
    # Exact equations (no residual at all) leave both at rounding level: no evidence either way, F = 0.
    f, p = parts_anova(halves, tiny=(1e-9 * float(np.sqrt(np.mean(y**2)))) ** 2)
    relative_error = float(np.linalg.norm(residual) / np.linalg.norm(y))
    records = tuple(records) if records is not None else tuple(f"record {r}" for r in range(n_records))
    return RecordOffsets(records, tuple(joints), offsets, halves, f, p, theta, relative_error, alpha)


def driven_joints(system) -> tuple[int, ...] | None:
    """The indices of the joints some input acts on (an unactuated joint's equation has no sensor to
    be off), or `None` where the system's own model has a constant term (a linear axis's `offset`)
    or drives no joint."""
    base = split_terms(system)[0]
    if "offset" in base.base_parameter_names("coulomb") or not hasattr(base, "input_matrix"):
        return None
    driven = np.flatnonzero(np.any(np.abs(np.asarray(base.input_matrix())) > 0, axis=1))
    return tuple(int(j) for j in driven) or None


def offset_groups(system, counts) -> list[np.ndarray] | None:
    """The row groups of the stacked dynamic equations (joint-major, `counts` rows per record) that
    each carry one constant offset: one per record and driven joint (`driven_joints`), in that order
    (all records of the first driven joint, then of the next). `None` where `driven_joints` is."""
    driven = driven_joints(system)
    if driven is None:
        return None
    return [record_rows(counts, r, j) for j in driven for r in range(len(counts))]


def joint_weighted_least_squares(a, y, joint_of_row, n_joints):
    """Least squares, unweighted and then each joint's rows by its residual scale (`Dynamic()`'s joint
    weighting): `(theta, residual)`."""
    weights = np.ones(len(y))
    for _ in range(2):
        theta = np.linalg.lstsq(a * weights[:, None], y * weights, rcond=None)[0]
        residual = y - a @ theta
        scale = np.sqrt([np.mean(residual[joint_of_row == j] ** 2) for j in range(n_joints)])
        weights = 1.0 / np.maximum(scale, np.finfo(float).tiny)[joint_of_row]
    return theta, residual


def parts_anova(parts: np.ndarray, tiny: float) -> tuple[np.ndarray, np.ndarray]:
    r"""The one-way analysis of variance of `parts` `(record, K, k)`: per column, the records as groups
    and each record's $K$ parts as replicates (see the module; `record_offsets` uses halves, $K = 2$).
    **Returns:** `(F, p)` on $(R-1, R(K-1))$ degrees of freedom. Mean squares below `tiny` (exact
    equations) count as none: F = 0 where both are, infinite where only the within-record one is."""
    n_records, k = parts.shape[:2]
    means = parts.mean(axis=1)
    between = k * np.sum((means - means.mean(axis=0)) ** 2, axis=0) / (n_records - 1)
    within = np.sum((parts - means[:, None, :]) ** 2, axis=(0, 1)) / (n_records * (k - 1))
    f = np.where(within > tiny, between / np.maximum(within, tiny), np.where(between > tiny, np.inf, 0.0))
    import scipy.stats  # not at import time: `import dynax` stays light (tests/cli/test_packaging.py)

    return f, scipy.stats.f.sf(f, n_records - 1, n_records * (k - 1))


def record_rows(counts, record, joint):
    """The rows of `record`'s equations of `joint` in the stacked dynamic equations (joint-major:
    all records' rows of joint 0, then of joint 1, ...; `counts` rows per record)."""
    start = int(joint * sum(counts) + sum(counts[:record]))
    return np.arange(start, start + counts[record])


def without_offsets(a, y, weights, groups):
    """`(a, y)` with each group's (weighted) mean removed: least squares on them is least squares with
    one free constant per group (Frisch-Waugh-Lovell). Also returns the group means `(a_means,
    y_means)` from which each group's offset at an estimate $\theta$ is `y_means - a_means @ theta`."""
    a, y = np.array(a, dtype=float), np.array(y, dtype=float)
    w = np.ones(len(y)) if weights is None else np.asarray(weights, dtype=float)
    a_means, y_means = [], []
    for rows in groups:
        total = max(float(np.sum(w[rows])), np.finfo(float).tiny)
        a_means.append(w[rows] @ a[rows] / total)
        y_means.append(float(w[rows] @ y[rows] / total))
        a[rows] -= a_means[-1]
        y[rows] -= y_means[-1]
    return a, y, np.asarray(a_means), np.asarray(y_means)


def record_labels(records) -> list[str]:
    """Each record's file name where it has one, else `record i`."""
    return [pathlib.Path(r.source).name if r.source else f"record {i}" for i, r in enumerate(records)]
