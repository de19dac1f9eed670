r"""The frequency-domain criterion (CIFER-style) for the linear velocity model.

1. **Frequency responses** from the data: Welch auto- and cross-spectra of the four inputs and the
   six body velocities and rates, the multi-input estimate $\hat H(f) = (G_{uu}^{-1} G_{uy})^\top$
   (which removes the correlation between inputs that a feedback controller creates), and for each
   input/output pair the *partial coherence* $\gamma^2_{ij}$ (from the inverse of the augmented
   spectral matrix of $(u, y_j)$).
2. **The model's responses**: the linear velocity model is linearised about level flight as the
   8-state LTI system $(\nu, \omega, \phi_r, \theta_p)$ with $\dot\phi_r = p$, $\dot\theta_p = q$, so
   $H_m(j\omega) = C(j\omega I - A)^{-1}B$.
3. **The fit**: minimise the coherence-weighted magnitude (dB) and phase (deg) error over the
   identified band, over the pairs and frequencies with $\gamma^2 \ge$ `min_coherence` whose
   magnitude is within 30 dB of the largest response of that output,

   $$J = \sum W_\gamma\big[(20\log_{10}|\hat H| - 20\log_{10}|H_m|)^2 + W_p(\angle\hat H - \angle H_m)^2\big],
   \quad W_\gamma = \big(1.58(1 - e^{-\gamma^2})\big)^2,\ W_p = 0.01745,$$

   by Levenberg-Marquardt (optimistix), started from the frequency-domain *equation-error* fit
   $j\omega \hat H = A\hat H + B e^{-j\omega\Delta t/2}$ (linear least squares, same weights). The
   model includes the half-sample delay of the zero-order hold. A weak prior toward the one-step
   weights holds the terms that the responses do not determine. The constant column, which has no
   frequency response, is then re-fitted by one-step least squares with the rest held.
4. **Accuracy** (CIFER's): each weight's Cramer-Rao bound $\sqrt{\hat\sigma^2 (J^\top J)^{-1}_{ii}}$
   and insensitivity $\hat\sigma / \sqrt{(J^\top J)_{ii}}$, in % of the weight, from the Jacobian $J$ of
   the weighted response residuals and their variance $\hat\sigma^2$ (`VehicleStatistics.accuracy`).
   With `eliminate=True`, weights beyond 10 % insensitivity or 20 % bound are dropped one at a
   time and the rest refitted (the model-structure reduction of Tischler and Remple, 2012).

??? cite "References"

    M. B. Tischler and R. K. Remple, *Aircraft and Rotorcraft System Identification: Engineering
    Methods with Flight-Test Examples*, 2nd ed., AIAA, 2012 (CIFER: the cost function, its weights
    and the coherence criterion).

    B. Mettler, M. B. Tischler and T. Kanade, "System identification modeling of a small-scale
    unmanned rotorcraft for flight control design", Journal of the American Helicopter Society
    47(1), 2002.
"""

import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._data._trajectory import Trajectory
from ..._errors import UsageError
from ..._fit import fit_least_squares, LeastSquaresOptions, levenberg_marquardt, Solution
from ..._model._helicopter import BODY, BODY_AXES, Helicopter, HELICOPTER_INPUT_NAMES, LINEAR_FEATURE_NAMES
from .._method import FitSettings
from ._criteria import (
    AbstractVehicleCriterion,
    fit_one_step,
    in_system,
    normal_equations,
    one_record,
    one_shot_history,
    ridge_solve,
    vehicle_solution,
    VehicleStatistics,
    with_theta,
)
from ._windows import check_helicopter_data, valid_starts

#: The derivatives of a hover model that frequency responses identify (Mettler, Tischler and
#: Kanade 2002 use this kind of structure): on-axis damping, attitude (gravity) and rotor-tilt
#: couplings, speed stability, weathercock stability and the control derivatives.
HOVER_DERIVATIVES = {
    "u": ("u", "q", "pitch", "u2"),
    "v": ("v", "p", "roll", "u1", "u3"),
    "w": ("w", "u4"),
    "p": ("p", "v", "u1", "u3"),
    "q": ("q", "u", "u2"),
    "r": ("r", "v", "u3", "u4"),
}


