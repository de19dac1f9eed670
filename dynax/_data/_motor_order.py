r"""Motors numbered one way in one flight log and another way in the next.

A multirotor's motor map is learned per motor: `m1` is the motor the training logs call `m1`. A log
whose columns are numbered otherwise (another logger's convention, a `--map` written for another
airframe) loads, fits and scores without a word, and every prediction on it is wrong: each log is
right for itself, so only a comparison between logs can tell. The body rates can: the moment about
each body axis is a signed combination of the motors' thrusts, different for every motor (on an X
or a + frame no two motors push the same way about all three axes), and the attitude controller
that flies the vehicle raises a motor against the rates it must stop, the same way in every flight.

**A flight's signature** (`flight_signature`) has two 4 x 3 tables (motor column x body axis) of
each motor's input above the mean of the four (the differential commands that turn the vehicle)
against the change of each body rate over the next `WINDOW_S` (long against the motors' lag and the
logging chain's delay, 40 ms on the NanoBench Crazyflie; short against a manoeuvre):

- their correlations, free of units and of the frame's size. On the 16 NanoBench flights each entry
  is 0.1-0.2 in size, in the signs of the X frame's mix, and varies by about 0.08 (one standard
  deviation) from flight to flight; it carries the controller's feedback as well as the physics, and
  depends on how a flight excites each axis;
- the least-squares map of the mean angular acceleration on the inputs over their median level
  (rad/s^2 per relative command; the minimum-norm solution, as the four sum to zero): the vehicle's
  moments where the commands cause the motion, muddied by feedback where a controller answers the
  rates (each table alone fails where the other holds: `docs/devdocs/quadrotor_notes.md`).

Each entry has its standard error from chunks of `CHUNK_S` (long against the windows' overlap and
the controller's cycle): of the correlations' chunk means, and of the map by deleting one chunk at
a time (the jackknife).

**The test** (`motor_order`) of a flight against a reference (the signatures of other flights,
`motor_signature`): for each of the 24 orders of the flight's motor columns, the $\chi^2$ distance
of its rows, so reordered, from the reference's mean, each entry weighed by its variance: the
flight's own standard error squared, the reference mean's, and the spread between flights beyond
their standard errors (estimated from three reference flights or more, as the random effect of a
meta-analysis; none from fewer). Where even the best order's $\chi^2$ exceeds its degrees of
freedom, the flight differs from the reference by more than these variances say (a reference of one
flight, a flight of another kind), and every gap is divided by that ratio (Birge's). Under Gaussian
errors, $\tfrac12[\chi^2(\text{given}) - \chi^2(P)]$ is the log likelihood ratio of order $P$
against the given one, so the given order loses where the best order $P^*$ beats it by `THRESHOLD`
$= 2\ln(23/\alpha)$ (`ALPHA` = 0.001, Bonferroni over the 23 other orders). $P^*$ is named; a
runner-up within `THRESHOLD` of it (motors the flight does not tell apart: a yaw axis that barely
moves) is named beside it. A flight whose rates barely answer its motors (near hover) moves every
$\chi^2$ alike: it passes, and its note names the orders it could not tell from the logged one.

**The reference** (`MotorNumbering`): a model's training flights' signature where one is given (`dynax
evaluate`, `diagnose --nominal`), each flight tested as it is loaded; else the consensus of the flights
given, once all are loaded (`settle`; each signature computed once): each flight against all the others
(leave one out), so that a misnumbered flight is named wherever it stands in the list, the first
included. Of three flights or more, those that disagree with the rest are named; two flights that
disagree are both named, neither blamed: two cannot tell which is numbered right.

Fewer than `MIN_CHUNKS` chunks of usable flight: no signature, no test. What each flight's test could see is
kept as a note (`MotorNumbering.notes`, `power_note`): not checked (too short), or checked in part (the
other orders within `THRESHOLD` of the one as logged: columns numbered that way would have passed).
"""

from collections.abc import Sequence
import dataclasses
import itertools
import math
import warnings

import numpy as np

from .._errors import DataError
from ._sanity import DataWarning
from ._trajectory import Trajectory

#: The 24 orders of four motor columns, the given one first: order `P` reads logged column `P[k]` as motor k.
PERMUTATIONS = tuple(itertools.permutations(range(4)))
WINDOW_S = 0.12  # the rates' change is taken over this [s]
CHUNK_S = 0.5  # the standard error's chunks [s]
MIN_CHUNKS = 10  # fewer chunks of usable flight than this: no signature
ALPHA = 1e-3
THRESHOLD = 2.0 * math.log((len(PERMUTATIONS) - 1) / ALPHA)  # 20.1: the chi-square gap that decides
DEGREES_OF_FREEDOM = 18  # 2 tables x 3 axes x 3: the four differential inputs sum to zero


