r"""Output-error refinement of a least-squares estimate, over the physically consistent set.

Least squares on the inverse-dynamics model differentiates noisy velocities into $\ddot q$: noise
in the regressor biases the estimate (errors in variables). The output-error fit has no such bias;
it only needs a start near the answer, which least squares gives. `refine_by_simulation` takes the
least-squares model, adds the rotor inertia of the elbow motor (`RotorInertia(1)`: with the
contract's base parameters this is the whole of a geared motor's effect, diagonal and the
off-diagonal coupling $-g_r I_r$, see `dynax._identify._consistency`), and fits every parameter by
`fit_simulation_error` (Levenberg-Marquardt, optimistix) through a `ConsistentParametrisation`, so
every iterate is physically consistent.

The data it fits are the records cut to 40 samples per period of their signal band's edge
(`choose_filter`; inputs averaged over each new interval), so that the integrator takes as few
steps as the motion needs, with the measured encoder positions and velocities from a local cubic
fit of those positions: each segment starts from the measured position and a velocity about a
hundred times less noisy than the driver's estimate, without the amplitude loss of a low-pass filter
at the band's edge (which on a large-amplitude run distorts the very motion that is fitted). Each state's residual is divided by its measurement-noise level
(`measurement_noise_std`): maximum likelihood under white measurement noise, which lets the
precise encoder positions, not the noisy velocity estimate, decide.
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
from ._defaults import choose_filter, measurement_noise_std
from ._regressors import _split, parameter_vector, with_parameters
from ._simulation_fit import fit_simulation_error, SimulationFit


BALANCE = True
SAMPLES_PER_PERIOD = 40.0  # grid of the fit: samples per period of the signal band's edge


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
    `std_errors` (through the parametrisation's Jacobian, ignoring correlations: indicative), `initial_residual_rms` and `residual_rms` (scaled state residual at the start and
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


def _velocities_from_positions(xs: np.ndarray, dt: float, band_hz: float) -> np.ndarray:
    r"""The states with measured positions and velocities from a local cubic fit of the positions.

    Encoder positions are three orders of magnitude less noisy (relative to the motion) than a
    driver's velocity estimate; the derivative of a cubic Savitzky-Golay fit over a window of
    half a period of the band's edge passes the band (its -3 dB point lies near
    $4 f_s / (3.2 (2m + 1))$, about 3 times the band edge) and differentiates the position noise
    into a velocity noise $\sim \sigma_q / (m^{3/2} dt)$ (Schafer, "What is a Savitzky-Golay
    filter?", IEEE Signal Processing Magazine 28(4), 2011).
    """
    import scipy.signal

    n = xs.shape[1] // 2
    window = max(5, int(round(0.5 / (band_hz * dt))) | 1)
    window = min(window, (len(xs) - 1) | 1 if len(xs) % 2 == 0 else len(xs))
    out = xs.copy()
    out[:, n:] = scipy.signal.savgol_filter(xs[:, :n], window, 3, deriv=1, delta=dt, axis=0, mode="interp")
    return out


def motion_records(records: list[Trajectory], *, filtered: bool | str = "positions") -> tuple[list[Trajectory], float]:
    """The records on a grid of about 40 samples per period of their signal band's edge.

    Each record (resampled at its median interval if irregular) is cut to every `d`-th sample,
    `d` the integer nearest to that grid; its inputs become the mean over each block of `d`
    samples (the same impulse as the recorded zero-order hold, without aliasing the torque noise);
    its states are, with `filtered="positions"` (default), the measured positions and the
    velocities of a local cubic fit of them (`_velocities_from_positions`); with `True`, the
    states low-passed at their signal band (`choose_filter`); with `False`, as measured.

    **Returns:** `(records, dt)`.
    """
    uniform = [r if r.is_uniform else resample(r, r.dt) for r in records]
    choices = [choose_filter(r) for r in uniform]
    bands = [c.cutoff_hz for c in choices if c.cutoff_hz is not None]
    out, steps = [], []
    for record, choice in zip(uniform, choices):
        d = max(1, int(round(1.0 / (SAMPLES_PER_PERIOD * max(bands)) / record.dt))) if bands else 1
        xs, us = np.asarray(record.xs), np.asarray(record.us)
        if filtered == "positions" and choice.cutoff_hz is not None:
            xs = _velocities_from_positions(xs, record.dt, choice.cutoff_hz)
        elif filtered and choice.cutoff_hz is not None:
            xs = np.asarray(butterworth_filtfilt(record.ts, xs, cutoff_hz=choice.cutoff_hz, order=choice.order))
        n = (len(record) // d) * d
        us = us[:n].reshape(n // d, d, -1).mean(axis=1)
        out.append(Trajectory(jnp.asarray(np.asarray(record.ts)[:n:d]), jnp.asarray(xs[:n:d]), jnp.asarray(us),
                              record.state_names, record.input_names, record.system, record.source))
        steps.append(d * record.dt)
    return out, float(np.median(steps))


def refine_by_simulation(
    system: AbstractSystem, names: tuple[str, ...], records: list[Trajectory], method: SimulationFit,
    *, filtered: bool | str = "positions",
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
    fitted, dt = motion_records(records, filtered=filtered)
    # Maximum likelihood under white measurement noise: each state weighted by its noise level.
    noise = np.median(np.stack([measurement_noise_std(r if r.is_uniform else resample(r, r.dt)) for r in records]), axis=0)
    # Each record counts alike, whatever its amplitude: a large-amplitude (chaotic) run must not swamp the rest.
    motion = np.array([float(np.sqrt(np.mean(np.square(np.asarray(r.xs[:, :2]) - np.mean(np.asarray(r.xs[:, :2]), 0)))))
                       for r in fitted])
    weights = (1.0 / motion) / np.mean(1.0 / motion) if BALANCE else None
    result = fit_simulation_error(
        wrapped, fitted, filter_spec=filter_spec, state_scale=jnp.asarray(noise), record_weights=weights, segment_s=method.segment_s,
        fit_initial_states=method.fit_initial_states, continuity_weight=method.continuity_weight,
        rtol=method.rtol, atol=method.atol, max_steps=method.max_steps, simulation=method.simulation,
    )
    refined = result.system.model
    estimate = np.asarray(parameter_vector(refined, friction))
    # Standard errors through the parametrisation's Jacobian (delta method).
    jac = np.asarray(jax.jacfwd(parametrisation.theta)(result.system.phi))
    phi_std = np.asarray(result.std_errors)
    with np.errstate(invalid="ignore"):  # an unidentified direction has an infinite standard error
        std = np.sqrt(np.sum((jac * phi_std[None, :]) ** 2, axis=1))
    return Refinement(refined, names, estimate, std, float(result.initial_residual_rms), float(result.residual_rms),
                      float(result.relative_error), int(result.steps), dt, method.segment_s, result.n_samples)
