r"""The typed feature library of the discovery search, the position-period search, and physical readings.

For the generalised-force residual at coordinate $j$ of a manipulator the library holds:

- positions of every coordinate and their polynomials ($q_k$, $q_k^2$, $q_k^3$), and for angles
  $\sin q_k$, $\cos q_k$;
- the coordinate's own velocity transforms: $\dot q_j$, $\operatorname{sign}\dot q_j$,
  $|\dot q_j|\dot q_j$, and position-dependent friction $q_j \operatorname{sign}\dot q_j$;
- every input $a_i$ and its products with $q_j$ and $\dot q_j$;
- a constant;
- for a coordinate that is not an angle (a prismatic axis), $\sin(2\pi q_j / p)$ and
  $\cos(2\pi q_j / p)$ with the period $p$ searched by a periodogram of the residual against
  position (Lomb-Scargle in the position domain).

Features that a named cause of the vocabulary represents exactly at this coordinate
($\dot q_j$: `viscous_friction`, $\operatorname{sign}\dot q_j$: `coulomb_friction`,
$|\dot q_j|\dot q_j$: `quadratic_drag`, an input acting at $j$: `input_gain`, a constant at an
actuated coordinate: `input_offset`) carry that cause's label: the named cause wins over an
equivalent discovered formula.

??? cite

    N. R. Lomb, "Least-squares frequency analysis of unequally spaced data", Astrophysics and
    Space Science 39, 1976; J. D. Scargle, "Studies in astronomical time series analysis II",
    Astrophysical Journal 263, 1982 (the periodogram the period search is).
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._model._extensions import Discovered, Feature


def is_angle(system, k: int) -> bool:
    """Whether coordinate `k` of `system` is an angle (a revolute joint): the system's `angle_indices`."""
    return k in system.angle_indices


def feature_library(system, channel: int, xs: np.ndarray, *, period: float | None = None) -> list[Feature]:
    """The typed library for the generalised-force residual at coordinate `channel` (see module docs).

    **Arguments:** `system` (a manipulator); `channel` (0-based coordinate); `xs` the smoothed states
    (sets the smoothing scale of the sign); `period` of the periodic pair, or `None` to leave it out.

    **Returns:** a list of `Feature`.
    """
    n = system.n_joints
    vs = max(0.05 * float(np.std(xs[:, n + channel])), 1e-6)
    library: list[Feature] = []
    for k in range(n):
        library += [Feature("position", k, power=p) for p in (1, 2, 3)]
        if is_angle(system, k):
            library += [Feature("sin", k), Feature("cos", k)]
    library += [
        Feature("velocity", channel),
        Feature("sign", channel, velocity_scale=vs),
        Feature("abs_velocity", channel),
        Feature("position_sign", channel, velocity_scale=vs),
    ]
    for i in range(system.n_inputs):
        library += [
            Feature("input", channel, input=i),
            Feature("input_position", channel, input=i),
            Feature("input_velocity", channel, input=i),
        ]
    library.append(Feature("constant", channel))
    if period is not None:
        library += [Feature("periodic_sin", channel, period=period), Feature("periodic_cos", channel, period=period)]
    return library


def evaluate_features(features: list[Feature], n_joints: int, xs: np.ndarray, us: np.ndarray) -> np.ndarray:
    """The features at every sample, `(time, n_features)`."""
    xs, us = jnp.asarray(xs), jnp.asarray(us)

    def row(x, u):
        return jnp.stack([f(x[:n_joints], x[n_joints:], u) for f in features])

    return np.asarray(jax.jit(jax.vmap(row))(xs, us))