@dataclasses.dataclass(frozen=True)
class FlightSignature:
    """One flight's signature (see the module notes). **Fields:** `pattern` (4 x 6: motor column x the
    correlations' and the map's three body axes), `variance` (its entries' squared standard errors),
    `n_chunks`, `source`."""

    pattern: np.ndarray
    variance: np.ndarray
    n_chunks: int
    source: str = ""


@dataclasses.dataclass(frozen=True)
class MotorSignature:
    """The reference of `motor_order`: the mean signature of `n_flights` flights (`pattern`), the mean of
    their squared standard errors (`noise`) and the spread between them beyond it (`spread`), each 4 x 6.
    Written into a fitted quadrotor model (`to_json`) so that `dynax evaluate` can test another flight."""

    pattern: np.ndarray
    noise: np.ndarray
    spread: np.ndarray
    n_flights: int
    sources: tuple[str, ...] = ()

    def variance(self, flight: FlightSignature, order: Sequence[int] = (0, 1, 2, 3)) -> np.ndarray:
        """The variance of `flight.pattern[order] - self.pattern` where the flight's columns read in `order`
        are numbered like the reference (the flight's own standard errors travel with its columns)."""
        own = flight.variance[list(order)]
        return own + self.noise / self.n_flights + self.spread * (1 + 1 / self.n_flights)

    def to_json(self) -> dict:
        return {
            "pattern": self.pattern.tolist(),
            "noise": self.noise.tolist(),
            "spread": self.spread.tolist(),
            "n_flights": self.n_flights,
            "window_s": WINDOW_S,
        }

    @classmethod
    def from_json(cls, obj, path=None) -> "MotorSignature | None":
        """The signature of `to_json`'s object; `None` where it is absent (a model written before the check).
        A malformed one (an edited file) raises `DataError` naming `path` and the key: the check is not
        switched off without a word."""
        if obj is None:
            return None

        def refuse(what: str):
            return DataError(
                f"the model file's `motor_signature` {what}; delete the key to use the model without the motor-order "
                "check, or fit the model again",
                path=path,
            )

        try:
            arrays = [np.asarray(obj[k], dtype=float) for k in ("pattern", "noise", "spread")]
            n = int(obj["n_flights"])
            window = float(obj["window_s"])
        except KeyError as e:
            raise refuse(f"lacks {e}") from None
        except (TypeError, ValueError) as e:
            raise refuse(f"cannot be read ({e})") from None
        if not math.isclose(window, WINDOW_S):
            raise refuse(f"has window_s = {window:g}, where this version of dynax reads {WINDOW_S:g} s")
        if n < 1:
            raise refuse(f"has n_flights = {n}")
        for key, a in zip(("pattern", "noise", "spread"), arrays):
            if a.shape != (4, 6) or not np.all(np.isfinite(a)):
                raise refuse(f"has a `{key}` that is not 4 x 6 finite numbers (shape {a.shape})")
        for key, a in zip(("noise", "spread"), arrays[1:]):
            if np.any(a < 0):
                raise refuse(f"has a negative `{key}`")
        return cls(*arrays, n_flights=n)


@dataclasses.dataclass(frozen=True)
class MotorOrder:
    """The evidence of one flight on its motors' order (`motor_order`).

    **Fields:** `chi2` (the 24 orders' distance from the reference, in `PERMUTATIONS`' order), `best` (the
    nearest order), `runner_up` (the next nearest other than the given one), `n_chunks`.
    """

    chi2: tuple[float, ...]
    best: tuple[int, ...]
    runner_up: tuple[int, ...]
    n_chunks: int

    @property
    def scale(self) -> float:
        """The best order's $\\chi^2$ per degree of freedom where above 1 (Birge's ratio): the flight differs from
        the reference by more than the variances say (flights of another kind, a reference of one or two
        flights, which shows no spread between flights), and every gap is divided by it."""
        return max(1.0, min(self.chi2) / DEGREES_OF_FREEDOM)

    @property
    def evidence(self) -> float:
        """$\\chi^2$ of the given order less that of the best, over `scale`: twice the log likelihood ratio."""
        return (self.chi2[0] - min(self.chi2)) / self.scale

    @property
    def margin(self) -> float:
        """$\\chi^2$ of the best other order less that of the given one, over `scale` (positive: the given order
        fits best)."""
        return (min(self.chi2[1:]) - self.chi2[0]) / self.scale

    @property
    def permuted(self) -> bool:
        return self.best != PERMUTATIONS[0] and self.evidence >= THRESHOLD

    @property
    def named(self) -> tuple[tuple[int, ...], ...]:
        """The orders named where `permuted`: the best, and the runner-up where within `THRESHOLD` of it."""
        if not self.permuted:
            return ()
        close = (self.chi2[PERMUTATIONS.index(self.runner_up)] - min(self.chi2)) / self.scale < THRESHOLD
        return (self.best, self.runner_up) if close else (self.best,)

    @property
    def untold(self) -> tuple[tuple[int, ...], ...]:
        """The other orders this flight does not tell from the one as logged (within `THRESHOLD` of it, nearest
        first): had its columns been numbered by one of these, the test would have passed them. Empty where
        the test had the power to see every misnumbering."""
        gaps = [((c - self.chi2[0]) / self.scale, p) for c, p in zip(self.chi2[1:], PERMUTATIONS[1:])]
        return tuple(p for gap, p in sorted(gaps) if gap < THRESHOLD)


