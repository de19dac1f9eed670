r"""`Discovered`: a data-driven term outside the cause vocabulary, carrying its own formula.

A discovered term adds a sparse combination of typed features of the state and the applied input
to the generalised force at one coordinate of a manipulator,

$$M(q)\,\ddot q + h(q, \dot q) = B a + e_j \sum_i c_i\,\phi_i(q, \dot q, a),$$

so it composes with `Extended` like any named term and is refitted through simulation with the
nominal parameters. The features are small static `Feature` values (a name, a kind, the
coordinates they read); `dynax._diagnose._library` builds the library the search chooses from.
"""

from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._errors import UsageError
from ._terms import AbstractJointTerm

# kind -> (arity over coordinates / inputs, what it reads)
FEATURE_KINDS = (
    "position",  # q_j ** power
    "sin",  # sin(q_j)
    "cos",  # cos(q_j)
    "velocity",  # dq_j
    "sign",  # tanh(dq_j / v_s): Coulomb-like
    "abs_velocity",  # |dq_j| dq_j
    "position_sign",  # q_j tanh(dq_j / v_s): position-dependent friction
    "input",  # a_i
    "input_position",  # a_i q_j
    "input_velocity",  # a_i dq_j
    "periodic_sin",  # sin(2 pi q_j / period)
    "periodic_cos",  # cos(2 pi q_j / period)
    "constant",  # 1
)


class Feature(eqx.Module):
    r"""One typed feature $\phi(q, \dot q, a)$ of a discovered term (all fields static).

    **Arguments:**

    - `kind`: one of `position`, `sin`, `cos`, `velocity`, `sign`, `abs_velocity`,
      `position_sign`, `input`, `input_position`, `input_velocity`, `periodic_sin`,
      `periodic_cos`, `constant`.
    - `coordinate`: the 0-based coordinate $j$ it reads (ignored by `input` and `constant`).
    - `input`: the 0-based input $i$ it reads (only the `input*` kinds).
    - `power`: the power of a `position` feature (1, 2, 3).
    - `period`: the period of a `periodic_*` feature, in the coordinate's unit.
    - `velocity_scale`: $v_s$ of the smoothed sign $\tanh(\dot q / v_s)$.
    """

    kind: str = eqx.field(static=True)
    coordinate: int = eqx.field(static=True, default=0)
    input: int = eqx.field(static=True, default=0)
    power: int = eqx.field(static=True, default=1)
    period: float = eqx.field(static=True, default=1.0)
    velocity_scale: float = eqx.field(static=True, default=1e-2)

    def __check_init__(self):
        if self.kind not in FEATURE_KINDS:
            raise UsageError(f"Feature: `kind` must be one of {FEATURE_KINDS}, got {self.kind!r}")
        if self.kind.startswith("periodic") and not self.period > 0:
            raise UsageError(f"Feature: a periodic feature needs a positive `period`, got {self.period}")

    def __call__(
        self, q: Float[Array, " n_joints"], dq: Float[Array, " n_joints"], a: Float[Array, " n_inputs"]
    ) -> Float[Array, ""]:
        """The feature's value at positions `q`, velocities `dq` and applied input `a`."""
        qj, vj, ai = q[self.coordinate], dq[self.coordinate], a[self.input]
        sign = jnp.tanh(vj / self.velocity_scale)
        phase = 2 * jnp.pi * qj / self.period
        return {
            "position": lambda: qj**self.power,
            "sin": lambda: jnp.sin(qj),
            "cos": lambda: jnp.cos(qj),
            "velocity": lambda: vj,
            "sign": lambda: sign,
            "abs_velocity": lambda: jnp.abs(vj) * vj,
            "position_sign": lambda: qj * sign,
            "input": lambda: ai,
            "input_position": lambda: ai * qj,
            "input_velocity": lambda: ai * vj,
            "periodic_sin": lambda: jnp.sin(phase),
            "periodic_cos": lambda: jnp.cos(phase),
            "constant": lambda: jnp.ones_like(qj),
        }[self.kind]()

    def name(self, system) -> str:
        """A readable name in the contract's coordinate and input names, e.g. `q2`, `sin(2π q/0.05)`."""
        c = system.state_names[self.coordinate]
        u = system.input_names[self.input]
        return {
            "position": c if self.power == 1 else f"{c}^{self.power}",
            "sin": f"sin({c})",
            "cos": f"cos({c})",
            "velocity": f"d{c}",
            "sign": f"sign(d{c})",
            "abs_velocity": f"|d{c}|d{c}",
            "position_sign": f"{c}*sign(d{c})",
            "input": u,
            "input_position": f"{u}*{c}",
            "input_velocity": f"{u}*d{c}",
            "periodic_sin": f"sin(2π {c}/{self.period:.5g})",
            "periodic_cos": f"cos(2π {c}/{self.period:.5g})",
            "constant": "1",
        }[self.kind]


