"""`Extended`: a system composed with model extensions, itself a system."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._errors import UsageError
from .._system import AbstractSystem
from ._inputs import AbstractInputTerm
from ._terms import AbstractJointTerm, AbstractTerm
from ._vehicle_terms import AbstractVehicleTerm


class Extended(AbstractSystem):
    r"""A system with model extensions added: `Extended(Acrobot(), (CoulombFriction(joint=1, fc=0.2),))`.

    Joint terms (friction, drag, rotor inertia, springs) act on a manipulator through its pieces,
    $\big(M(q) + \operatorname{diag}(I_r)\big)\ddot q + h(q, \dot q) = B\,a + \sum_k f_k(q, \dot q)$,
    so they compose with any `AbstractManipulator`. Vehicle terms (`BodyQuadraticDrag`, `Wind`,
    `BodyBias`) act on a `Helicopter`'s body-frame accelerations, the body model's aerodynamic
    features seeing the air-relative velocity (see `dynax._model._extensions._vehicle_terms`). Input terms (gain,
    offset, lag, delay) act on any system between the recorded input $u$ and the applied input $a$; they are applied in
    the order given, so `(InputGain(0, 2.0), InputLag(0, 0.05))` lags the doubled input. Terms whose
    coefficients are at their neutral values leave the nominal system unchanged.

    The state is the nominal state followed by the terms' internal states, named in `state_names`: the
    input terms' first (a lag's output, a delay's filter states: they move with the recorded input
    alone), then every other term's in the order given (`AbstractTerm.hidden_names`, e.g. `Stiction`'s
    memory of rest), each read by its own term. `initial_state(x0, u0)` completes a measured state
    with them (the input terms' at rest under `u0`, the others' `AbstractTerm.initial_hidden`).

    **Arguments:**

    - `system`: the nominal system.
    - `terms`: a tuple of terms (`CoulombFriction`, `InputDelay`, ...).
    """

    system: AbstractSystem
    terms: tuple[AbstractTerm, ...]

    def __check_init__(self):
        if not isinstance(self.system, AbstractSystem):
            raise UsageError(f"Extended: `system` must be a dynax system, got {type(self.system).__name__}")
        if isinstance(self.system, Extended):
            raise UsageError("Extended: `system` is already Extended; pass all terms in one tuple")
        if not isinstance(self.terms, tuple) or not all(isinstance(t, AbstractTerm) for t in self.terms):
            raise UsageError("Extended: `terms` must be a tuple of model extension terms (e.g. CoulombFriction)")
        labels = []
        for term in self.terms:
            # Each term knows what it acts on (a manipulator's joints, a vehicle's body axes, an input).
            try:
                term.check_system(self.system)
            except ValueError as e:
                raise UsageError(f"Extended: {e}") from None
            # `label` also checks the joint / input index; wind components share `wind@world`
            labels.append(f"{term.label(self.system)} ({term.parameter_name(self.system)})")
        duplicates = sorted({label for label in labels if labels.count(label) > 1})
        if duplicates:
            raise UsageError(f"Extended: the same term is given twice: {duplicates}")

    @property
    def state_names(self) -> tuple[str, ...]:
        inputs = tuple(n for t in self.input_terms for n in t.hidden_names(self.system))
        others = tuple(n for t in self.state_terms for n in t.hidden_names(self.system))
        return tuple(self.system.state_names) + inputs + others

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.system.input_names)

    def parameter_filter(self):
        """The nominal system's own filter, and each term's (`AbstractTerm.parameter_filter`: its coefficients)."""
        spec = jax.tree.map(eqx.is_inexact_array, self)
        spec = eqx.tree_at(lambda m: m.system, spec, self.system.parameter_filter())
        return eqx.tree_at(lambda m: m.terms, spec, tuple(t.parameter_filter() for t in self.terms))

    def state_error(self, simulated, measured):
        return self.system.state_error(simulated, measured)

    @property
    def position_indices(self) -> tuple[int, ...]:
        return self.system.position_indices

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        return self.system.velocity_indices

    @property
    def angle_indices(self) -> tuple[int, ...]:
        return self.system.angle_indices

    @property
    def joint_terms(self) -> tuple[AbstractJointTerm, ...]:
        return tuple(t for t in self.terms if isinstance(t, AbstractJointTerm))

    @property
    def state_terms(self) -> tuple[AbstractTerm, ...]:
        """The terms other than input terms that carry internal states (`AbstractTerm.hidden_names`), whose
        states follow the input terms' in the state, in this order."""
        return tuple(t for t in self.terms if not isinstance(t, AbstractInputTerm) and t.hidden_names(self.system))

    @property
    def vehicle_terms(self) -> tuple[AbstractVehicleTerm, ...]:
        return tuple(t for t in self.terms if isinstance(t, AbstractVehicleTerm))

    @property
    def input_terms(self) -> tuple[AbstractInputTerm, ...]:
        return tuple(t for t in self.terms if isinstance(t, AbstractInputTerm))

    @property
    def labels(self) -> tuple[str, ...]:
        """`cause@where` of each term, e.g. `("coulomb_friction@q2",)`."""
        return tuple(t.label(self.system) for t in self.terms)

    @property
    def parameters(self) -> dict[str, Array]:
        """The terms' coefficients by report name, e.g. `{"fc2": 0.21}`."""
        return {k: v for t in self.terms for k, v in t.parameters(self.system).items()}

    def applied_input(
        self, u: Float[Array, " n_inputs"], z: Float[Array, " n_hidden"]
    ) -> tuple[Float[Array, " n_inputs"], Float[Array, " n_hidden"]]:
        """The applied input and the internal states' derivative, from the recorded input and internal states."""
        a = jnp.asarray(u)
        dz, offset = [], 0
        for term in self.input_terms:
            for i in term.inputs:  # a term on several inputs has its internal states for each
                zi = z[offset : offset + term.n_hidden]
                offset += term.n_hidden
                ui = a[i]
                dz.append(term.hidden_derivative(ui, zi))
                a = a.at[i].set(term.applied(ui, zi))
        dz = jnp.concatenate(dz) if dz else z[:0]
        # The joint terms' states (after the input terms') do not move with the input alone.
        return a, jnp.concatenate([dz, jnp.zeros_like(z[offset:])])

    def with_shifted_inputs(
        self, us: Float[Array, "step n_inputs"], dt: Float[ArrayLike, ""]
    ) -> tuple["Extended", Float[Array, "step n_inputs"]]:
        """`(model, shifted)`: the recorded inputs `us` (zero-order hold, `dt` apart, any history first) with the
        input terms' shifts applied (a dead time's, `InputDelay.shift`: exact at any size, a fraction of a sample
        included), and the model without them in its ODE. The windowed rollouts of a record simulate this way. The
        shifts act on the recorded input ahead of the other input terms, which commute with them (a gain, an
        offset, a lag: time-invariant and linear in the input)."""
        for term in self.input_terms:
            us = term.shift(us, dt)
        terms = tuple(t.after_shift() if isinstance(t, AbstractInputTerm) else t for t in self.terms)
        return eqx.tree_at(lambda m: m.terms, self, terms), us

    def initial_state(
        self, x0: Float[ArrayLike, " n_measured"], u0: Float[ArrayLike, " n_inputs"]
    ) -> Float[Array, " n_states"]:
        """Complete the nominal state `x0` with internal states at rest under a constant input `u0`."""
        x0 = jnp.asarray(x0)
        a = jnp.asarray(u0, x0.dtype)
        hidden = []
        for term in self.input_terms:
            for i in term.inputs:
                ui = a[i]
                zi = term.steady_state(ui).astype(x0.dtype)
                hidden.append(zi)
                a = a.at[i].set(term.applied(ui, zi))
        for term in self.state_terms:
            hidden.append(term.initial_hidden(self.system, x0, a).astype(x0.dtype))
        return jnp.concatenate([x0, *hidden]) if hidden else x0

    def vector_field(self, t, x, u):
        n = self.system.n_states
        x_nominal, z = x[:n], x[n:]
        a, dz = self.applied_input(u, z)
        hidden = self._hidden_of_terms(z)
        # The terms that change the nominal dynamics (not just its input) say how, per kind.
        if self.vehicle_terms:
            dx = AbstractVehicleTerm.extended_vector_field(
                self.system,  # pyright: ignore[reportArgumentType] (a vehicle: the terms' `check_system` said so)
                self.vehicle_terms,
                x_nominal,
                a,
                self._of_kind(hidden, AbstractVehicleTerm),
            )
        elif self.joint_terms:
            dx = AbstractJointTerm.extended_vector_field(
                self.system, self.joint_terms, x_nominal, a, self._of_kind(hidden, AbstractJointTerm)
            )
        else:
            dx = self.system.vector_field(t, x_nominal, a)
        states = [(term, zt) for term, zt in zip(self.terms, hidden) if zt.shape[0]]
        if states:  # the other terms' states follow the input terms' (whose part `applied_input` gave)
            own = sum(zt.shape[0] for _, zt in states)
            moving = [term.hidden_vector_field(self.system, x_nominal, a, zt) for term, zt in states]
            dz = jnp.concatenate([dz[: dz.shape[0] - own], *moving])
        return jnp.concatenate([dx, dz])

    def _hidden_of_terms(self, z: Float[Array, " n_hidden"]) -> tuple[Float[Array, " _"], ...]:
        """Each term's internal states in `z`, in the order of `terms`: empty for an input term (the input chain reads
        its own, `applied_input`) and for a term without."""
        offset = z.shape[0] - sum(len(t.hidden_names(self.system)) for t in self.state_terms)
        hidden = []
        for term in self.terms:
            size = 0 if isinstance(term, AbstractInputTerm) else len(term.hidden_names(self.system))
            hidden.append(z[offset : offset + size])
            offset += size
        return tuple(hidden)

    def _of_kind(self, hidden, kind) -> tuple[Float[Array, " _"], ...]:
        return tuple(zt for term, zt in zip(self.terms, hidden) if isinstance(term, kind))
