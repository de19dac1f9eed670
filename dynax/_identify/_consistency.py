r"""Physical consistency of identified parameters: the conditions, a check, and a constrained fit.

**Two-link arms** (`Acrobot`, `DoublePendulum`, base parameters of the contract). With
$I_1 = I_{c1} + m_1 l_{c1}^2$, $I_2 = I_{c2} + m_2 l_{c2}^2$, $m_i > 0$, $I_{ci} \ge 0$, the base
parameters satisfy

- **rigid-body inertia**: $\begin{pmatrix}\theta_1 & \theta_3\\ \theta_3 & \theta_2\end{pmatrix}
  \succeq 0$ with $\theta_2 > 0$, because $\theta_1\theta_2 - \theta_3^2 = I_1 I_2 + m_2 l_1^2 I_{c2}
  \ge 0$ (it is $\theta_1 \ge m_2 l_1^2$, $\theta_2 \ge m_2 l_{c2}^2$ and $\theta_3 = m_2 l_1 l_{c2}$).
  It is exactly the condition that the rigid-body mass matrix $M(q)$ is positive definite at *every*
  elbow angle, since $\det M = \theta_1\theta_2 - \theta_3^2\cos^2 q_2$;
- **hanging rest is stable**: $\theta_4 > 0$ and $\theta_5 > 0$. The contract measures $q$ from
  hanging straight down; the potential $-\theta_4\cos q_1 - \theta_5\cos(q_1 + q_2)$ has a minimum
  there iff its Hessian $\begin{pmatrix}\theta_4 + \theta_5 & \theta_5\\ \theta_5 & \theta_5
  \end{pmatrix}$ is positive definite;
- **link 1 has positive length**: $\theta_3 \ge 0$, since $g\theta_3/\theta_5 = l_1$;
- **friction dissipates**: $\theta_6, \theta_7, f_{c1}, f_{c2} \ge 0$;
- **static friction** (`Stiction`'s `fs`): at least the joint's Coulomb level (the Stribeck curve falls
  from the static level to the Coulomb one) and at least the largest torque the records show the
  joint holding at rest under the rigid body's gravity (`Stiction.held`): $f_s \ge \max(f_c, f_{held})$;
- **rotor inertia**: $I_{r} \ge 0$. A geared motor's coupling term ($M_{12} \mathrel{-}= g_r I_r$,
  $M_{11} \mathrel{+}= (g_r^2 + 1) I_r$, $M_{22} \mathrel{+}= g_r^2 I_r$, as in the DFKI lab's
  equations) is absorbed exactly by the base parameters: $\theta_1 \mathrel{+}= (g_r^2 + g_r + 1) I_r$,
  $\theta_2 \mathrel{-}= g_r I_r$ and $I_{r2} = (g_r^2 + g_r) I_r$ at the elbow. The conditions
  above then hold for the rigid-body-plus-coupling part as long as $g_r I_r < I_2$ (the case for
  quasi-direct drives, whose $g_r I_r$ is about 1 % of $I_2$).

On top, `check_consistency` evaluates the whole model's mass matrix (with rotor inertia) at the
data's configurations.

**Linear axis**: mass $> 0$, viscous and Coulomb friction $\ge 0$; the offset is free.

**The constrained fit** (`consistent_least_squares`) minimises the same weighted least-squares cost
over the consistent set, a convex set (a 2x2 linear matrix inequality and sign constraints, the
two-link reduction of Wensing, Kim and Slotine's LMI), through a parametrisation that is consistent
by construction: every non-negative parameter is $s\,\mathrm{softplus}(\phi)$,
$\theta_1 = \theta_3^2/\theta_2 + s_1\mathrm{softplus}(\phi_1)$ (a positive Schur complement), and a
static level $f_s = \max(f_c, f_{held}) + s\,\mathrm{softplus}(\phi)$.
The map is a diffeomorphism onto the interior of the set and the cost is convex in $\theta$, so a
stationary point in $\phi$ is the global constrained minimum. It is solved by Levenberg-Marquardt
(optimistix) on the $n$ residuals $S V^\top D\theta - U^\top W^{1/2} y$ of the regressor's SVD,
which has the same minimiser as the full problem.

??? cite

    C. D. Sousa and R. Cortesão, "Physical feasibility of robot base inertial parameter
    identification: a linear matrix inequality approach", Int. J. Robotics Research 33(6), 2014;
    P. M. Wensing, S. Kim and J.-J. E. Slotine, "Linear matrix inequalities for physically
    consistent inertial parameter identification: a statistical perspective on the mass
    distribution", IEEE Robotics and Automation Letters 3(1), 2018.
"""

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._fit import fit_least_squares, LeastSquaresOptions, levenberg_marquardt
from .._model._extensions import Extended
from .._model._linear_in_parameters import identification_hooks, violated_bound


