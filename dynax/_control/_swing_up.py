"""Drake's Spong swing-up controller for the acrobot: energy pumping, collocated PFL, LQR balance."""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._model._two_link import Acrobot
from ._lqr import LQR, lqr

SPONG_PARAMETER_NAMES = ("k_e", "k_p", "k_d", "phi")
"""The names of the Spong controller's tunable parameters, in the order of `SpongController.params`."""

DRAKE_SPONG_PARAMETERS = (5.0, 50.0, 5.0, 1000.0)
"""Drake's `SpongControllerParams` defaults: `k_e`, `k_p`, `k_d`, `balancing_threshold`."""

UPRIGHT = (jnp.pi, 0.0, 0.0, 0.0)


def balancing_lqr(system: Acrobot) -> LQR:
    r"""Drake's balancing LQR for the acrobot: $Q = \mathrm{diag}(10, 10, 1, 1)$, $R = 1$, about upright.

    **Arguments:**

    - `system`: the acrobot model to linearise.

    **Returns:**

    An `LQR` about $(\pi, 0, 0, 0)$ with both angles wrapped.
    """
    dtype = jnp.result_type(system.theta1, float)
    x_eq = jnp.asarray(UPRIGHT, dtype)
    balance = lqr(system, x_eq, jnp.zeros(1, dtype), jnp.array([10.0, 10.0, 1.0, 1.0], dtype), 1.0, angles=(0, 1))
    assert isinstance(balance, LQR)  # the system form (the matrix form returns python-control's tuple)
    return balance


class AbstractSwitchingRule(eqx.Module):
    """When the swing-up controller hands over to the balancing LQR.

    A rule maps the controller and the state to a weight in $[0, 1]$ on the LQR torque (1: LQR,
    0: swing-up); a hard rule returns exactly 0 or 1.
    """

    @abc.abstractmethod
    def weight(self, controller: "SpongController", x: Float[Array, " 4"]) -> Float[Array, ""]:
        """The weight on the LQR torque at state `x`."""


class CostToGoThreshold(AbstractSwitchingRule):
    r"""Drake's rule: balance when the LQR cost-to-go $\delta x^\top S \delta x$ is below `phi`."""

    def weight(self, controller, x):
        return jnp.where(controller.balance.cost_to_go(x) < controller.phi, 1.0, 0.0).astype(x.dtype)


class SmoothActivation(AbstractSwitchingRule):
    r"""A learnable soft hand-over: weight $\sigma((\log\phi - \log V(x)) / \tau)$ on the LQR torque.

    $V$ is the LQR cost-to-go. Unlike the hard threshold this is differentiable in `phi` and
    in the state, so the threshold can be tuned by backpropagation through rollouts along with
    the gains; as `temperature` goes to 0 it recovers `CostToGoThreshold`.

    **Arguments:**

    - `temperature`: $\tau$, the width of the blend in log cost-to-go (default 0.5).
    """

    temperature: float = 0.5

    def weight(self, controller, x):
        v = controller.balance.cost_to_go(x)
        log_ratio = jnp.log(jnp.maximum(controller.phi, 1e-12)) - jnp.log(jnp.maximum(v, 1e-12))
        return jax.nn.sigmoid(log_ratio / self.temperature)


