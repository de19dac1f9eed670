r"""Linear-in-parameter regressors of the rigid-body models: dynamic, energy and power.

Every model here is linear in its parameter vector $\theta$, so its regressor is the Jacobian of the
model with respect to $\theta$. Nothing is expanded by hand: the dynamic regressor is
`jax.jacfwd` of the inverse dynamics $M(q)\ddot q + h(q, \dot q) + F(\dot q)$, the energy regressor is
`jax.grad` of the total energy $H(q, \dot q)$ (linear in $\theta_1..\theta_5$), and the friction
columns are the Jacobian of the friction force. The parameter vectors are named in the contract's
names:

- `Acrobot`, `DoublePendulum`: `theta1..theta7` (viscous friction), plus `fc1`, `fc2` with Coulomb
  friction $f_{ci} \operatorname{sign}(\dot q_i)$.
- `LinearAxis`: `mass`, `viscous`, `offset`, plus `coulomb` with Coulomb friction (the EMPS model
  $F = M \ddot q + F_v \dot q + F_c \operatorname{sign}(\dot q) + F_0$).
"""

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._errors import UsageError
from .._model._linear_axis import LinearAxis
from .._model._system import AbstractSystem
from .._model._two_link import AbstractTwoLink, BASE_PARAMETER_NAMES

Friction = Literal["viscous", "coulomb"]

_TWO_LINK_ENERGY = BASE_PARAMETER_NAMES[:5]


def _check_friction(friction):
    if friction not in ("viscous", "coulomb"):
        raise UsageError(f"`friction` must be 'viscous' or 'coulomb', got {friction!r}")


def parameter_names(system: AbstractSystem, friction: Friction = "viscous") -> tuple[str, ...]:
    """The names of the regressor's columns (the identified parameters), in the contract's names.

    **Arguments:**

    - `system`: an `Acrobot`, `DoublePendulum` or `LinearAxis`.
    - `friction`: `"viscous"` or `"coulomb"` (adds the Coulomb columns).

    **Returns:** a tuple of names, e.g. `("theta1", ..., "theta7", "fc1", "fc2")`.
    """
    _check_friction(friction)
    if isinstance(system, AbstractTwoLink):
        return BASE_PARAMETER_NAMES + (("fc1", "fc2") if friction == "coulomb" else ())
    if isinstance(system, LinearAxis):
        return ("mass", "viscous") + (("coulomb",) if friction == "coulomb" else ()) + ("offset",)
    raise UsageError(
        f"least-squares identification supports Acrobot, DoublePendulum and LinearAxis, got {type(system).__name__}; "
        "use SimulationFit() for other systems"
    )


def energy_parameter_names(system: AbstractSystem) -> tuple[str, ...]:
    """The parameters the total energy depends on (the rest enter through dissipation only)."""
    if isinstance(system, AbstractTwoLink):
        return _TWO_LINK_ENERGY
    if isinstance(system, LinearAxis):
        return ("mass",)
    parameter_names(system)  # raises the informative error
    raise AssertionError


def parameter_vector(system: AbstractSystem, friction: Friction = "viscous") -> Float[Array, " n_params"]:
    """The system's current parameters as a vector in the order of `parameter_names` (Coulomb terms 0)."""
    names = parameter_names(system, friction)
    values = [getattr(system, n) if hasattr(system, n) and not n.startswith("fc") else 0.0 for n in names]
    dtype = jnp.result_type(*[jnp.asarray(v) for v in values], float)
    return jnp.stack([jnp.asarray(v, dtype) for v in values])


def _with(system, names, theta):
    """`system` with its parameter fields replaced by the entries of `theta` (Coulomb ones left out)."""
    fields = [n for n in names if hasattr(system, n)]
    values = [theta[names.index(n)] for n in fields]
    return eqx.tree_at(lambda s: [getattr(s, n) for n in fields], system, values)


def _coulomb(names, theta, dq):
    """The Coulomb friction force, exact sign (identification does not need it smooth)."""
    out = jnp.zeros_like(dq)
    for i, n in enumerate(("fc1", "fc2")):
        if n in names:
            out = out.at[i].add(theta[names.index(n)] * jnp.sign(dq[i]))
    return out


def _inverse_dynamics(system, names, theta, q, dq, ddq):
    """Generalised force that produces `ddq` at `(q, dq)`; linear in `theta`."""
    if isinstance(system, AbstractTwoLink):
        s = _with(system, names, theta)
        return s.mass_matrix(q) @ ddq + s.bias_force(q, dq) + _coulomb(names, theta, dq)
    # LinearAxis, exact sign.
    p = dict(zip(names, theta))
    force = p["mass"] * ddq[0] + p["viscous"] * dq[0] + p["offset"]
    if "coulomb" in p:
        force = force + p["coulomb"] * jnp.sign(dq[0])
    return force[None]