class FrequencyDomain(AbstractVehicleCriterion):
    """The CIFER-style frequency-domain criterion (linear velocity model only).

    **Fields:**

    - `band_hz`: the identified band `(low, high)` [Hz] (default 0.2 to 8 Hz).
    - `segment_s`: the Welch segment length [s] (default 10 s; 50 % overlap, Hann window; shortened
      to an eighth of the record when the record is short).
    - `min_coherence`: pairs and frequencies with a lower partial coherence are left out (0.6).
    - `max_steps`: Levenberg-Marquardt iterations (default 30; 0 keeps the equation-error fit).
    - `structure`: per body axis, the weights fitted (default `HOVER_DERIVATIVES`: the on-axis
      damping, the gravity and rotor-tilt couplings and the control derivatives of a hover
      model); the other weights of the linear model are zero, as in a CIFER hover model.
    - `start`: the starting point of the output-error fit, `"one-step"` (default) or
      `"equation-error"` (the frequency-domain equation-error fit, which is fast but biased by the
      collinear responses of closed-loop data).
    - `prior_weight`: weight of a prior pulling each weight toward its one-step value, relative to
      its magnitude (default 0.1). Closed-loop responses determine the on-axis dynamics well and
      many off-axis terms hardly at all; the prior holds the latter (whose free drift otherwise
      yields unstable models) and is negligible where the data speak.
    - `eliminate`: CIFER's model-structure reduction (default `False`): after each fit, compute every
      weight's Cramer-Rao bound and insensitivity (relative to the weight); while some weight is
      more insensitive than `max_insensitivity` (10 %), drop the most insensitive one, otherwise
      while some bound is wider than `max_cramer_rao` (20 %), drop the one with the widest bound;
      refit; repeat. Dropped weights are zero (`VehicleStatistics.eliminated`); the final bounds are in
      `VehicleStatistics.accuracy`. These are the guidelines of Tischler and Remple (2012) for a model
      whose weights the responses determine.
    """

    band_hz: tuple[float, float] = eqx.field(static=True, default=(0.1, 2.5))
    segment_s: float = eqx.field(static=True, default=10.0)
    min_coherence: float = eqx.field(static=True, default=0.6)
    max_steps: int = eqx.field(static=True, default=30)
    prior_weight: float = 0.1
    start: str = eqx.field(static=True, default="equation-error")
    structure: dict = eqx.field(static=True, default_factory=lambda: dict(HOVER_DERIVATIVES))
    eliminate: bool = eqx.field(static=True, default=False)
    max_cramer_rao: float = 0.2
    max_insensitivity: float = 0.1

    @property
    def label(self) -> str:
        return "frequency"

    def fit(self, system, records, settings: FitSettings = FitSettings()) -> Solution:
        """`fit_frequency` of `system` on one continuous record (no `settings.breaks`); a vehicle
        whose inputs are not the helicopter's `u1..u4` (a quadrotor) is refused."""
        if tuple(system.input_names) != HELICOPTER_INPUT_NAMES:
            raise UsageError(
                "the frequency-domain criterion identifies the helicopter's linear model (its structure and "
                "frequency responses are written in the helicopter's inputs u1..u4); for a "
                f"{type(system).__name__.lower()} use OneStep, Lagged or Backprop"
            )
        if settings.breaks is not None and len(settings.breaks):
            raise UsageError("fit_vehicle: the frequency criterion needs one continuous record, not joined ones")
        return in_system(system, fit_frequency(system.as_helicopter(), one_record(records, "FrequencyDomain"), self))