class SpongController(eqx.Module):
    r"""Drake's `AcrobotSpongController`: energy-shaping swing-up with an LQR hand-over.

    With $E$ the total energy of the controller's model and $E_d$ its value upright at rest,

    - energy pumping $u_e = k_e (E_d - E)\dot q_2$;
    - collocated partial feedback linearisation $u_p = (a_2 C_0 + y)/a_3 + C_1$ with
      $y = -k_p q_2 - k_d \dot q_2$, $[[a_1, a_2], [a_2, a_3]] = M^{-1}$ and $(C_0, C_1)$ the
      bias vector (Coriolis, gravity and damping, Drake's `DynamicsBiasTerm`);
    - balancing $u = -K(x \ominus x_{up})$ from the LQR with $Q = \mathrm{diag}(10, 10, 1, 1)$,
      $R = 1$, angles wrapped, used when the LQR cost-to-go is below $\phi$ (`switching`);
    - the torque is saturated at $\pm$ `torque_limit`.

    The controller is pure: `__call__(t, x) -> u` with `u` of shape `(1,)`. The tunable
    parameters are $\theta = (k_e, k_p, k_d, \phi)$ (`params`, `with_params`); Drake's defaults
    are `(5, 50, 5, 1000)`. The model the controller uses (`system`) may differ from the plant
    it drives, which is how a controller tuned on an identified model is evaluated on the truth.

    It does not start from the exact hanging rest $(0, 0, 0, 0)$: there the energy pumping
    vanishes with $\dot q_2$, the partial feedback linearisation with $q_2$ and $\dot q_2$, and
    the bias forces with the angles and rates, so the torque is exactly zero and the arm never
    moves. Start it from a perturbed state (Drake's test starts at $(0.1, -0.1, 0, 0.02)$), or
    use a from-rest controller (`dynax.control.SwingUpFromRest`).

    **Arguments:**

    - `system`: the acrobot model inside the controller (default: Drake's parameters).
    - `k_e`, `k_p`, `k_d`, `phi`: the gains and the balancing threshold.
    - `balance`: the balancing `LQR` (default: `balancing_lqr(system)`).
    - `switching`: the hand-over rule (default `CostToGoThreshold()`, Drake's).
    - `torque_limit`: the saturation [N m] (default 20).

    ??? cite

        M. W. Spong, "Swing up control of the acrobot", IEEE ICRA 1994; Drake,
        `examples/acrobot/spong_controller.h`; R. Tedrake, *Underactuated Robotics*, ch. 3.
    """

    system: Acrobot
    k_e: Float[Array, ""]
    k_p: Float[Array, ""]
    k_d: Float[Array, ""]
    phi: Float[Array, ""]
    balance: LQR
    switching: AbstractSwitchingRule
    torque_limit: float = eqx.field(static=True)

    def __init__(
        self,
        system: Acrobot | None = None,
        k_e: ArrayLike = DRAKE_SPONG_PARAMETERS[0],
        k_p: ArrayLike = DRAKE_SPONG_PARAMETERS[1],
        k_d: ArrayLike = DRAKE_SPONG_PARAMETERS[2],
        phi: ArrayLike = DRAKE_SPONG_PARAMETERS[3],
        *,
        balance: LQR | None = None,
        switching: AbstractSwitchingRule | None = None,
        torque_limit: float = 20.0,
    ):
        if system is None:
            system = Acrobot()
        # What the controller needs, asked of the system: two joints, the torque at the elbow only.
        if tuple(system.joint_names) != ("q1", "q2") or tuple(system.input_names) != ("tau2",):
            raise ValueError(
                "SpongController: `system` must be an Acrobot (a two-link manipulator driven at the elbow, "
                f"input 'tau2'), got {type(system).__name__}"
            )
        self.system = system
        self.k_e, self.k_p, self.k_d, self.phi = (jnp.asarray(v) for v in (k_e, k_p, k_d, phi))
        self.balance = balancing_lqr(system) if balance is None else balance
        self.switching = CostToGoThreshold() if switching is None else switching
        self.torque_limit = float(torque_limit)

    @property
    def params(self) -> Float[Array, " 4"]:
        r"""$\theta = (k_e, k_p, k_d, \phi)$."""
        return jnp.stack([self.k_e, self.k_p, self.k_d, self.phi])

    def with_params(self, params: Float[ArrayLike, " 4"]) -> "SpongController":
        r"""A copy with $\theta = (k_e, k_p, k_d, \phi)$ replaced; the LQR is reused, not re-solved."""
        params = jnp.asarray(params)
        if params.shape != (4,):
            raise ValueError(
                f"SpongController.with_params: `params` must have shape (4,) (k_e, k_p, k_d, phi), got {params.shape}"
            )
        return eqx.tree_at(lambda c: (c.k_e, c.k_p, c.k_d, c.phi), self, tuple(params))

    def desired_energy(self) -> Float[Array, ""]:
        r"""$E_d = g(m_1 l_{c1} + m_2 (l_1 + l_{c2})) = \theta_4 + \theta_5$, the energy upright at rest."""
        return self.system.theta4 + self.system.theta5

    def swing_up_torque(self, x: Float[Array, " 4"]) -> Float[Array, ""]:
        r"""$u_e + u_p$, the energy-shaping and partial-feedback-linearisation torque (unsaturated)."""
        q, dq = x[:2], x[2:]
        m = self.system.mass_matrix(q)
        bias = self.system.bias_force(q, dq)
        det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        a2, a3 = -m[0, 1] / det, m[0, 0] / det
        energy_error = self.system.energy(x) - self.desired_energy()
        u_e = -self.k_e * energy_error * dq[1]
        y = -self.k_p * q[1] - self.k_d * dq[1]
        u_p = (a2 * bias[0] + y) / a3 + bias[1]
        return u_e + u_p

    def __call__(self, t: Float[ArrayLike, ""], x: Float[Array, " 4"]) -> Float[Array, " 1"]:
        w = self.switching.weight(self, x)
        u_balance = self.balance(t, x)[0]
        u = w * u_balance + (1 - w) * self.swing_up_torque(x)
        return jnp.clip(u, -self.torque_limit, self.torque_limit)[None]
