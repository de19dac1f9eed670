r"""Output-error screening of candidates: the first Gauss-Newton step of each candidate's refit.

The equation-error screening (`dynax._diagnose._screening`) ranks candidates by how much they reduce
the one-step acceleration residuals. Where those residuals are dominated by noise (a gyro's
derivative on a real flight) or a term acts by accumulating (a rate damping changes the attitude
over tenths of a second far more than any one acceleration sample), that ranking can leave the
candidate the simulation most needs off the shortlist, and no refit ever tries it.

This screening looks where the refit looks. Around the current model, the simulated states on the
training windows change with the refitted parameters $\theta$ (the nominal parameters refitted
and the coefficients already selected) and a candidate's coefficient $c$ by
$J_\theta\,\Delta\theta + j_c\,\Delta c$ to first order (forward-mode sensitivities of the window
rollouts, the same rollouts and scaling as `dynax._diagnose._fit`). Solving
$\min \lVert r + J_\theta\Delta\theta + j_c\Delta c\rVert$ on the training windows is the first
Gauss-Newton step of the candidate's simulation-error refit; its held-out gain is the fraction by
which that step reduces the held-out windows' sum of squares beyond the step of $\theta$ alone.

An input's dynamics (a delay, a lag) has no first-order sensitivity at its neutral value, and a term
not `smooth_at_neutral` (a static level) none that shows it; they keep their finite-size
equation-error screening and are not ranked here. A term with states of its own is ranked as any.

??? cite

    L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, sections 7.3 and 10.2
    (output-error criteria and their Gauss-Newton minimisation); S. Chen, S. A. Billings and W. Luo,
    "Orthogonal least squares methods and their application to non-linear system identification",
    International Journal of Control 50(5), 1989 (ranking candidate terms by the error they remove).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._fit import Family, window_errors, Windows
from ._residuals import input_dynamics

# Windows per compiled call: every call has this shape (the last chunk padded with left-out windows), so the
# training and held-out windows of one fit-window length share one compilation across all rounds.
CHUNK = 32


@eqx.filter_jit
def _jacobian(family: Family, windows: Windows, slots, p, tangents_p, tangents_c):
    """Scaled window residuals `(window * step * state,)` at `p` and their derivatives along each row of
    `(tangents_p, tangents_c)`: directions in the parameters `p` (the nominal parameters and the slots'
    coefficients) and in the candidates' coefficients."""
    n_nominal = len(family.names)

    def residuals(p_, c_):
        model = family.build(p_[:n_nominal], family.coefficients(slots, jnp.asarray(-1), p_) + c_)
        e = window_errors(model, windows)[:, 1:]
        e = e / jnp.broadcast_to(family.state_scale, e.shape)
        return jnp.where(windows.weights[:, None, None] > 0, e, 0.0).reshape(-1)

    zeros = jnp.zeros(family.n_candidates, p.dtype)
    # The residuals are the primal of the same forward-mode rollout (not batched over the directions): a separate
    # rollout for them would be a second loop in the program, compiled on its own.
    derivative = lambda tp, tc: jax.jvp(residuals, (p, zeros), (tp, tc))  # noqa: E731
    return jax.vmap(derivative, out_axes=(None, 0))(tangents_p, tangents_c)


def _chunks(windows: Windows):
    """`windows` in chunks of `CHUNK`, the last padded with copies of the first at weight zero."""
    n = windows.ts.shape[0]
    pad = (-n) % CHUNK
    index = np.concatenate([np.arange(n), np.zeros(pad, int)])
    weight = np.concatenate([np.ones(n), np.zeros(pad)])
    for lo in range(0, n + pad, CHUNK):
        # Gathered and weighted on the host: a gather or product in JAX would compile a program for each window set.
        chunk = windows.take(index[lo : lo + CHUNK])
        weights = np.asarray(chunk.weights)
        weights = weights * weight[lo : lo + CHUNK].astype(weights.dtype)
        yield eqx.tree_at(lambda w: w.weights, chunk, jax.device_put(weights))


def _sensitivities(family: Family, windows: Windows, slots, p, tangents_p, tangents_c):
    """Residuals `(rows,)` and their derivatives `(rows, direction)` along the tangents, over every window."""
    rs, js = [], []
    for chunk in _chunks(windows):
        r, jac = _jacobian(family, chunk, slots, p, tangents_p, tangents_c)
        rs.append(np.asarray(r, float))
        js.append(np.asarray(jac, float).T)
    return np.concatenate(rs), np.concatenate(js)


def rankable(family: Family, remaining) -> list[int]:
    """The candidates of `remaining` this screening ranks: those whose derivative at neutral shows them, neither an
    input's dynamics (a delay, a lag: `input_dynamics`) nor a term not `smooth_at_neutral` (a static level, which
    sits on a tie of its clipping there)."""
    terms, system = family.model.terms, family.model.system
    return [k for k in remaining if not input_dynamics(terms[k], system) and terms[k].smooth_at_neutral]


