r"""Stretches that two records share, sample for sample: an excerpt of a record given beside it.

A validation record cut out of a training record that is still given whole (the last ten seconds saved
to a file of their own, re-stamped from zero or not), two logs that overlap because a logger's files
overlap, or a record saved again with fewer digits are not new data: held-out error on such a stretch is
in-sample, and a stretch counted twice doubles its weight in a fit. Equality of whole records misses all
three, so the records are compared row by row on their states and inputs (times are not compared: an
excerpt may be re-stamped).

Two rows are the same sample when every column agrees within its tolerance: $10^{-4}$ of the column's
spread, or half the coarser of the two records' quanta where a record is stored with fewer digits.
Two repeats of one motion on a real rig never agree that closely in every state and input at once (the
sensors' noise alone parts them), while a copy agrees to its rounding. A shared stretch is a run of
at least `min_samples` rows that agree one for one in order, over which the record moves (its states
span 5 % of their spread or more): rows at rest, where two records may both read the same quantised pose
at zero input, share nothing that matters and are not counted.

Rows are matched through a k-d tree on the scaled columns (`scipy.spatial.KDTree`, max-norm), probing
at most about 5,000 rows of each record, and each run found is extended row by row to its exact ends. A copy
at a whole fraction of the rate (every second row kept) matches every `step`-th row of the original, and a
copy at a whole multiple of it (samples interpolated between the original's) holds every row of the original
at every `step`-th of its own (`shared_either_way`).

A copy resampled at another ratio (100 Hz read onto a 150 Hz or a jittered clock) shares no row: its rows lie
*between* the original's, on the path the original traces. `resampled_stretches` finds those: each probed row
of the copy is placed on the original's path, on the chord between two neighbouring rows (linear
interpolation) or on the cubic through four (a spline's, to within $h^4$), within the same tolerance in every
column; a stretch is a run of at least `min_samples` rows placed in order at one steady rate ratio. Two real
records never trace one path that closely in every state and input at once, any more than they share a row.
"""

import dataclasses

import numpy as np

from ._trajectory import Trajectory

RELATIVE_TOLERANCE = 1e-4  # rows agree within this fraction of each column's spread ...
MOVING = 0.05  # ... over a stretch whose states span this fraction of their spread (not rest)
PROBES = 5000  # rows of the second record probed per pair (a stride over longer records)


@dataclasses.dataclass(frozen=True)
class SharedStretch:
    """Rows `rows_b` (first, last; 0-based, inclusive) of record `b` are rows `rows_a` of record `a`, every
    `step`-th of them (1: one for one; 2: `b` holds every other row of `a`'s stretch, a copy at half the rate;
    0: `b`'s rows lie between `a`'s, `ratio` rows of `a` per row of `b`, a copy resampled at another rate)."""

    rows_a: tuple[int, int]
    rows_b: tuple[int, int]
    step: int = 1
    ratio: float | None = None  # a resampled copy (`step` 0): rows of `a` per row of `b`, not a whole number


def _table(record: Trajectory) -> np.ndarray:
    return np.column_stack([np.asarray(record.xs, float), np.asarray(record.us, float).reshape(len(record), -1)])


def _quantum(column: np.ndarray) -> float:
    """The smallest step between the column's distinct values (its storage's resolution, where rounded)."""
    steps = np.diff(np.unique(column[np.isfinite(column)]))
    return float(steps.min()) if steps.size else 0.0