def _runs_ok(usable: np.ndarray, width: int) -> np.ndarray:
    """The samples `k` whose window `k..k+width` is usable throughout."""
    bad = np.concatenate([[0], np.cumsum(~np.asarray(usable, bool))])
    k = np.arange(max(len(usable) - width, 0))
    return k[(bad[k + width + 1] - bad[k]) == 0]


def flight_signature(flight: Trajectory, usable: np.ndarray | None = None) -> FlightSignature | None:
    """The signature of a quadrotor record over its `usable` samples (default: all); `None` where it has
    fewer than `MIN_CHUNKS` chunks of usable flight or a motor or rate that does not move there."""
    ts = np.asarray(flight.ts, dtype=float)
    if len(ts) < 3:
        return None
    usable = np.ones(len(ts), bool) if usable is None else np.asarray(usable, bool)
    width = max(round(WINDOW_S / float(np.median(np.diff(ts)))), 1)
    k = _runs_ok(usable, width)
    if k.size < 2:
        return None
    _, index, counts = np.unique(
        np.floor((ts[k] - ts[0]) / CHUNK_S).astype(int), return_inverse=True, return_counts=True
    )
    if len(counts) < MIN_CHUNKS:
        return None
    motors = np.asarray(flight.us[:, :4], dtype=float)
    rates = np.asarray(flight.xs[:, 10:13], dtype=float)
    d = (motors - motors.mean(axis=1, keepdims=True))[k]  # the differential inputs
    change = rates[k + width] - rates[k]
    sd_d, sd_c = d.std(axis=0), change.std(axis=0)
    if np.any(sd_d == 0) or np.any(sd_c == 0):
        return None
    # the correlations: chunk means of the standardised products, their weighted mean and its standard error
    products = (
        ((d - d.mean(axis=0)) / sd_d)[:, :, None] * ((change - change.mean(axis=0)) / sd_c)[:, None, :]
    ).reshape(len(k), 12)
    per_chunk = np.stack([np.bincount(index, weights=products[:, j]) for j in range(12)], axis=1) / counts[:, None]
    weights = counts / counts.sum()
    correlation = weights @ per_chunk
    n = len(counts)
    correlation_variance = np.sum(weights[:, None] ** 2 * (per_chunk - correlation) ** 2, axis=0) * n / (n - 1)
    # the map: least squares of the mean angular acceleration on the differential inputs over their median
    # level (the minimum-norm solution: the four sum to zero), its variance by deleting one chunk at a time
    x = d / (float(np.median(np.abs(motors[k]))) or 1.0)
    y = change / (width * float(np.median(np.diff(ts))))
    xx, xy = np.zeros((n, 4, 4)), np.zeros((n, 4, 3))
    np.add.at(xx, index, x[:, :, None] * x[:, None, :])
    np.add.at(xy, index, x[:, :, None] * y[:, None, :])
    total_xx, total_xy = xx.sum(axis=0), xy.sum(axis=0)
    gains = np.linalg.pinv(total_xx, rcond=1e-10) @ total_xy
    left_out = np.linalg.pinv(total_xx[None] - xx, rcond=1e-10) @ (total_xy[None] - xy)
    gains_variance = (n - 1) / n * np.sum((left_out - left_out.mean(axis=0)) ** 2, axis=0)
    return FlightSignature(
        np.concatenate([correlation.reshape(4, 3), gains], axis=1),
        np.concatenate([correlation_variance.reshape(4, 3), gains_variance], axis=1),
        n,
        flight.source,
    )