class InconsistentEstimateWarning(UserWarning):
    """An identified parameter set violates a physical-consistency condition."""


@dataclasses.dataclass(frozen=True)
class Consistency:
    """The outcome of `check_consistency` (and of the constrained fit).

    **Fields:**

    - `violated`: the conditions the estimate breaks, each as a sentence naming the parameters.
    - `active`: the conditions the constrained fit had to enforce (those the unconstrained
      estimate broke); empty when the constraint was not needed or not applied.
    - `constrained`: whether the returned estimate comes from the constrained fit.
    - `min_mass_eigenvalue`: the smallest eigenvalue of the model's mass matrix over the data's
      configurations (`None` where not evaluated).
    """

    violated: tuple[str, ...]
    active: tuple[str, ...] = ()
    constrained: bool = False
    min_mass_eigenvalue: float | None = None

    @property
    def consistent(self) -> bool:
        return not self.violated

    def to_json(self) -> dict:
        return {
            "consistent": self.consistent,
            "violated": list(self.violated),
            "constraint_active": bool(self.active),
            "active": list(self.active),
            "constrained": self.constrained,
            "min_mass_eigenvalue": self.min_mass_eigenvalue,
        }


def _base(system):
    return system.system if isinstance(system, Extended) else system


# Joint terms' coefficients that cannot be negative: Coulomb, rotor inertia, viscous, drag.
_NON_NEGATIVE_PREFIXES = ("fc", "fs", "Ir", "b", "cd")


def _kinds(system, names):
    """Per parameter: 'inertia1' (theta1, Schur complement), 'positive', 'nonnegative' or 'free'.

    The system's `base_parameter_kinds()` bound its base parameters; on a system with conditions,
    the joint terms' dissipative and inertial coefficients are non-negative. A system without
    conditions leaves every parameter free."""
    kinds = identification_hooks(_base(system)).base_parameter_kinds()

    def term_kind(n):
        return "nonnegative" if kinds and n.startswith(_NON_NEGATIVE_PREFIXES) else "free"

    return tuple(kinds[n] if n in kinds else term_kind(n) for n in names)


def consistency_conditions(system, names: tuple[str, ...], theta) -> tuple[str, ...]:
    """The physical-consistency conditions `theta` (named `names`) violates, as sentences.

    **Arguments:** `system` (its `base_parameter_conditions` and `base_parameter_kinds` decide the
    conditions: a two-link arm's or a linear axis's, optionally `Extended` with joint terms), `names`,
    `theta`.

    **Returns:** a tuple of sentences, empty when consistent. Other systems have no conditions here.
    """
    p = {n: float(v) for n, v in zip(names, np.asarray(theta))}
    base = identification_hooks(_base(system))
    own = base.base_parameter_kinds()
    out = list(base.base_parameter_conditions({n: v for n, v in p.items() if n in own}))
    for n, kind in zip(names, _kinds(system, names)):
        if n not in own:
            sentence = violated_bound(n, p[n], kind, "friction" if n.startswith(("fc", "b", "cd")) else "rotor inertia")
            out += [sentence] if sentence else []
    return tuple(dict.fromkeys(out))


def min_mass_eigenvalue(system, qs) -> float | None:
    r"""The smallest eigenvalue of the model's mass matrix (with its terms' inertia) over configurations `qs`.

    Evaluated at the configurations the system names (`mass_check_configurations`: for a two-link
    arm the two ends of the data's range of $\cos q_2$, where the minimum is exact), not at all of them;
    `None` for a system without a mass matrix.
    """
    terms = system.joint_terms if isinstance(system, Extended) else ()
    value = _min_mass_eigenvalue(_base(system), terms, jnp.asarray(qs))
    return None if value is None else float(value)


@eqx.filter_jit
def _min_mass_eigenvalue(base, terms, qs):
    # Compiled: op by op, even the choice of configurations costs more than the fit's solve.
    qs = identification_hooks(base).mass_check_configurations(qs)
    if qs is None:  # no mass matrix to check
        return None

    def mass(q):
        m = base.mass_matrix(q)
        for t in terms:
            m = m.at[t.joint, t.joint].add(t.inertia())
        if m.shape == (1, 1):
            return m[0, 0]
        if m.shape == (2, 2):
            # Closed form: a batched LAPACK eigensolver call per 2x2 matrix is far slower.
            half_trace, half_gap = 0.5 * (m[0, 0] + m[1, 1]), 0.5 * (m[0, 0] - m[1, 1])
            return half_trace - jnp.sqrt(half_gap**2 + m[0, 1] * m[1, 0])
        return jnp.linalg.eigvalsh(m)[0]

    return jnp.min(jax.vmap(mass)(qs))