def _energy(system, names, theta, q, dq):
    if isinstance(system, AbstractTwoLink):
        return _with(system, names, theta).energy(jnp.concatenate([q, dq]))
    return 0.5 * theta[names.index("mass")] * dq[0] ** 2


def _positions(system, xs):
    n = system.n_joints if isinstance(system, AbstractTwoLink) else 1
    return xs[..., :n], xs[..., n : 2 * n]


def generalised_force(system: AbstractSystem, us: Float[Array, "time n_inputs"]) -> Float[Array, "time n_joints"]:
    r"""The measured generalised forces $B u$, one entry per joint (the acrobot's `tau1` is 0)."""
    parameter_names(system)
    if isinstance(system, AbstractTwoLink):
        return us @ system.input_matrix().T.astype(us.dtype)
    return us[..., :1]


@eqx.filter_jit
def dynamic_regressor(
    system: AbstractSystem,
    xs: Float[Array, "time n_states"],
    ddq: Float[Array, "time n_joints"],
    friction: Friction = "viscous",
) -> Float[Array, "time n_joints n_params"]:
    r"""The inverse-dynamics regressor $Y(q, \dot q, \ddot q)$ with $Y\theta = M\ddot q + h + F = B u$.

    One row per joint and sample: both equations of motion are kept (never summed), and for the
    acrobot the unactuated shoulder gives the row $Y_1 \theta = 0$.

    **Arguments:**

    - `system`: the model (its parameter values are irrelevant: the model is linear in them).
    - `xs`: states `(q, dq)`, shape `(time, n_states)`.
    - `ddq`: joint accelerations, shape `(time, n_joints)`.
    - `friction`: `"viscous"` or `"coulomb"`.

    **Returns:** shape `(time, n_joints, n_params)`, columns named by `parameter_names`.

    ??? cite

        M. Gautier and W. Khalil, "Direct calculation of minimum set of inertial parameters of
        serial robots", IEEE Transactions on Robotics and Automation 6(3), 1990.
    """
    names = parameter_names(system, friction)
    theta0 = jnp.zeros(len(names), xs.dtype)
    q, dq = _positions(system, xs)

    def row(q, dq, ddq):
        return jax.jacfwd(lambda th: _inverse_dynamics(system, names, th, q, dq, ddq))(theta0)

    return jax.vmap(row)(q, dq, ddq)


@eqx.filter_jit
def energy_regressor(
    system: AbstractSystem, xs: Float[Array, "time n_states"], friction: Friction = "viscous"
) -> Float[Array, "time n_params"]:
    r"""The total-energy regressor $w(q, \dot q)$ with $H = w\,\theta$ (zero in the dissipative columns).

    Obtained as `jax.grad` of the energy with respect to the parameters: the energy is linear in
    $\theta_1..\theta_5$ (two-link) or in the mass (linear axis).

    **Arguments:** `system`; `xs` of shape `(time, n_states)`; `friction`.

    **Returns:** shape `(time, n_params)`.

    ??? cite

        M. Gautier and W. Khalil, "On the identification of the inertial parameters of robots",
        Proc. 27th IEEE Conference on Decision and Control, 1988.
    """
    names = parameter_names(system, friction)
    theta0 = jnp.zeros(len(names), xs.dtype)
    q, dq = _positions(system, xs)
    return jax.vmap(lambda q, dq: jax.grad(lambda th: _energy(system, names, th, q, dq))(theta0))(q, dq)


@eqx.filter_jit
def friction_power_regressor(
    system: AbstractSystem, xs: Float[Array, "time n_states"], friction: Friction = "viscous"
) -> Float[Array, "time n_params"]:
    r"""The dissipated power $\dot q^\top F(\dot q)$ as a regressor row (zero in the energy columns).

    $F$ is the non-conservative part of the inverse dynamics (viscous, Coulomb and, for the linear
    axis, the constant offset force), obtained as the inverse dynamics at $\ddot q = 0$ with the
    energy parameters masked out.

    **Arguments:** `system`; `xs` of shape `(time, n_states)`; `friction`.

    **Returns:** shape `(time, n_params)`.
    """
    names = parameter_names(system, friction)
    energy_names = energy_parameter_names(system)
    mask = jnp.asarray([n not in energy_names for n in names], xs.dtype)
    q, dq = _positions(system, xs)
    ys = dynamic_regressor(system, xs, jnp.zeros_like(dq), friction)
    return jnp.einsum("tj,tjp->tp", dq, ys) * mask


@eqx.filter_jit
def input_power(system: AbstractSystem, xs: Float[Array, "time n_states"], us: Float[Array, "time n_inputs"]) -> Float[Array, " time"]:
    r"""The power delivered by the inputs, $\dot q^\top B u$."""
    _, dq = _positions(system, xs)
    return jnp.sum(dq * generalised_force(system, us), axis=-1)