def motor_signature(signatures: Sequence[FlightSignature | None]) -> MotorSignature | None:
    """The reference of the flights' `signatures` (those that are `None` left out); `None` where none is left."""
    found = [s for s in signatures if s is not None]
    if not found:
        return None
    patterns = np.stack([s.pattern for s in found])
    noise = np.mean([s.variance for s in found], axis=0)
    spread = np.zeros_like(noise)
    if len(found) >= 3:  # the between-flight variance beyond the flights' own standard errors
        spread = np.maximum(patterns.var(axis=0, ddof=1) - noise, 0.0)
    return MotorSignature(patterns.mean(axis=0), noise, spread, len(found), tuple(s.source for s in found))


def motor_order(flight: FlightSignature | None, reference: MotorSignature | None) -> MotorOrder | None:
    """The evidence of a flight's signature on its motors' order against a `reference` (see the module notes);
    `None` where either is missing."""
    if flight is None or reference is None:
        return None
    chi2 = [
        float(np.sum((flight.pattern[list(p)] - reference.pattern) ** 2 / reference.variance(flight, p)))
        for p in PERMUTATIONS
    ]
    ranked = [int(i) for i in np.argsort(chi2, kind="stable")]
    runner = next(i for i in ranked if i not in (0, ranked[0]))
    return MotorOrder(tuple(chi2), PERMUTATIONS[ranked[0]], PERMUTATIONS[runner], flight.n_chunks)


def power_note(found: MotorOrder | None, reference: str) -> str:
    """What the test of one flight against the `reference` (words) could see, for the notes: `""` where it
    could see every misnumbering (or found one: that is refused, not noted)."""
    if found is None:
        return (
            f"motors' numbering not checked against {reference}: under {MIN_CHUNKS * CHUNK_S:g} s of usable flight, "
            "or a motor or body rate that does not move"
        )
    if found.permuted or not found.untold:
        return ""
    shown = ", ".join(order_text(p) for p in found.untold[:2])
    return (
        f"motors' numbering checked in part against {reference}: the body rates do not tell the order as logged "
        f"from {len(found.untold)} of the 23 others (such as {shown}), so columns numbered that way would pass"
    )


def order_text(order: Sequence[int] | np.ndarray) -> str:
    """The reference's motor names that the logged columns `m1..m4` read like under `order`."""
    inverse = np.argsort(order)
    return ",".join(f"m{int(inverse[j]) + 1}" for j in range(4))


def order_error(found: MotorOrder, path, reference: str, columns=None, also: str = "") -> DataError:
    """The refusal of a flight whose motors `found` says are in another order than the `reference`'s (words);
    `also`, words added at the end."""
    columns = columns or {}

    def fix(order) -> str:
        inverse = np.argsort(order)  # the file's motor j is the reference's motor inverse[j]
        return ",".join(sorted(f"m{int(inverse[j]) + 1}={columns.get(f'm{j + 1}', f'm{j + 1}')}" for j in range(4)))

    fixes = f"fix the --map ({fix(found.best)})"
    if len(found.named) > 1:  # two orders the flight does not tell apart: both fixes, the choice left to the user
        other = found.named[1]
        fixes += f", or ({fix(other)}) for {order_text(other)}; the body rates cannot say which: check the airframe"
    return DataError(
        f"m1,m2,m3,m4 read like {order_text(found.best)} of {reference}: the body rates answer the motors as there "
        f"{'only ' if len(found.named) < 2 else ''}in that order (ahead of the order as logged by "
        f"{found.evidence:.1f} in chi-square; {THRESHOLD:.1f} decides){_alike(found)}; the motors are numbered "
        f"otherwise than there: {fixes}{also}",
        path=path,
    )


def _alike(found: MotorOrder) -> str:
    """The look-alike of a refusal's order, where the flight does not tell the two apart (`MotorOrder.named`)."""
    if len(found.named) < 2:
        return ""
    other = found.named[1]
    ahead = (found.chi2[0] - found.chi2[PERMUTATIONS.index(other)]) / found.scale
    return f", or like {order_text(other)} ({ahead:.1f}: this flight does not tell the two apart)"


def _names(paths) -> str:
    shown = [str(p) for p in paths]
    return ", ".join(shown[:3]) + (f" and {len(shown) - 3} more" if len(shown) > 3 else "")


def pair_error(found: MotorOrder, first, second) -> DataError:
    """The refusal of two flights whose motors `found` (the `second` against the `first`) says are numbered
    otherwise: two flights cannot say which of them is right, so neither is blamed."""
    return DataError(
        f"files {first} and {second} disagree on the motors' numbering: {second}'s m1,m2,m3,m4 read like "
        f"{order_text(found.best)} of {first} (ahead of the order as logged by {found.evidence:.1f} in chi-square; "
        f"{THRESHOLD:.1f} decides){_alike(found)}, and two flights cannot tell which of them is numbered right: "
        "check each log's motor columns and fix the --map of the wrong one, or give a third flight"
    )