def check_consistency(system, names, theta, qs=None, *, warn: bool = True) -> Consistency:
    """Check an estimate against the physical-consistency conditions; warn when it breaks one.

    **Arguments:** `system` carrying the estimate (for the mass matrix at `qs`), `names`, `theta`,
    `qs` the data's joint configurations `(time, n_joints)` (optional), `warn` whether to emit an
    `InconsistentEstimateWarning` naming each violated condition.

    **Returns:** a `Consistency`.
    """
    violated = list(consistency_conditions(system, names, theta))
    eigenvalue = None
    if qs is not None:
        eigenvalue = min_mass_eigenvalue(system, qs)
        if eigenvalue is not None and not eigenvalue > 0:
            violated.append(
                f"mass matrix: not positive definite at the data's configurations "
                f"(smallest eigenvalue {eigenvalue:.4g})"
            )
    if violated and warn:
        warnings.warn(
            "physically inconsistent estimate: " + "; ".join(violated), InconsistentEstimateWarning, stacklevel=3
        )
    return Consistency(tuple(violated), min_mass_eigenvalue=eigenvalue)


def _softplus_inverse(x):
    return x + jnp.log(-jnp.expm1(-x))


class ConsistentParametrisation(eqx.Module):
    r"""The map $\phi \mapsto \theta$ onto the interior of the consistent set (see the module notes).

    **Fields:** `kinds` per parameter (`"inertia1"`, `"positive"`, `"nonnegative"`, `"free"`),
    `scale` per parameter (the natural size $s$), and the indices of $\theta_2, \theta_3$.
    """

    scale: jax.Array
    kinds: tuple[str, ...] = eqx.field(static=True)
    i2: int = eqx.field(static=True)
    i3: int = eqx.field(static=True)
    # Static levels: per parameter the index of the Coulomb level it stays above (-1: none), and the rest it
    # held: the force applied there and the gravity there, affine in theta (row and intercept; zeros elsewhere).
    above: tuple[int, ...] = eqx.field(static=True, default=())
    held_force: jax.Array | None = None
    held_rows: jax.Array | None = None
    held_intercept: jax.Array | None = None

    def _static_floor(self, theta, i):
        r"""The least value of static level `i` at `theta`: $\max(f_c, f_{held})$, with $f_{held}$ the torque
        held at rest under the rigid body of `theta` (the force applied less the gravity there)."""
        held = jnp.zeros_like(theta[i])
        if self.held_force is not None and self.held_rows is not None and self.held_intercept is not None:
            held = jnp.abs(self.held_force[i] - self.held_rows[i] @ theta - self.held_intercept[i])
        return held if not self.above or self.above[i] < 0 else jnp.maximum(theta[self.above[i]], held)

    def theta(self, phi):
        values = []
        for i, kind in enumerate(self.kinds):
            values.append(self.scale[i] * (phi[i] if kind == "free" else jax.nn.softplus(phi[i])))
        theta = jnp.stack(values)
        if "inertia1" in self.kinds:
            i1 = self.kinds.index("inertia1")
            theta = theta.at[i1].add(theta[self.i3] ** 2 / theta[self.i2])
        for i, kind in enumerate(self.kinds):
            if kind == "static":
                theta = theta.at[i].add(self._static_floor(theta, i))
        return theta

    def phi(self, theta, floor=1e-3):
        """A point whose image is `theta` pushed into the interior (each bound parameter at least `floor * scale`)."""
        theta = jnp.asarray(theta)
        s = self.scale
        lifted = theta
        if "inertia1" in self.kinds:
            i1 = self.kinds.index("inertia1")
            t2 = jnp.maximum(theta[self.i2], floor * s[self.i2])
            t3 = jnp.maximum(theta[self.i3], floor * s[self.i3])
            lifted = lifted.at[i1].add(-(t3**2) / t2)
        for i, kind in enumerate(self.kinds):
            if kind == "static":
                lifted = lifted.at[i].add(-self._static_floor(theta, i))
        out = []
        for i, kind in enumerate(self.kinds):
            if kind == "free":
                out.append(lifted[i] / s[i])
            else:
                out.append(_softplus_inverse(jnp.maximum(lifted[i] / s[i], floor)))
        return jnp.stack(out)


