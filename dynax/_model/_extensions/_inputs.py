"""Input-side model extensions: gain, offset, first-order lag and dead time of one input; one dead time and
one first-order lag shared by several inputs (a multirotor's motors)."""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float
import numpy as np

from ..._errors import UsageError
from ._terms import AbstractTerm, float_scalar

# Time constants and delays at or below this are treated as zero (the input passes through).
_TINY_TIME = 1e-4


def _time(term: str, name: str, value: ArrayLike) -> Array:
    """A time constant or dead time given as a number: refused unless it is a time >= 0 (a negative delay would
    act before the command, a negative time constant is an unstable filter; NaN is no time). Arrays and traced
    values pass unchecked (a fit sets them)."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not value >= 0.0:
        raise UsageError(f"{term}: `{name}` must be a time >= 0 [s], got {value}")
    return float_scalar(value)


class AbstractInputTerm(AbstractTerm):
    r"""A term acting on one input channel between the recorded and the applied input.

    It may carry `n_hidden` internal states $z$ per input (the lag's output, the delay's filter states),
    which depend on the input only: $\dot z = g(u_i, z)$, applied input $a(u_i, z)$. The rest of dynax
    counts them by `hidden_names`, the protocol every term has (`AbstractTerm`).

    **Fields:** `input`, the 0-based index of the input (static).
    """

    input: eqx.AbstractVar[int]
    n_hidden: ClassVar[int] = 0

    def __check_init__(self):
        if not isinstance(self.input, int) or self.input < 0:
            raise UsageError(f"{type(self).__name__}: `input` must be a non-negative int index, got {self.input!r}")

    @property
    def inputs(self) -> tuple[int, ...]:
        """The inputs the term acts on (0-based); `n_hidden` internal states each."""
        return (self.input,)

    def where(self, system) -> str:
        if self.input >= system.n_inputs:
            raise UsageError(
                f"{type(self).__name__}: `input={self.input}` but {type(system).__name__} has inputs "
                f"{system.input_names}"
            )
        return system.input_names[self.input]

    def hidden_names(self, system) -> tuple[str, ...]:
        """Names of the internal states, e.g. `tau2_lag`."""
        where = self.where(system)
        suffix = self.prefix
        return tuple(
            f"{where}_{suffix}" if self.n_hidden == 1 else f"{where}_{suffix}{k + 1}" for k in range(self.n_hidden)
        )

    def applied(self, u: Float[Array, ""], z: Float[Array, " n_hidden"]) -> Float[Array, ""]:
        """The input that acts on the system, from the recorded one `u` and the internal states `z`."""
        return u

    def hidden_derivative(self, u: Float[Array, ""], z: Float[Array, " n_hidden"]) -> Float[Array, " n_hidden"]:
        """$\\dot z$."""
        return jnp.zeros_like(z)

    def steady_state(self, u: Float[Array, ""]) -> Float[Array, " n_hidden"]:
        """The internal states at rest under a constant input `u` (used to start a rollout)."""
        return jnp.zeros((self.n_hidden,), jnp.result_type(u, self.coefficient))

    def shift(self, us: Float[Array, "step n_inputs"], dt: Float[ArrayLike, ""]) -> Float[Array, "step n_inputs"]:
        """The recorded inputs `us` (zero-order hold, `dt` apart) as a windowed rollout of a record passes them on,
        before the ODE: unchanged, but for a dead time, which shifts them exactly (`InputDelay.shift`)."""
        return us

    def after_shift(self) -> "AbstractInputTerm":
        """The term as it acts in the ODE once `shift` has moved the inputs: itself, but for a dead time (none left)."""
        return self


class InputGain(AbstractInputTerm):
    """The applied input is `gain` times the recorded one (a wrong drive gain or torque constant).

    **Arguments:** `input` (0-based), `gain` (dimensionless; neutral 1).
    """

    input: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "input_gain"
    prefix: ClassVar[str] = "gain"
    neutral: ClassVar[float] = 1.0
    sign: ClassVar[int] = 0

    def __init__(self, input: int, gain: ArrayLike = 1.0):
        self.input = input
        self.coefficient = float_scalar(gain)

    def applied(self, u, z):
        return self.coefficient * u


class InputOffset(AbstractInputTerm):
    """A constant force or torque `offset` adds to the recorded input (sensor bias, cable, gravity comp.).

    **Arguments:** `input` (0-based), `offset` [input units].
    """

    input: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "input_offset"
    prefix: ClassVar[str] = "offset"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def __init__(self, input: int, offset: ArrayLike = 0.0):
        self.input = input
        self.coefficient = float_scalar(offset)

    def applied(self, u, z):
        return u + self.coefficient


class _AbstractLag(AbstractInputTerm):
    r"""A first-order lag $\tau \dot a = u - a$ on each of its inputs (the term's `coefficient` $\tau$), one internal
    state per input, the applied input; a time constant of zero passes the input through."""

    coefficient: eqx.AbstractVar[Float[Array, ""]]

    def applied(self, u, z):
        return jnp.where(self.coefficient > _TINY_TIME, z[0], u)

    def hidden_derivative(self, u, z):
        tau = jnp.maximum(self.coefficient, _TINY_TIME)
        return jnp.where(self.coefficient > _TINY_TIME, (u - z) / tau, 0.0 * z)

    def steady_state(self, u):
        return jnp.reshape(u, (1,)).astype(jnp.result_type(u, self.coefficient))


class _AbstractMotors(AbstractInputTerm):
    """A term on several inputs at once, `motors` (0-based, distinct; the first is its `input`), placed at
    `motors`."""

    motors: eqx.AbstractVar[tuple[int, ...]]

    def __check_init__(self):
        if not all(isinstance(i, int) and i >= 0 for i in self.motors):
            raise UsageError(f"{type(self).__name__}: `inputs` must be non-negative int indices, got {self.motors!r}")

    @property
    def inputs(self) -> tuple[int, ...]:
        return self.motors

    def where(self, system) -> str:
        if max(self.motors) >= system.n_inputs:
            raise UsageError(
                f"{type(self).__name__}: `inputs={self.motors}` but {type(system).__name__} has inputs "
                f"{system.input_names}"
            )
        return "motors"


def _motor_indices(term: str, inputs) -> tuple[int, ...]:
    """The distinct input indices of a term on several motors, refused otherwise."""
    inputs = tuple(inputs)
    if not inputs or len(set(inputs)) != len(inputs):
        raise UsageError(f"{term}: `inputs` must be distinct input indices, got {inputs!r}")
    return inputs


class InputLag(_AbstractLag):
    r"""The input acts through a first-order lag $\tau \dot a = u - a$ (motor current or drive dynamics).

    One internal state, the applied input $a$. A time constant of zero passes the input through.
    Simulating with fixed steps needs steps shorter than about $\tau$.

    **Arguments:** `input` (0-based), `time_constant` $\tau$ [s].
    """

    input: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "input_lag"
    prefix: ClassVar[str] = "lag"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1
    n_hidden: ClassVar[int] = 1

    def __init__(self, input: int, time_constant: ArrayLike = 0.0):
        self.input = input
        self.coefficient = _time("InputLag", "time_constant", time_constant)


class _AbstractPadeDelay(AbstractInputTerm):
    r"""A dead time $T$ (the term's `coefficient`), in two forms.

    - In an ODE (`simulate`, the one-step residuals): the (2, 2) Padé approximant, two internal states per input,
      $a = u - T s F(s) u$ with $F = 1 / (1 + sT/2 + s^2 T^2 / 12)$, $z = (F u, s F u)$. A delay of zero passes the
      input through. Its poles lie at $|s| T = \sqrt{12}$, 150 degrees from the positive real axis: one Tsit5 step
      of $h$ per sample follows the delayed input for $T \ge h$ and diverges just below it, and where it is
      resolved it shows a dead time shorter than a sample as a first-order lag of the same size would (its
      moments, not its shape, are the dead time's).
    - In the windowed rollouts of a record (`dynax.internal.window_rollout` with an input history, which the
      diagnosis fits and judges with): exactly, as the recorded zero-order-hold input shifted by $T$
      (`shift`). Then a dead time of any size, a fraction of a sample included, is simulated right, and told from
      a lag by what the record shows.
    """

    coefficient: eqx.AbstractVar[Float[Array, ""]]

    def shift(self, us: Float[Array, "step n_inputs"], dt: Float[ArrayLike, ""]) -> Float[Array, "step n_inputs"]:
        r"""The recorded inputs `us` (zero-order hold, `dt` apart, the first ones history) delayed by $T$ on the
        term's inputs: over each sample interval the mean of the held input $T$ earlier,
        $a_k = (1 - f)\,u_{k-m} + f\,u_{k-m-1}$ with $T/\Delta t = m + f$, $0 \le f < 1$ (the first sample held
        before the record). That mean is exact for what the interval's input does to the state at the interval's
        end to first order in the step, and continuous and differentiable in $T$ within each sample (a fit moves
        it)."""
        s = jnp.maximum(self.coefficient, 0.0) / dt
        m = jnp.floor(s)
        f = (s - m).astype(us.dtype)
        k = jnp.arange(us.shape[0]) - m.astype(jnp.int32)
        now, before = us[jnp.maximum(k, 0)], us[jnp.maximum(k - 1, 0)]
        columns = jnp.asarray(self.inputs)
        return us.at[:, columns].set((1.0 - f) * now[:, columns] + f * before[:, columns])

    def after_shift(self):
        """This term with no delay left in the ODE (its `shift` moved the inputs instead)."""
        return eqx.tree_at(lambda t: t.coefficient, self, jnp.zeros_like(self.coefficient))

    def applied(self, u, z):
        return jnp.where(self.coefficient > _TINY_TIME, u - self.coefficient * z[1], u)

    def hidden_derivative(self, u, z):
        active = self.coefficient > _TINY_TIME
        T = jnp.maximum(self.coefficient, _TINY_TIME)
        a2, a1 = T**2 / 12.0, T / 2.0
        dz = jnp.stack([z[1], (u - z[0] - a1 * z[1]) / a2])
        return jnp.where(active, dz, 0.0 * z)

    def steady_state(self, u):
        dtype = jnp.result_type(u, self.coefficient)
        return jnp.stack([jnp.asarray(u, dtype), jnp.zeros((), dtype)])


class InputDelay(_AbstractPadeDelay):
    r"""The input acts a dead time $T$ late, $a(t) = u(t - T)$.

    In an ODE, represented by the (2, 2) Padé approximant
    $e^{-sT} \approx (1 - sT/2 + s^2T^2/12) / (1 + sT/2 + s^2T^2/12)$, two internal states,
    so that the delay is a smooth, differentiable parameter of an ODE. Accurate for input content
    below about $1/(2T)$ Hz; fixed-step simulation needs steps shorter than about $T/2$. A delay of
    zero passes the input through. The windowed rollouts of a record (with its input history, as the
    diagnosis takes them) shift the recorded input by $T$ instead, exactly (`shift`), so a dead time
    shorter than a sample is simulated as one.

    **Arguments:** `input` (0-based), `delay` $T$ [s].

    ??? cite

        G. F. Franklin, J. D. Powell, A. Emami-Naeini, *Feedback Control of Dynamic Systems*,
        section 5.6 (Padé approximation of a time delay).
    """

    input: int = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "input_delay"
    prefix: ClassVar[str] = "delay"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1
    n_hidden: ClassVar[int] = 2

    def __init__(self, input: int, delay: ArrayLike = 0.0):
        self.input = input
        self.coefficient = _time("InputDelay", "delay", delay)


class MotorDelay(_AbstractPadeDelay, _AbstractMotors):
    r"""One dead time $T$ on several inputs at once, $a_i(t) = u_i(t - T)$: the latency between a
    multirotor's logged motor commands and the rotors' thrust (the speed controller, the motor's
    spin-up, the log's own latency), which all motors share.

    Each input's delay is `InputDelay`'s (2, 2) Padé approximant, two internal states per input. A
    per-motor `InputDelay` or `InputLag` acts on one motor; this term moves every motor's command by
    the same time, as a latency in the command chain does.

    **Arguments:** `inputs` (0-based indices, default the four motors `(0, 1, 2, 3)`), `delay` $T$ [s].
    """

    input: int = eqx.field(static=True)
    motors: tuple[int, ...] = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "motor_delay"
    prefix: ClassVar[str] = "delay"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1
    n_hidden: ClassVar[int] = 2

    def __init__(self, inputs: tuple[int, ...] = (0, 1, 2, 3), delay: ArrayLike = 0.0):
        self.motors = _motor_indices("MotorDelay", inputs)
        self.input = self.motors[0]
        self.coefficient = _time("MotorDelay", "delay", delay)

    def hidden_names(self, system) -> tuple[str, ...]:
        self.where(system)
        names = system.input_names
        return tuple(f"{names[i]}_{self.prefix}{k + 1}" for i in self.motors for k in range(self.n_hidden))


class MotorLag(_AbstractLag, _AbstractMotors):
    r"""One first-order lag $\tau$ on several inputs at once, $\tau \dot a_i = u_i - a_i$: the spin-up of a
    multirotor's rotors behind their commands, which identical motors and speed controllers share.

    A per-motor `InputLag` lags one motor; this term lags every motor by the same time constant, as
    `MotorDelay` delays them all by one dead time. The two are told apart by the shape of the response: a lag
    answers a step at once and settles exponentially, a dead time answers nothing until it has passed.

    One internal state per input, its applied input. A time constant of zero passes the inputs through.

    **Arguments:** `inputs` (0-based indices, default the four motors `(0, 1, 2, 3)`), `time_constant`
    $\tau$ [s].
    """

    input: int = eqx.field(static=True)
    motors: tuple[int, ...] = eqx.field(static=True)
    coefficient: Float[Array, ""]
    cause: ClassVar[str] = "motor_lag"
    prefix: ClassVar[str] = "lag"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 1
    n_hidden: ClassVar[int] = 1

    def __init__(self, inputs: tuple[int, ...] = (0, 1, 2, 3), time_constant: ArrayLike = 0.0):
        self.motors = _motor_indices("MotorLag", inputs)
        self.input = self.motors[0]
        self.coefficient = _time("MotorLag", "time_constant", time_constant)

    def hidden_names(self, system) -> tuple[str, ...]:
        self.where(system)
        return tuple(f"{system.input_names[i]}_motor_lag" for i in self.motors)
