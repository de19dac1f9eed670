r"""Output-error refinement of a least-squares estimate, over the physically consistent set.

Least squares on the inverse-dynamics model differentiates noisy velocities into $\ddot q$: noise
in the regressor biases the estimate (errors in variables). The output-error fit has no such bias;
it only needs a start near the answer, which least squares gives. `refine_by_simulation` takes the
least-squares model, adds the rotor inertia of the elbow motor (`RotorInertia(1)`: with the
contract's base parameters this is the whole of a geared motor's effect, diagonal and the
off-diagonal coupling $-g_r I_r$, see `dynax._identify._consistency`), and fits every parameter by
`fit_simulation_error` (Levenberg-Marquardt, optimistix) through a `ConsistentParametrisation`, so
every iterate is physically consistent.

The data it fits are the records low-passed at their signal band (`choose_filter`) and resampled
to 20 samples per period of that band: the simulation is compared with the motion, not with the
velocity estimate's noise, and the integrator takes as few steps as the motion needs.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import butterworth_filtfilt, resample
from .._data._trajectory import Trajectory
from .._model._extensions import Extended, RotorInertia
from .._model._system import AbstractSystem
from .._model._two_link import AbstractTwoLink
from ._consistency import consistent_parametrisation, ConsistentParametrisation
from ._defaults import choose_filter
from ._regressors import _split, parameter_vector, with_parameters
from ._simulation_fit import fit_simulation_error, SimulationFit


class ConsistentSystem(AbstractSystem):
    r"""A system whose parameters are a point $\phi$ of a `ConsistentParametrisation`.

    Its only inexact leaf is `phi`; `model` is the system it stands for, with
    $\theta = \theta(\phi)$ in the parameters `names`. Fitting `phi` (e.g. with
    `fit_simulation_error`) searches the consistent set only.
    """

    phi: jax.Array
    template: AbstractSystem
    parametrisation: ConsistentParametrisation
    names: tuple[str, ...] = eqx.field(static=True)

    @property
    def state_names(self):
        return self.template.state_names

    @property
    def input_names(self):
        return self.template.input_names

    @property
    def model(self) -> AbstractSystem:
        return with_parameters(self.template, self.names, self.parametrisation.theta(self.phi))

    def vector_field(self, t, x, u):
        return self.model.vector_field(t, x, u)


def with_elbow_rotor(system: AbstractSystem) -> AbstractSystem:
    """`system` with `RotorInertia(joint=1)` (coefficient 0) if it has none."""
    base, terms = _split(system)
    if any(isinstance(t, RotorInertia) and t.joint == 1 for t in terms):
        return system
    dtype = jnp.result_type(base.theta1)
    return Extended(base, terms + (RotorInertia(1, jnp.zeros((), dtype)),))


@dataclasses.dataclass(frozen=True)
class Refinement:
    """What `refine_by_simulation` did. Fields: `system` (refined), `names`, `estimate`,
    `std_errors`, `initial_residual_rms` and `residual_rms` (scaled state residual at the start and
    at the end), `steps`, `dt` and `segment_s` (the grid and segment length fitted)."""

    system: AbstractSystem
    names: tuple[str, ...]
    estimate: np.ndarray
    std_errors: np.ndarray
    initial_residual_rms: float
    residual_rms: float
    relative_error: float
    steps: int
    dt: float
    segment_s: float
    n_samples: int


def motion_records(records: list[Trajectory]) -> tuple[list[Trajectory], float]:
    """The records low-passed at their signal band and resampled to 20 samples per period of it.

    **Returns:** `(records, dt)`; records without detectable noise are only resampled.
    """
    choices = [choose_filter(r if r.is_uniform else resample(r, r.dt)) for r in records]
    bands = [c.cutoff_hz for c in choices if c.cutoff_hz is not None]
    finest = min(r.dt for r in records)
    dt = max(finest, 1.0 / (20.0 * max(bands))) if bands else finest
    out = []
    for record, choice in zip(records, choices):
        uniform = record if record.is_uniform else resample(record, record.dt)
        if choice.cutoff_hz is not None:
            xs = butterworth_filtfilt(uniform.ts, uniform.xs, cutoff_hz=choice.cutoff_hz, order=choice.order)
            uniform = Trajectory(uniform.ts, xs, uniform.us, uniform.state_names, uniform.input_names,
                                 uniform.system, uniform.source)
        out.append(resample(uniform, dt) if dt > uniform.dt * 1.01 else uniform)
    return out, dt


def refine_by_simulation(
    system: AbstractSystem, names: tuple[str, ...], records: list[Trajectory], method: SimulationFit
) -> Refinement:
    """Refine a two-link arm's least-squares model by the output-error fit, consistent by construction.

    **Arguments:** `system` (the least-squares model, carrying its estimate; rotor inertia at the
    elbow is added if missing), `names` its parameter names, `records` to fit, `method` the
    `SimulationFit` settings (segment length, steps).

    **Returns:** a `Refinement`.
    """
    if not isinstance(_split(system)[0], AbstractTwoLink):
        raise TypeError("refine_by_simulation refines two-link arms")
    model = with_elbow_rotor(system)
    friction = "coulomb" if any(n.startswith("fc") for n in names) else "viscous"
    from ._regressors import parameter_names

    names = parameter_names(model, friction)
    start = parameter_vector(model, friction)
    scale = jnp.maximum(jnp.abs(start), 1e-3 * jnp.max(jnp.abs(start[:5])))
    parametrisation = consistent_parametrisation(model, names, scale)
    wrapped = ConsistentSystem(parametrisation.phi(start), model, parametrisation, names)
    filter_spec = jax.tree.map(lambda _: False, wrapped)
    filter_spec = eqx.tree_at(lambda s: s.phi, filter_spec, True)
    fitted, dt = motion_records(records)
    result = fit_simulation_error(
        wrapped, fitted, filter_spec=filter_spec, segment_s=method.segment_s,
        fit_initial_states=method.fit_initial_states, continuity_weight=method.continuity_weight,
        rtol=method.rtol, atol=method.atol, max_steps=method.max_steps, simulation=method.simulation,
    )
    refined = result.system.model
    estimate = np.asarray(parameter_vector(refined, friction))
    # Standard errors through the parametrisation's Jacobian (delta method).
    jac = np.asarray(jax.jacfwd(parametrisation.theta)(result.system.phi))
    phi_std = np.asarray(result.std_errors)
    std = np.sqrt(np.sum((jac * phi_std[None, :]) ** 2, axis=1))
    return Refinement(refined, names, estimate, std, float(result.initial_residual_rms), float(result.residual_rms),
                      float(result.relative_error), int(result.steps), dt, method.segment_s, result.n_samples)