def consistent_parametrisation(system, names, scale) -> ConsistentParametrisation:
    """The `ConsistentParametrisation` of `system`'s parameters `names`, with natural sizes `scale`."""
    kinds = _kinds(system, names)
    i2 = names.index("theta2") if "theta2" in names else 0
    i3 = names.index("theta3") if "theta3" in names else 0
    kinds = tuple("static" if k == "nonnegative" and n.startswith("fs") else k for k, n in zip(kinds, names))
    above = tuple(
        names.index(f"fc{n[2:]}") if k == "static" and f"fc{n[2:]}" in names else -1 for k, n in zip(kinds, names)
    )
    force, rows, intercept = _held_at_rest(system, names, jnp.result_type(jnp.asarray(scale)))
    return ConsistentParametrisation(jnp.asarray(scale), kinds, i2, i3, above, force, rows, intercept)


def _held_at_rest(system, names, dtype):
    """Per parameter, the rest its `Stiction` held (`Stiction.held_force`, `held_position`): the force applied,
    and the gravity at the joint there as an affine map of the parameters `names` (row, intercept); zeros for
    parameters of no `Stiction`, and for one without a position (its force is then the torque held)."""
    from .._model._extensions._stiction import Stiction
    from ._regressors import split_terms, with_parameters

    p = len(names)
    force, rows, intercept = np.zeros(p), np.zeros((p, p)), np.zeros(p)
    if isinstance(system, Extended):
        for t in system.terms:
            name = t.parameter_name(system.system)
            if not isinstance(t, Stiction) or name not in names:
                continue
            i = names.index(name)
            force[i] = float(t.held_force)
            if t.held_position is None:
                continue
            q = jnp.asarray(t.held_position, dtype)

            def gravity(theta, t=t, q=q):
                base = split_terms(with_parameters(system, names, theta))[0]
                zeros = jnp.zeros_like(q)
                return base.inverse_dynamics(q, zeros, zeros)[t.joint]  # pyright: ignore[reportAttributeAccessIssue]

            at = jnp.ones(p, dtype)
            rows[i] = np.asarray(jax.jacfwd(gravity)(at))
            intercept[i] = float(gravity(at)) - float(rows[i] @ np.asarray(at))
    return jnp.asarray(force, dtype), jnp.asarray(rows, dtype), jnp.asarray(intercept, dtype)


@eqx.filter_jit
def _constrained_solve(parametrisation, reduced, projected, col_scale, phi0, max_steps):
    def residuals(phi, _):
        return reduced @ (parametrisation.theta(phi) * col_scale) - projected

    # The engine's fit on phi itself (unit scale), with no covariance: the projection needs only the point.
    solver = levenberg_marquardt(rtol=1e-10, atol=1e-12)
    solution = fit_least_squares(
        residuals,
        phi0,
        True,
        None,
        solver=solver,
        scale=jnp.ones_like(phi0),
        max_steps=max_steps,
        options=LeastSquaresOptions(nonfinite=None, covariance=False),
    )
    return solution.value, solution.result == optx.RESULTS.successful


def consistent_least_squares(system, names, a, y, weights=None, start=None, *, max_steps: int = 500):
    r"""Weighted least squares over the physically consistent set of `system`'s parameters.

    **Arguments:** `system` and `names` (which parameters, which conditions), regressor `a`
    `(rows, n)`, target `y`, optional row `weights`, optional `start` (an estimate to start from,
    pushed into the interior; default the unconstrained solution).

    **Returns:** `(theta, converged)`: the constrained estimate and whether Levenberg-Marquardt met
    its tolerance within `max_steps`.
    """
    a = jnp.asarray(a)
    y = jnp.asarray(y)
    w = jnp.ones(a.shape[0], a.dtype) if weights is None else jnp.asarray(weights, a.dtype)
    sw = jnp.sqrt(w)
    aw, yw = a * sw[:, None], y * sw
    col = jnp.linalg.norm(aw, axis=0)
    col = jnp.where(col > 0, col, 1.0)
    q, r = jnp.linalg.qr(aw / col[None, :])
    projected = q.T @ yw
    if start is None:
        start = jnp.linalg.lstsq(r, projected)[0] / col
    # Natural size of each parameter: the value at which its column alone would explain the target.
    scale = jnp.linalg.norm(yw) / col / np.sqrt(len(names))
    scale = jnp.where(jnp.abs(start) > scale * 1e-2, jnp.abs(start), scale)
    parametrisation = consistent_parametrisation(system, names, scale)
    phi, converged = _constrained_solve(parametrisation, r, projected, col, parametrisation.phi(start), max_steps)
    return parametrisation.theta(phi), bool(converged)