@dataclasses.dataclass
class MotorNumbering:
    """The motors' numbering that flights are held to: the `reference` signature's (a model's training
    flights', named `name` in the refusal) where given, each flight as it is `check`ed; else the consensus
    of the flights checked (`seen`), settled once they are all in (`settle`): each against all the others."""

    reference: MotorSignature | None = None
    name: str = "the training flights"
    seen: list[FlightSignature | None] = dataclasses.field(default_factory=list)
    files: list[tuple[object, dict]] = dataclasses.field(default_factory=list)
    notes: dict[str, str] = dataclasses.field(default_factory=dict)

    def check(self, flight: Trajectory, usable: np.ndarray, path, columns=None) -> MotorOrder | None:
        """Count `flight` (its `usable` samples; `path` and `columns`, contract name -> file column, for the
        message) among `seen`; where a `reference` is given, refuse it first if its motors are numbered
        otherwise (see the module notes). **Returns:** the evidence against the reference (`None`: no
        reference, or no test).

        **Raises:** `DataError` naming the file, the order its columns read like and the `--map` that fixes it.
        """
        signature = flight_signature(flight, usable)
        found = motor_order(signature, self.reference)
        if found is not None and found.permuted:
            raise order_error(found, path, self.name, columns)
        if self.reference is not None:
            self.notes[str(path)] = power_note(found, self.name)
        self.seen.append(signature)
        self.files.append((path, dict(columns or {})))
        return found

    def settle(self) -> None:
        """Without a `reference`, test each flight seen against the signature of all the others (their
        consensus: a misnumbered flight is found wherever it stands in the list). Of three flights or more,
        refuse naming those that disagree with the rest; of two that disagree, refuse naming both, blaming
        neither.

        **Raises:** `DataError` as `check`'s, or naming the two flights of a pair that disagree."""
        if self.reference is not None:
            return
        if len(self.files) >= 2:  # what each flight's test could see (`notes`); a single flight has nothing to hold
            for signature, (path, _) in zip(self.seen, self.files):
                if signature is None:
                    self.notes[str(path)] = power_note(None, "the other flights")
        tested = [(s, path, columns) for s, (path, columns) in zip(self.seen, self.files) if s is not None]
        if len(tested) == 2:
            (first, a, _), (second, b, _) = tested
            found = motor_order(second, motor_signature([first]))
            if found is not None and found.permuted:
                raise pair_error(found, a, b)
            for path, other in ((a, b), (b, a)):  # the pair's test is symmetric in what it can see
                self.notes[str(path)] = power_note(found, f"{other}")
            return
        wrong = []
        for k, (signature, path, columns) in enumerate(tested):
            others = [s for j, (s, _, _) in enumerate(tested) if j != k]
            found = motor_order(signature, motor_signature(others))
            if found is not None and found.permuted:
                wrong.append((found, path, columns))
            self.notes[str(path)] = power_note(found, "the other flights")
        if wrong:
            found, path, columns = wrong[0]
            rest = [p for _, p, _ in tested if p != path]
            also = "".join(
                f"; {p} also disagrees with the rest (reads like {order_text(f.best)})" for f, p, _ in wrong[1:]
            )
            raise order_error(found, path, f"the other {len(rest)} flights ({_names(rest)})", columns, also)

    def signature(self) -> MotorSignature | None:
        """The reference of a model fitted to the flights seen (`MODEL.json`'s `motor_signature`)."""
        return motor_signature(self.seen)


def warn_if_numbered_otherwise(flights: Sequence[Trajectory] | Trajectory, stacklevel: int = 3) -> None:
    """Warn (`DataWarning`) where the motors of the flights given together read as numbered otherwise in one of
    them than in the rest, by the consensus `dynax fit quadrotor` refuses on (`MotorNumbering`;
    flights too short for a signature are not tested). A warning here, not a refusal: a Python caller may give
    runs of one record, or flights it has checked otherwise."""
    if isinstance(flights, Trajectory) or len(flights) < 2:
        return
    numbering = MotorNumbering()
    for i, flight in enumerate(flights):
        numbering.check(flight, np.ones(len(flight), bool), f"{flight.source or 'flight'} (flights[{i}])")
    try:
        numbering.settle()
    except DataError as e:
        fix = " (from Python: the `mapping=` given to `dynax.load_flight`)"
        warnings.warn(f"{e}{fix}", DataWarning, stacklevel=stacklevel)