def _tolerance(ta: np.ndarray, tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`(spread, tolerance)` per column: `a`'s spread, and how closely two rows agree when they are one sample."""
    spread = np.array([np.std(c[np.isfinite(c)]) if np.isfinite(c).any() else 0.0 for c in ta.T])
    quantum = np.array([max(_quantum(ca), _quantum(cb)) for ca, cb in zip(ta.T, tb.T)])
    tolerance = np.maximum(RELATIVE_TOLERANCE * spread, 0.5 * quantum * (1 + 1e-9))
    return spread, np.where(tolerance > 0, tolerance, 1e-12)  # a constant column: exact agreement


def shared_stretches(a: Trajectory, b: Trajectory, *, min_samples: int = 20) -> list[SharedStretch]:
    """The stretches of `b` that are rows of `a`, one for one and in order, while the record moves.

    **Arguments:** two records of one system (records of other shapes share nothing); `min_samples`, the
    shortest stretch reported.

    **Returns:** the shared stretches, in `b`'s order (empty when none).
    """
    if a.state_names != b.state_names or a.input_names != b.input_names or len(a) < min_samples or len(b) < min_samples:
        return []
    ta, tb = _table(a), _table(b)
    finite = np.isfinite(ta).all(1)
    spread, tolerance = _tolerance(ta, tb)
    from scipy.spatial import KDTree

    index = np.flatnonzero(finite)
    if not index.size:
        return []
    tree = KDTree(ta[index] / tolerance)
    stride = max(1, len(b) // PROBES)
    probes = np.arange(0, len(b), stride)
    probes = probes[np.isfinite(tb[probes]).all(1)]
    distance, found = tree.query(tb[probes] / tolerance, p=np.inf, distance_upper_bound=1.0)
    matched = np.isfinite(distance)
    rows = np.where(matched, index[np.minimum(found, len(index) - 1)], -1)

    def same(i, j):
        return 0 <= i < len(b) and 0 <= j < len(a) and bool(np.all(np.abs(tb[i] - ta[j]) <= tolerance))

    def step_between(k):  # rows of `a` per row of `b` from probe k to k + 1, where a whole number
        di, dj = probes[k + 1] - probes[k], rows[k + 1] - rows[k]
        return int(dj // di) if dj > 0 and dj % di == 0 else 0

    states = a.xs.shape[1]
    shared, k = [], 0
    while k < len(probes):
        if not matched[k]:
            k += 1
            continue
        # a run of probes whose matches step through `a` as they step through `b`, `step` rows of `a` a row of `b`
        step = step_between(k) if k + 1 < len(probes) and matched[k + 1] else 1
        step = step or 1
        end = k
        while end + 1 < len(probes) and matched[end + 1] and step_between(end) == step:
            end += 1
        i0, i1, j0 = int(probes[k]), int(probes[end]), int(rows[k])
        k = end + 1
        if not all(same(i, j0 + step * (i - i0)) for i in range(i0, i1 + 1)):
            continue  # probes matched a stride apart, not every row between
        while same(i0 - 1, j0 - step):
            i0, j0 = i0 - 1, j0 - step
        while same(i1 + 1, j0 + step * (i1 + 1 - i0)):
            i1 += 1
        if i1 - i0 + 1 < min_samples:
            continue
        span = np.ptp(tb[i0 : i1 + 1, :states], axis=0) / np.where(spread[:states] > 0, spread[:states], np.inf)
        if span.max() < MOVING:
            continue
        if shared and i0 <= shared[-1].rows_b[1]:
            continue  # the run a probe stride inside the one before
        shared.append(SharedStretch((j0, j0 + step * (i1 - i0)), (i0, i1), step))
    return shared


def _rows_dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", x, y)


def _cubic(lam: np.ndarray, points: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The Lagrange cubic through `points` (rows j - 1 .. j + 2, at parameters -1, 0, 1, 2) at `lam` on the segment
    from row j to j + 1, and its derivative in `lam`."""
    p0, u, v, p3 = points
    x = lam[:, None]
    c = (
        -x * (x - 1) * (x - 2) * p0
        + 3 * (x + 1) * (x - 1) * (x - 2) * u
        - 3 * (x + 1) * x * (x - 2) * v
        + (x + 1) * x * (x - 1) * p3
    ) / 6
    dc = (
        -(3 * x**2 - 6 * x + 2) * p0
        + 3 * (3 * x**2 - 4 * x - 1) * u
        - 3 * (3 * x**2 - 2 * x - 2) * v
        + (3 * x**2 - 1) * p3
    ) / 6
    return c, dc


def _on_path(A: np.ndarray, B: np.ndarray, near: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`(residual, s)` for each row of `B` (scaled columns): the largest column's distance to `A`'s path near row
    `near` of `A`, on the chord or the cubic of the segment before or after it, and the fractional row of `A`
    (`s`) where it is closest. A row on the path has a residual of at most 1."""
    n = len(A)
    best_r, best_s = np.full(len(B), np.inf), np.zeros(len(B))
    for j in (near - 1, near):  # the segment from row j to j + 1
        j = np.clip(j, 0, n - 2)
        u, v = A[j], A[j + 1]
        d = v - u
        lam = np.clip(_rows_dot(B - u, d) / np.maximum(_rows_dot(d, d), 1e-300), 0.0, 1.0)
        r = np.abs(B - u - lam[:, None] * d).max(1)
        # the cubic through rows j - 1 .. j + 2 (parameter lam on the segment), refined by Gauss-Newton
        points = (A[np.clip(j - 1, 0, n - 1)], u, v, A[np.clip(j + 2, 0, n - 1)])
        lc = lam.copy()
        for _ in range(3):
            c, dc = _cubic(lc, points)
            lc = np.clip(lc - _rows_dot(c - B, dc) / np.maximum(_rows_dot(dc, dc), 1e-300), 0.0, 1.0)
        rc = np.abs(B - _cubic(lc, points)[0]).max(1)
        use_cubic = rc < r
        r, lam = np.where(use_cubic, rc, r), np.where(use_cubic, lc, lam)
        better = r < best_r
        best_r, best_s = np.where(better, r, best_r), np.where(better, j + lam, best_s)
    return best_r, best_s


def resampled_stretches(a: Trajectory, b: Trajectory, *, min_samples: int = 20) -> list[SharedStretch]:
    """The stretches of `b` whose rows lie on `a`'s path between its samples, in order at a steady rate ratio (`b`
    a copy of `a` resampled at another rate), while the record moves: `step` 0, `ratio` rows of `a` per row of
    `b`, `rows_a` the rows of `a` the stretch spans (see the module)."""
    if a.state_names != b.state_names or a.input_names != b.input_names or len(a) < 4 or len(b) < min_samples:
        return []
    ta, tb = _table(a), _table(b)
    finite_a = np.isfinite(ta).all(1)
    if finite_a.sum() < 4 or not np.isfinite(tb).all(1).any():
        return []
    spread, tolerance = _tolerance(ta, tb)
    # Rows with a gap (a dropout's NaN) are off every path: no segment ends there, no probe starts there, and a
    # stretch ends at one (its comparisons are false).
    A, B = ta / tolerance, tb / tolerance
    from scipy.spatial import KDTree

    # A row on a segment is within half the segment (and the tolerance) of one of its ends in every column. The
    # tree searches in columns scaled by their longest steps (99 % of them: a glitch's are not searched from; a
    # run broken there is rejoined below), where that is 0.5 to 1.5 whatever the column's noise, so probes far
    # from every row of `a` in any column (nearly all, in a record that is not a copy) are rejected at once.
    jumps = np.abs(np.diff(A, axis=0))
    jumps = jumps[np.isfinite(jumps).all(1)]
    if len(jumps) < 3:
        return []  # no path to lie on: no two rows in a row without a gap
    steps = np.maximum(np.quantile(jumps, 0.99, axis=0), 1.0)
    index = np.flatnonzero(finite_a)
    tree = KDTree(A[index] / steps)
    stride = max(1, len(b) // PROBES)
    probes = np.arange(0, len(b), stride)
    usable = np.isfinite(B[probes]).all(1)  # a probe in a gap is unmatched: a run of probes breaks there
    distance, near = np.full(len(probes), np.inf), np.zeros(len(probes), int)
    distance[usable], near[usable] = tree.query(B[probes[usable]] / steps, p=np.inf, distance_upper_bound=1.5 + 1e-9)
    found = np.isfinite(distance)
    with np.errstate(invalid="ignore"):
        residual, s = _on_path(A, B[probes], np.where(found, index[np.minimum(near, len(index) - 1)], 0))
        matched = found & (residual <= 1.0)

    def placed(rows: np.ndarray, s_expected: np.ndarray) -> np.ndarray:
        """Whether each row of `b` lies on `a`'s path within a row of where the stretch's ratio puts it."""
        ok = (rows >= 0) & (rows < len(b)) & (s_expected >= 0) & (s_expected <= len(a) - 1)
        rows_, near_ = np.clip(rows, 0, len(b) - 1), np.clip(np.round(s_expected).astype(int), 0, len(a) - 1)
        with np.errstate(invalid="ignore"):
            r, s_ = _on_path(A, B[rows_], near_)
            return ok & (r <= 1.0) & (np.abs(s_ - s_expected) <= 1.0)

    states = a.xs.shape[1]
    shared, k = [], 0
    while k + 1 < len(probes):
        if not (matched[k] and matched[k + 1]):
            k += 1
            continue
        ratio = (s[k + 1] - s[k]) / (probes[k + 1] - probes[k])
        end = k + 1
        while (
            end + 1 < len(probes)
            and matched[end + 1]
            and abs((s[end + 1] - s[k]) / (probes[end + 1] - probes[k]) - ratio) <= 0.01 * abs(ratio)
        ):
            end += 1
        i0, i1, s0 = int(probes[k]), int(probes[end]), float(s[k])
        k = end + 1
        if ratio <= 0:
            continue
        ratio = (float(s[end]) - s0) / max(i1 - i0, 1)  # over the whole run of probes
        rows = np.arange(i0, i1 + 1)
        if not placed(rows, s0 + ratio * (rows - i0)).all():
            continue
        while i0 > 0 and placed(np.array([i0 - 1]), np.array([s0 - ratio]))[0]:
            i0, s0 = i0 - 1, s0 - ratio
        while i1 + 1 < len(b) and placed(np.array([i1 + 1]), np.array([s0 + ratio * (i1 + 1 - i0)]))[0]:
            i1 += 1
        if i1 - i0 + 1 < min_samples:
            continue
        span = np.ptp(tb[i0 : i1 + 1, :states], axis=0) / np.where(spread[:states] > 0, spread[:states], np.inf)
        if span.max() < MOVING:
            continue
        if shared and i0 <= shared[-1].rows_b[1]:
            continue
        s1 = s0 + ratio * (i1 - i0)
        shared.append(SharedStretch((int(np.floor(s0)), int(np.ceil(s1))), (i0, i1), 0, float(ratio)))
    return shared


def shared_either_way(a: Trajectory, b: Trajectory, *, min_samples: int = 20) -> list[SharedStretch]:
    """`shared_stretches(a, b)`, and where that finds nothing, the stretches of `a` that are every `step`-th row
    of `b` (`b` a copy of `a` at a whole multiple of its rate: interpolated between `a`'s samples), each given
    from `b`'s side: `rows_b` the span of `b` that holds them, `rows_a` `a`'s rows, `step` as negative (`b`'s
    rows per row of `a`); where neither finds any, `resampled_stretches(a, b)` (`step` 0)."""
    found = shared_stretches(a, b, min_samples=min_samples)
    if found:
        return found
    found = [
        SharedStretch(s.rows_b, s.rows_a, -s.step)
        for s in shared_stretches(b, a, min_samples=min_samples)
        if s.step > 1
    ]
    return found or resampled_stretches(a, b, min_samples=min_samples)
