r"""Equation-error screening of candidates: cheap, linearised, on one-step acceleration residuals.

Around the current model, adding candidate $c$ with a small coefficient $\delta_c$ and moving the
refitted nominal parameters by $\Delta\theta$ changes the predicted acceleration by
$J_\theta \Delta\theta + J_c \delta_c$, with the sensitivities $J$ from forward-mode autodiff of
the vector field at the measured (smoothed) states. Regressing the training residuals on
$[J_\theta, J_c]$ and measuring the reduction of the *held-out* residuals ranks every candidate in
one linear least-squares solve each. A delay or lag at zero has no sensitivity (it is a dynamic
term); to first order both act as $-\tau\,\partial f/\partial u\,\dot u$, so they screen alike and
the output-error refit that follows tells them apart.

??? cite

    S. Chen, S. A. Billings and W. Luo, "Orthogonal least squares methods and their application
    to non-linear system identification", International Journal of Control 50(5), 1989
    (ranking candidate terms by their reduction of the equation error).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import savitzky_golay
from .._model._extensions import AbstractInputTerm
from ._residuals import _hidden_trajectory, _sg_window, velocity_indices


@eqx.filter_jit
def _directions(family, values, coefficients, xs, zs, us, us_before):
    model = family.build(values, coefficients)
    idx = jnp.asarray(velocity_indices(model.system))

    def accel(v, c, x, z, u):
        m = family.build(v, c)
        return m.vector_field(0.0, jnp.concatenate([x, z]), u)[idx]

    jac = jax.jacfwd(accel, argnums=(0, 1, 4))

    def both(x, z, u, ub):
        a = jac(values, coefficients, x, z, u)
        b = jac(values, coefficients, x, z, ub)
        return tuple(0.5 * (p + q) for p, q in zip(a, b))

    del model
    return jax.vmap(both)(xs, zs, us, us_before)


def screening_data(family, values, coefficients, trajectory, residual_fn):
    """Residuals and sensitivities on one record: `(r (time, n_vel), J_nominal (time, n_vel, n_nom), J_candidates (time, n_vel, n_cand))`."""
    model = family.build(jnp.asarray(values), jnp.asarray(coefficients))
    r, _, _, keep = residual_fn(model, trajectory)
    ts = trajectory.ts
    w = _sg_window(trajectory.dt)
    xs = savitzky_golay(ts, trajectory.xs, window=w, order=3)
    zs = _hidden_trajectory(model, ts, trajectory.us)
    us = trajectory.us
    us_before = jnp.concatenate([us[:1], us[:-1]])
    J_nom, J_c, J_u = _directions(family, jnp.asarray(values), jnp.asarray(coefficients), xs, zs, us, us_before)
    du = savitzky_golay(ts, us, window=w, order=2, deriv=1)  # (time, n_inputs)
    J_c = np.array(J_c)
    for k, term in enumerate(family.model.terms):
        if isinstance(term, AbstractInputTerm) and term.n_hidden and not np.any(J_c[:, :, k]):
            J_c[:, :, k] = -np.asarray(J_u)[:, :, term.input] * np.asarray(du)[:, None, term.input]
    smooth = lambda a: np.asarray(savitzky_golay(ts, a, window=w, order=3))  # noqa: E731
    return r, smooth(np.asarray(J_nom))[keep], smooth(J_c)[keep]


def screen(family, values, coefficients, refit_mask, train, validation, candidates_to_screen, residual_fn):
    """Held-out equation-error gain of each candidate in `candidates_to_screen` (indices), linearised.

    **Returns:** `(gain, delta)` arrays: the fraction by which the candidate reduces the held-out
    residual sum of squares (beyond refitting the nominal parameters), and its coefficient step.
    """
    parts = {}
    for name, records in (("train", train), ("validation", validation)):
        data = [screening_data(family, values, coefficients, rec, residual_fn) for rec in records]
        parts[name] = tuple(np.concatenate([d[i] for d in data]) for i in range(3))
    r_tr, Jn_tr, Jc_tr = parts["train"]
    r_va, Jn_va, Jc_va = parts["validation"]
    scale = r_tr.std(axis=0) + 1e-12
    refit = np.asarray(refit_mask) > 0

    def design(Jn, Jc, k):
        cols = [Jn[:, :, refit]] if refit.any() else []
        if k is not None:
            cols.append(Jc[:, :, k : k + 1])
        if not cols:
            return np.zeros((Jn.shape[0] * Jn.shape[1], 0))
        X = np.concatenate(cols, axis=2) / scale[None, :, None]
        return X.reshape(-1, X.shape[2])

    y_tr, y_va = (r_tr / scale).reshape(-1), (r_va / scale).reshape(-1)

    def held_out_sse(k):
        X_tr, X_va = design(Jn_tr, Jc_tr, k), design(Jn_va, Jc_va, k)
        if X_tr.shape[1] == 0:
            return float(np.sum(y_va**2)), 0.0
        norms = np.linalg.norm(X_tr, axis=0)
        norms[norms == 0] = 1.0
        beta = np.linalg.lstsq(X_tr / norms, y_tr, rcond=None)[0] / norms
        return float(np.sum((y_va - X_va @ beta) ** 2)), float(beta[-1])

    base, _ = held_out_sse(None)
    gains, deltas = [], []
    for k in candidates_to_screen:
        sse, delta = held_out_sse(k)
        gains.append(1 - sse / base)
        deltas.append(delta)
    return np.asarray(gains), np.asarray(deltas)