def rollout_screen(family: Family, train: Windows, validation: Windows, slots, p, candidates) -> np.ndarray:
    """Held-out gain of the first Gauss-Newton step of each candidate's simulation-error refit.

    **Arguments:** the candidate `family`, the `train`ing and held-out `validation` windows, the current
    configuration (`slots`, parameter vector `p` as `dynax._diagnose._fit` lays it out) and the indices of
    the `candidates` to rank (see `rankable`).

    **Returns:** one gain per candidate: the fraction by which the step (the refitted parameters and the
    candidate's coefficient, fitted on `train`) reduces the held-out sum of squares beyond the step of the
    refitted parameters alone. `NaN` where the candidate has no finite direction (every window diverged, or it does
    not move the rollouts).
    """
    dtype = family.neutral.dtype
    slots = jnp.asarray(slots)
    p = jnp.asarray(p, dtype)
    n_nominal, n_slots, n_c = len(family.names), slots.shape[0], family.n_candidates
    # The directions: every refitted nominal parameter and every slot (a slot not yet filled has scale zero), then
    # every candidate. Their number is fixed for a diagnosis, so every round reuses one compilation.
    refitted = np.flatnonzero(np.asarray(family.refit) > 0)
    along_p = np.concatenate([refitted, n_nominal + np.arange(n_slots)])
    scale = family.host_scale(slots, -1)[:-1]
    tp = np.zeros((len(along_p) + n_c, len(p)))
    tp[np.arange(len(along_p)), along_p] = scale[along_p]
    tc = np.zeros((len(along_p) + n_c, n_c))
    tc[len(along_p) + np.arange(n_c), np.arange(n_c)] = np.asarray(family.candidate_scale)
    candidates = list(candidates)
    free = np.flatnonzero(scale[along_p] != 0)
    keep = np.concatenate([free, len(along_p) + np.asarray(candidates, int)])
    data = []
    for windows in (train, validation):
        r, jac = _sensitivities(family, windows, slots, p, jnp.asarray(tp, dtype), jnp.asarray(tc, dtype))
        data.append((r, jac[:, keep]))
    (r_tr, J_tr), (r_va, J_va) = data
    base = np.arange(len(free))

    def train_step(columns):
        """The least-squares step along `columns` on the training rows where everything is finite."""
        rows = np.isfinite(r_tr) & np.all(np.isfinite(J_tr[:, columns]), axis=1)
        X = J_tr[rows][:, columns]
        norms = np.linalg.norm(X, axis=0)
        norms[norms == 0] = 1.0
        return np.linalg.lstsq(X / norms, -r_tr[rows], rcond=None)[0] / norms

    def held_out_sse(columns, step, rows):
        return float(np.sum((r_va[rows] + J_va[rows][:, columns] @ step) ** 2))

    base_step = train_step(base) if len(base) else np.zeros(0)
    gains = np.full(len(candidates), np.nan)
    for i in range(len(candidates)):
        column = len(free) + i
        both = np.append(base, column)
        finite = np.isfinite(J_tr[:, column])
        if not np.any(J_tr[finite, column]):  # no direction (or none that is finite)
            continue
        # Windows where a sensitivity is not finite (a diverged rollout) count for neither step or score.
        rows = np.isfinite(r_va) & np.all(np.isfinite(J_va[:, both]), axis=1)
        sse_base = held_out_sse(base, base_step, rows)
        if sse_base > 0:
            gains[i] = 1.0 - held_out_sse(both, train_step(both), rows) / sse_base
    return gains


def with_rollout_evidence(
    look_alikes_of, remaining, gains_one_step, short, candidates, rollout_gains, n_promote, floor
):
    """The shortlist with up to `n_promote` candidates that the output-error screening ranks above shortlisted ones.

    The equation-error screening's best candidate and its look-alikes keep their places (`look_alikes_of`), and
    so do shortlisted candidates this screening cannot rank (delays, lags, static levels: not in `candidates`).
    An outsider whose output-error gain (`rollout_gains`, one per `candidates`) is at least `floor` takes the
    place of the shortlisted candidate with the lowest output-error gain, if that is lower than its own.

    **Returns:** `(short, promoted)`: the new shortlist and the candidates promoted into it.
    """
    gain_of = {k: g for k, g in zip(candidates, rollout_gains) if np.isfinite(g)}
    best_one_step = remaining[int(np.argmax(gains_one_step))]
    kept = {best_one_step, *look_alikes_of(best_one_step)}
    outsiders = sorted((k for k in gain_of if k not in short and gain_of[k] >= floor), key=lambda k: -gain_of[k])
    short, promoted = list(short), []
    for k in outsiders[:n_promote]:
        replaceable = [s for s in short if s not in kept and s in gain_of]
        if not replaceable:
            break
        worst = min(replaceable, key=lambda s: gain_of[s])
        if gain_of[worst] >= gain_of[k]:
            break
        short[short.index(worst)] = k
        promoted.append(k)
    return short, promoted