class Discovered(AbstractJointTerm):
    r"""A discovered term: $\sum_i c_i \phi_i(q, \dot q, a)$ added to the generalised force at one coordinate.

    Cause `discovered`. Its neutral value is all coefficients zero. `formula(system)` renders it
    in torque form (`tau_q2 += -1.49*q2`, the force balance $M\ddot q + h = Ba + f$) and
    `acceleration_formula(system)` in acceleration form (`ddq2 += M^-1[:,q2] (...)`).

    **Arguments:** `joint` (0-based coordinate), `features` (a tuple of `Feature`),
    `coefficients` (one per feature).
    """

    joint: int = eqx.field(static=True)
    features: tuple[Feature, ...] = eqx.field(static=True)
    coefficients: Float[Array, " n_features"]
    cause: ClassVar[str] = "discovered"
    prefix: ClassVar[str] = "c"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, joint: int, features, coefficients: ArrayLike | Sequence[float] | None = None):
        self.joint = joint
        self.features = tuple(features)
        if coefficients is None:
            coefficients = jnp.zeros(len(self.features))
        self.coefficients = jnp.asarray(coefficients, dtype=jnp.result_type(float))

    def __check_init__(self):
        super().__check_init__()
        if not self.features or not all(isinstance(f, Feature) for f in self.features):
            raise UsageError("Discovered: `features` must be a non-empty tuple of Feature")
        if self.coefficients.shape != (len(self.features),):
            raise UsageError(
                f"Discovered: `coefficients` must have shape ({len(self.features)},), got {self.coefficients.shape}"
            )

    @property
    def coefficient(self) -> Float[Array, ""]:
        """The size of the term, $\\lVert c \\rVert_2$ (the coefficients themselves are `coefficients`)."""
        return jnp.linalg.norm(self.coefficients)

    def joint_force(self, q, dq, a, z=None):
        values = jnp.stack([f(q, dq, a) for f in self.features])
        return jnp.dot(self.coefficients, values)

    def feature_names(self, system) -> tuple[str, ...]:
        return tuple(f.name(system) for f in self.features)

    def parameter_names(self, system) -> tuple[str, ...]:
        """One report name per coefficient, e.g. `c_q2[q2]`."""
        where = self.where(system)
        return tuple(f"c_{where}[{n}]" for n in self.feature_names(system))

    def parameters(self, system) -> dict[str, Array]:
        return dict(zip(self.parameter_names(system), self.coefficients))

    def label(self, system) -> str:
        return f"{self.cause}@{self.where(system)}[{' + '.join(self.feature_names(system))}]"

    def _sum(self, system, digits: int) -> str:
        parts = []
        for c, n in zip(map(float, self.coefficients), self.feature_names(system)):
            parts.append(f"{'-' if c < 0 else '+'} {abs(c):.{digits}g}*{n}")
        text = " ".join(parts)
        return text[2:] if text.startswith("+ ") else "-" + text[2:]

    def formula(self, system, digits: int = 4) -> str:
        """Torque (generalised force) form, e.g. `tau_q2 += -1.49*q2`."""
        return f"tau_{self.where(system)} += {self._sum(system, digits)}"

    def acceleration_formula(self, system, digits: int = 4) -> str:
        """Acceleration form, e.g. `ddq2 += (-1.49*q2) / M22` for the diagonal, or `M^-1` for coupled joints."""
        where = self.where(system)
        n = getattr(system, "n_joints", 1)
        if n == 1:
            return f"dd{where} += ({self._sum(system, digits)}) / M"
        j = self.joint + 1
        return f"ddq += M(q)^-1 e{j} ({self._sum(system, digits)})   (so dd{where} += M^-1[{j},{j}] (...))"