def frequency_responses(trajectory: Trajectory, segment_s: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Multi-input frequency responses and partial coherences of the body states to the inputs.

    **Returns:** `(freqs (f,), H (f, 6, 4) complex, coherence (f, 6, 4))`.
    """
    dt = check_helicopter_data(trajectory, "frequency_responses")
    u = np.asarray(trajectory.us, float)
    y = np.asarray(trajectory.xs[:, BODY], float)
    # At least ~15 averaged segments (50 % overlap), or the 4x4 input spectra are singular.
    nperseg = max(16, min(int(round(segment_s / dt)), len(u) // 8))
    z = np.concatenate([u, y], axis=1)
    n = z.shape[1]
    spectra = None
    for a in range(n):
        for b in range(n):
            import scipy.signal  # lazily: keeps `import dynax` light

            f, g = scipy.signal.csd(z[:, a], z[:, b], fs=1 / dt, nperseg=nperseg, detrend="linear")
            if spectra is None:
                spectra = np.zeros((len(f), n, n), complex)
            spectra[:, a, b] = g
    guu, guy = spectra[:, :4, :4], spectra[:, :4, 4:]
    responses = np.transpose(np.linalg.pinv(guu) @ guy, (0, 2, 1))  # y = H u
    coherence = np.zeros((len(f), 6, 4))
    for j in range(6):
        idx = [0, 1, 2, 3, 4 + j]
        inverse = np.linalg.pinv(spectra[:, idx][:, :, idx])
        for i in range(4):
            coherence[:, j, i] = np.abs(inverse[:, i, 4]) ** 2 / np.real(inverse[:, i, i] * inverse[:, 4, 4])
    return f, responses, np.clip(coherence, 0.0, 1.0)


def _model_response(weights, omegas, delay=0.0):
    r"""$C(j\omega I - A)^{-1}B e^{-j\omega\tau}$ of the linear velocity model linearised about level flight.

    `delay` $\tau$ is the half-sample delay of the zero-order hold, $\Delta t / 2$.
    """
    names = LINEAR_FEATURE_NAMES
    idx = lambda *ns: [names.index(n) for n in ns]  # noqa: E731
    top = jnp.concatenate([weights[:, idx("u", "v", "w", "p", "q", "r")], weights[:, idx("roll", "pitch")]], axis=1)
    kinematics = jnp.zeros((2, 8), weights.dtype).at[0, 3].set(1.0).at[1, 4].set(1.0)
    a = jnp.concatenate([top, kinematics])
    b = jnp.concatenate([weights[:, idx("u1", "u2", "u3", "u4")], jnp.zeros((2, 4), weights.dtype)])

    def at(w):
        return jnp.linalg.solve(1j * w * jnp.eye(8) - a, b.astype(complex))[:6] * jnp.exp(-1j * w * delay)

    return jax.vmap(at)(omegas)


def _equation_error(weights, freqs, measured, w_gamma, dt, prior_weight, structure_mask):
    r"""Frequency-domain equation error: $j\omega H = A_s H + A_\theta H_\theta + B e^{-j\omega\tau}$,
    linear least squares per output row, weighted by the coherence weights (the starting point)."""
    names = LINEAR_FEATURE_NAMES
    state_cols = [names.index(n) for n in ("u", "v", "w", "p", "q", "r", "roll", "pitch")]
    input_cols = [names.index(n) for n in ("u1", "u2", "u3", "u4")]
    jw = 2j * np.pi * freqs
    n_f = len(freqs)
    # Regressors per (frequency, input): the 6 responses, roll/pitch responses p/(jw), q/(jw), the inputs.
    hs = measured  # (f, 6, 4)
    attitude = np.stack([hs[:, 3, :] / jw[:, None], hs[:, 4, :] / jw[:, None]], axis=1)  # (f, 2, 4)
    delay = np.exp(-jw * dt / 2)[:, None, None] * np.broadcast_to(np.eye(4), (n_f, 4, 4))  # (f, 4 inputs, 4)
    regressors = np.concatenate([hs, attitude, delay], axis=1)  # (f, 12, 4)
    x = np.transpose(regressors, (0, 2, 1)).reshape(-1, 12)  # rows: (f, input)
    new = np.asarray(weights, float).copy()
    fixed = new.copy()
    for row in range(6):
        free_cols = [c for c in state_cols + input_cols if structure_mask[row, c]]
        if not free_cols:
            continue
        held_cols = [c for c in state_cols + input_cols if not structure_mask[row, c]]
        held = (
            x[:, [(state_cols + input_cols).index(c) for c in held_cols]] @ fixed[row, held_cols] if held_cols else 0.0
        )
        target = (jw[:, None] * hs[:, row, :]).reshape(-1) - held
        w = np.sqrt(w_gamma[:, row, :].reshape(-1))
        if not np.any(w > 0):
            continue
        xf = x[:, [(state_cols + input_cols).index(c) for c in free_cols]]
        a = np.concatenate([(w[:, None] * xf).real, (w[:, None] * xf).imag])
        b = np.concatenate([(w * target).real, (w * target).imag])
        # The same prior as the output-error cost, scaled to these equations: a ridge toward the
        # one-step weights that holds the terms the responses do not determine.
        centre = new[row, free_cols]
        ridge = prior_weight * np.sqrt(np.trace(a.T @ a) / a.shape[1]) / np.maximum(np.abs(centre), 1.0)
        a = np.concatenate([a, np.diag(ridge)])
        b = np.concatenate([b, ridge * centre])
        coef, *_ = np.linalg.lstsq(a, b, rcond=1e-10)
        new[row, free_cols] = coef
    return jnp.asarray(new, weights.dtype)


def _accuracy(residuals: np.ndarray, jacobian: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""CIFER's accuracy measures of weights `theta` [% of each weight]: the Cramer-Rao bound
    $\sqrt{\hat\sigma^2 (J^\top J)^{-1}_{ii}}$ and the insensitivity $\hat\sigma/\sqrt{(J^\top J)_{ii}}$, with
    $\hat\sigma^2$ the residual variance. A weight the residuals do not depend on gets infinite ones."""
    dof = max(1, residuals.size - theta.size)
    sigma2 = float(residuals @ residuals) / dof
    info = jacobian.T @ jacobian
    diag = np.diag(info)
    seen = diag > 1e-12 * max(float(diag.max(initial=0.0)), 1e-300)
    variance = np.full(len(diag), np.inf)
    variance[seen] = np.abs(np.diag(np.linalg.pinv(info[np.ix_(seen, seen)])))
    with np.errstate(divide="ignore", invalid="ignore"):
        magnitude = np.abs(theta)
        cramer_rao = np.nan_to_num(100 * np.sqrt(sigma2 * variance) / magnitude, nan=np.inf)
        insensitivity = np.nan_to_num(100 * np.sqrt(sigma2 / diag) / magnitude, nan=np.inf)
    return cramer_rao, insensitivity


def _elimination_order(cramer_rao, insensitivity, criterion: "FrequencyDomain") -> np.ndarray:
    """Candidates to drop, worst first: the insensitive weights while there are any, else those
    whose Cramer-Rao bound is too wide (Tischler and Remple 2012); empty when all pass."""
    for measure, limit in ((insensitivity, criterion.max_insensitivity), (cramer_rao, criterion.max_cramer_rao)):
        failing = np.nonzero(measure > 100 * limit)[0]
        if failing.size:
            return failing[np.argsort(-measure[failing])]
    return np.zeros(0, int)


def _check(system: Helicopter, criterion: "FrequencyDomain", trajectory: Trajectory) -> None:
    if system.body_model.kind != "linear" or system.body_model.feature_names != LINEAR_FEATURE_NAMES:
        raise UsageError("fit_frequency: the frequency-domain criterion fits the linear model only (--model linear)")
    check_helicopter_data(trajectory, "fit_frequency")
    if not (criterion.max_cramer_rao > 0 and criterion.max_insensitivity > 0):
        raise UsageError(
            f"fit_frequency: max_cramer_rao and max_insensitivity must be positive fractions, got "
            f"{criterion.max_cramer_rao} and {criterion.max_insensitivity}"
        )


@dataclasses.dataclass(frozen=True)
class _Responses:
    """The measured responses in the criterion's band, and which (frequency, output, input) to fit."""

    freqs: np.ndarray  # (f,) [Hz]
    measured: np.ndarray  # (f, 6 outputs, 4 inputs), complex
    coherence: np.ndarray  # (f, 6, 4)
    use: np.ndarray  # (f, 6, 4) bool: coherent and within 30 dB of the output's largest response
    w_gamma: np.ndarray  # (f, 6, 4): CIFER's coherence weights where used, else 0


def _band_responses(trajectory: Trajectory, criterion: "FrequencyDomain") -> _Responses:
    freqs, measured, coherence = frequency_responses(trajectory, criterion.segment_s)
    low, high = criterion.band_hz
    band = (freqs >= low) & (freqs <= high)
    if band.sum() < 3:
        raise UsageError(f"fit_frequency: fewer than 3 frequencies in the band {criterion.band_hz} Hz; use longer data")
    freqs, measured, coherence = freqs[band], measured[band], coherence[band]
    # Pairs with good partial coherence and a response within 30 dB of the output's largest one:
    # off-axis responses that are (nearly) absent carry no information and their dB error is noise.
    magnitude_db = 20 * np.log10(np.abs(measured) + 1e-300)
    use = (coherence >= criterion.min_coherence) & (magnitude_db >= magnitude_db.max(axis=2, keepdims=True) - 30.0)
    if not use.any():
        raise UsageError(
            "fit_frequency: no input/output pair reaches the coherence threshold; the data lack excitation"
        )
    w_gamma = np.where(use, (1.58 * (1 - np.exp(-coherence))) ** 2, 0.0)
    return _Responses(freqs, measured, coherence, use, w_gamma)


def _hover_structure(initial: Helicopter, criterion: "FrequencyDomain"):
    """`(model, mask)`: the one-step model reduced to the hover-derivative structure (the other weights
    zero, the constant column kept for its re-fit at the end), and the mask of the weights to fit."""
    mask = np.array(
        [[name in criterion.structure.get(axis, ()) for name in LINEAR_FEATURE_NAMES] for axis in BODY_AXES]
    )
    mask &= np.array(initial.body_model.mask, bool)
    keep = mask.copy()
    keep[:, LINEAR_FEATURE_NAMES.index("1")] = True
    weights = jnp.where(jnp.asarray(keep), initial.body_model.weights, 0.0)
    return eqx.tree_at(lambda h: h.body_model.weights, initial, weights), mask


def _response_residuals(initial: Helicopter, free, responses: _Responses, delay: float, dtype):
    """`theta, active -> residuals`: weighted magnitude [dB] and phase [deg] errors of the model's
    responses against the measured ones (eliminated weights, `active` 0, are zero)."""
    omegas = jnp.asarray(2 * np.pi * responses.freqs, dtype)
    sqrt_wg = jnp.asarray(np.sqrt(responses.w_gamma), dtype)
    measured = jnp.asarray(np.where(responses.use, responses.measured, 1.0))
    use = jnp.asarray(responses.use)

    def residuals(theta, active):
        weights = initial.body_model.weights.at[free].set(theta * active)
        model = _model_response(weights, omegas, delay)
        ratio = measured / jnp.where(use, model, 1.0)  # unused pairs (weight 0) may have no response
        magnitude = 20 * jnp.log10(jnp.abs(ratio))
        phase = jnp.degrees(jnp.angle(ratio))
        return jnp.concatenate([(sqrt_wg * magnitude).ravel(), (sqrt_wg * jnp.sqrt(0.01745) * phase).ravel()])

    return residuals


def _droppable(theta, active, cramer_rao, insensitivity, response_residuals, criterion):
    """The weight CIFER's structure reduction drops next (the worst that fails a limit), or `None`.
    A weight whose removal would leave a fitted (coherent) response with no path is kept."""
    for worst in _elimination_order(cramer_rao, insensitivity, criterion):
        index = np.nonzero(active)[0][worst]
        trial = active.copy()
        trial[index] = False
        if np.all(np.isfinite(np.asarray(response_residuals(theta, jnp.asarray(trial, theta.dtype))))):
            return index
    return None


def _reduce_structure(theta, response_residuals, residuals, responses: _Responses, free_names, criterion):
    """Fit (Levenberg-Marquardt), judge every weight's accuracy, drop the worst, refit, until all pass.

    **Returns:** `(theta, active, cramer_rao, insensitivity, eliminated, cost)`, with the accuracies
    of the weights kept and the final cost per used response."""
    n_free = len(free_names)
    active = np.ones(n_free, bool)
    cost_jit = jax.jit(lambda th, act: jnp.sum(residuals(th, act) ** 2))
    jacobian = jax.jit(jax.jacfwd(response_residuals))
    # The rows that carry data: magnitude and phase at every used (frequency, pair).
    rows = np.concatenate([responses.use.ravel(), responses.use.ravel()])

    def cost(theta):
        return float(cost_jit(theta, jnp.asarray(active, theta.dtype))) / max(1, int(responses.use.sum()))

    solver = levenberg_marquardt(rtol=1e-6, atol=1e-8)
    eliminated = []
    for _ in range(n_free + 1):  # the last pass only re-checks (at most n_free eliminations)
        act = jnp.asarray(active, theta.dtype)
        if criterion.max_steps > 0:
            solution = fit_least_squares(
                residuals,
                theta,
                True,
                act,
                solver=solver,
                scale=jnp.ones_like(theta),
                max_steps=criterion.max_steps,
                options=LeastSquaresOptions(nonfinite=None, covariance=False),
            )
            if np.all(np.isfinite(solution.value)) and cost(solution.value) < cost(theta):
                theta = solution.value
        cramer_rao, insensitivity = _accuracy(
            np.asarray(response_residuals(theta, act))[rows],
            np.asarray(jacobian(theta, act))[np.ix_(rows, active)],
            np.asarray(theta)[active],
        )
        dropped = (
            _droppable(theta, active, cramer_rao, insensitivity, response_residuals, criterion)
            if criterion.eliminate
            else None
        )
        if dropped is None:
            break
        active[dropped] = False
        eliminated.append(free_names[dropped])
        theta = theta.at[dropped].set(0.0)
    theta = theta * jnp.asarray(active, theta.dtype)
    return theta, active, cramer_rao, insensitivity, eliminated, cost(theta)


def _refit_constants(fitted: Helicopter, trajectory: Trajectory) -> Helicopter:
    """The constant column (no frequency response) re-fitted by one-step least squares, the rest held."""
    starts = jnp.asarray(valid_starts(len(trajectory), 1))
    ata, atb, _ = normal_equations(fitted, trajectory, starts, 1, jnp.ones(6, trajectory.xs.dtype), False, 1024)
    theta = fitted.body_model.parameter_vector()
    bias = np.array([n.endswith("/1") for n in fitted.body_model.parameter_names])
    rest = ~bias
    rhs = atb[bias] - ata[np.ix_(bias, rest)] @ theta[rest]
    theta = theta.at[np.nonzero(bias)[0]].set(ridge_solve(ata[np.ix_(bias, bias)], rhs, 1e-12))
    return with_theta(fitted, theta)


def fit_frequency(
    system: Helicopter, trajectory: Trajectory, criterion: FrequencyDomain = FrequencyDomain()
) -> Solution:
    """Fit a linear velocity model by the frequency-domain criterion (see the module docstring).

    The steps: the one-step fit as the start, reduced to the hover-derivative structure; the
    measured responses in the band; an equation-error start (optional); the output-error fit with
    CIFER's structure reduction; the constant column re-fitted in the time domain.
    """
    _check(system, criterion, trajectory)
    t0 = time.perf_counter()
    initial, mask = _hover_structure(fit_one_step(system, trajectory).model, criterion)
    responses = _band_responses(trajectory, criterion)
    dt = float(trajectory.ts[1] - trajectory.ts[0])
    free = np.nonzero(mask)
    free_names = [f"d{BODY_AXES[i]}/{LINEAR_FEATURE_NAMES[j]}" for i, j in zip(*free)]
    response_residuals = _response_residuals(initial, free, responses, 0.5 * dt, trajectory.xs.dtype)
    prior_centre = initial.body_model.weights[free]
    prior_scale = jnp.maximum(jnp.abs(prior_centre), 1.0) / criterion.prior_weight

    def residuals(theta, active):
        return jnp.concatenate([response_residuals(theta, active), (theta - prior_centre) / prior_scale])

    start = initial.body_model.weights
    if criterion.start == "equation-error":
        coherent = responses.coherence >= criterion.min_coherence
        w_equation = np.where(coherent, (1.58 * (1 - np.exp(-responses.coherence))) ** 2, 0.0)
        start = _equation_error(
            start, responses.freqs, responses.measured, w_equation, dt, criterion.prior_weight, mask
        )
    theta, active, cramer_rao, insensitivity, eliminated, final_cost = _reduce_structure(
        start[free], response_residuals, residuals, responses, free_names, criterion
    )
    kept = [n for n, a in zip(free_names, active) if a]
    summary = tuple(
        (n, float(v), float(c), float(i))
        for n, v, c, i in zip(kept, np.asarray(theta)[active], cramer_rao, insensitivity)
    )
    fitted = eqx.tree_at(lambda h: h.body_model.weights, initial, initial.body_model.weights.at[free].set(theta))
    losses, seconds = one_shot_history(final_cost, time.perf_counter() - t0)
    statistics = VehicleStatistics("frequency", len(trajectory), accuracy=summary, eliminated=tuple(eliminated))
    return vehicle_solution(system, _refit_constants(fitted, trajectory), losses, seconds, statistics)