def named_equivalent(system, feature: Feature, channel: int) -> str | None:
    """The label (`cause@where`) of the named cause that represents `feature` exactly at `channel`, if any."""
    c = system.state_names[channel]
    if feature.coordinate != channel and feature.kind not in ("input", "constant"):
        return None
    actuated = np.asarray(system.input_matrix())[channel]
    if feature.kind == "velocity":
        return f"viscous_friction@{c}"
    if feature.kind == "sign":
        return f"coulomb_friction@{c}"
    if feature.kind == "abs_velocity":
        return f"quadratic_drag@{c}"
    if feature.kind == "input" and actuated[feature.input] != 0:
        return f"input_gain@{system.input_names[feature.input]}"
    if feature.kind == "constant":
        inputs = [system.input_names[i] for i in np.flatnonzero(actuated)]
        return f"input_offset@{inputs[0]}" if inputs else None
    return None


def search_period(
    q: np.ndarray, target: np.ndarray, *, p_min: float, p_max: float, n_grid: int = 400
) -> tuple[float, float]:
    r"""The period $p$ for which $a \sin(2\pi q/p) + b \cos(2\pi q/p) + c$ explains most of `target`.

    A periodogram in the position domain on a log-spaced grid of `n_grid` periods in
    `[p_min, p_max]`, refined by a second grid around the best one.

    **Returns:** `(period, explained fraction of target's variance)`.
    """
    q, y = np.asarray(q, float), np.asarray(target, float) - np.mean(target)
    sst = float(np.sum(y**2)) or 1.0

    def scores(periods):
        out = []
        for p in periods:
            A = np.stack([np.sin(2 * np.pi * q / p), np.cos(2 * np.pi * q / p), np.ones_like(q)], axis=1)
            beta = np.linalg.lstsq(A, y, rcond=None)[0]
            out.append(1 - float(np.sum((y - A @ beta) ** 2)) / sst)
        return np.asarray(out)

    grid = np.exp(np.linspace(np.log(p_min), np.log(p_max), n_grid))
    s = scores(grid)
    k = int(np.argmax(s))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, n_grid - 1)]
    fine = np.linspace(lo, hi, 41)
    sf = scores(fine)
    j = int(np.argmax(sf))
    return float(fine[j]), float(sf[j])


def physical_readings(system, term: Discovered) -> list[str]:
    """Plain-language readings of a discovered term where its formula has a known physical one."""
    readings = []
    where = term.where(system)
    unit_q = "rad" if is_angle(system, term.joint) else "m"
    unit_f = "N m" if is_angle(system, term.joint) else "N"
    coef = list(zip(term.features, map(float, term.coefficients)))
    periodic = [f for f, _ in coef if f.kind.startswith("periodic")]
    if periodic:
        a = sum(c for f, c in coef if f.kind == "periodic_sin")
        b = sum(c for f, c in coef if f.kind == "periodic_cos")
        readings.append(
            f"a position-periodic force at {where} with period {periodic[0].period:.4g} {unit_q} and amplitude "
            f"{np.hypot(a, b):.3g} {unit_f} (a screw's pitch, cogging, a cable's wrap)"
        )
    for f, c in coef:
        other = system.state_names[f.coordinate]
        if f.kind == "position" and f.power == 1 and f.coordinate == term.joint:
            kind = "a joint spring" if c < 0 else "a negative stiffness (a destabilising spring)"
            readings.append(f"{kind} at {where} of stiffness k = {-c:.4g} {unit_f}/{unit_q} (force -k {where})")
        elif f.kind == "position" and f.power == 1:
            readings.append(f"a coupling spring: the force at {where} depends on {other} ({c:.4g} {unit_f}/rad)")
        elif f.kind == "position" and f.power == 3 and f.coordinate == term.joint:
            readings.append(f"a hardening or softening spring at {where} (cubic stiffness {-c:.4g})")
        elif f.kind == "position_sign":
            readings.append(
                f"position-dependent friction at {where}: the dry friction changes by {-c:.4g} {unit_f} per {unit_q}"
            )
        elif f.kind in ("sin", "cos"):
            readings.append(f"a gravity-like torque at {where} in {f.name(system)} (a mass or balance the model lacks)")
        elif f.kind == "constant":
            readings.append(f"a constant force at {where} of {c:.4g} {unit_f} (a bias, a cable's pull)")
        elif f.kind == "input_position":
            readings.append(f"an input gain that varies with position at {where}")
    return readings
