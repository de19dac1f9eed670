r"""optimistix's Levenberg-Marquardt, with a trust region that never accepts a step that raises the
loss, and MINPACK's relative-reduction convergence test.

optimistix's `ClassicalTrustRegion` accepts a step when the actual change of the loss is at most
`low_cutoff` (0.01) times the change its linear model predicts, written without the division as
`actual <= 0.01 * predicted` on the assumption that `predicted` is negative. Where the prediction
$\tfrac12(\lVert J\delta + r\rVert^2 - \lVert r\rVert^2)$ comes out positive (it is a difference of
two large sums, and the step and the Jacobian need not come from the same linearisation), the test
passes for an actual increase of up to a hundred times the predicted one. An output-error fit on
real data can then end, not reproducibly, at a point where every rollout diverged, its loss
hundreds of times its start, which only an accepted rise can do (docs/devdocs/code_notes.md).
`StrictTrustRegion` adds the textbook condition (Nocedal & Wright, *Numerical Optimization*, 2nd
ed., 2006, Algorithm 4.1: a step is
taken only when the ratio of actual to predicted reduction is positive): a step is accepted only if
the loss does not rise, and a step refused for that shrinks the region as any refused step does.

**Convergence.** optimistix stops only after an *accepted* step that moved every unknown by less
than `atol + rtol |y|` and every residual by less than `atol + rtol |r|`. At a minimum whose loss
is flat to rounding, the strict region refuses every step that raises the loss in its last digits,
and only a step shrunk to those digits is accepted: on an output-error fit of a two-link arm
(`tests/fit/test_engine.py`, and `identify`'s refinement) a fit that had its loss to 1e-10 after 3
steps of a warm start took 29 more, each a full Jacobian through every rollout. MINPACK's `lmder`
(Moré, Garbow & Hillstrom, *User guide for MINPACK-1*, ANL-80-74, 1980, the `ftol` test; Moré
1978) also stops when both the actual and the predicted relative reductions of the sum of squares
are at most `ftol` and the actual is at most twice the predicted: the linear model promises no
further decrease worth a step, and the function agrees. `levenberg_marquardt` adds that test with
`ftol = rtol`, on accepted and refused steps alike (a refused step at the floor is the typical
last one); the point returned is the last accepted one, as always.

**The Jacobian only where a step was taken.** optimistix linearises the residuals at every trial
point before its search decides whether to take it, so a refused step costs a whole Jacobian: on
an output-error fit, one rollout carrying every parameter's tangent. MINPACK's `lmder` evaluates
only the residuals at a trial point and forms the Jacobian after a successful step (Moré, "The
Levenberg-Marquardt algorithm: implementation and theory", 1978; the user guide above).
`levenberg_marquardt(..., jacobian="accepted")` does the same (`_JacobianOnAcceptance`): the trial
point's residuals first, which is all the trust region reads, then `jax.jacfwd` at the point only
when it is taken, kept as a dense matrix (a few unknowns, many residuals). The iterates are those
of the default to rounding: same search, same descent, same Jacobian. It pays only where the
solve runs unbatched: under `vmap` the branch becomes a select and both sides run, so the batched
diagnosis keeps the default.

**Nielsen's damping update.** optimistix's trust region keeps its size after an accepted step
unless the loss fell by at least 99 % of what its linear model predicted, and then grows it by 3.5;
a step that the model predicted well but not that well leaves the damping where it was (on the
noisy rig records, 10 of the first fit's 18 accepted steps), and the fit walks down a valley in
steps too short for it. Nielsen's rule sets the damping from the gain
ratio $\rho$ of actual to predicted decrease after every accepted step:
$\lambda \leftarrow \lambda \max(1/3,\, 1 - (2\rho - 1)^3)$, a third for a perfect prediction, unchanged at
$\rho = 1/2$, up to twice for a poor one (H. B. Nielsen, "Damping parameter in Marquardt's method",
IMM-REP-1999-05, DTU, 1999; K. Madsen, H. B. Nielsen and O. Tingleff, *Methods for non-linear least
squares problems*, 2nd ed., 2004, eq. 3.15 and Algorithm 3.16). A refused step still shrinks the
region by a quarter. `levenberg_marquardt(..., damping="nielsen")`; the refinement uses it with the
Jacobian at accepted points (31 steps, 19 accepted, became 25 and 13 on those records, the same
minimum).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PyTree
import lineax as lx
import optimistix as optx


class _StrictState(eqx.Module):
    step_size: Float[Array, ""]
    flat: Bool[Array, ""]  # the last step passed the relative-reduction test


class StrictTrustRegion(optx.ClassicalTrustRegion):
    """`optimistix.ClassicalTrustRegion` that also refuses every step that does not lower the loss,
    and records whether the last step passed MINPACK's relative-reduction test with tolerance
    `ftol` (default 0: never); with `nielsen`, an accepted step sets the region by Nielsen's rule
    (see the module's docstring)."""

    ftol: float = 0.0
    nielsen: bool = False

    def init(self, y, f_info_struct) -> _StrictState:
        return _StrictState(jnp.array(1.0), jnp.array(False))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        step_size, accept, result, _ = super().step(first_step, y, y_eval, f_info, f_eval_info, state)
        loss, loss_eval = f_info.as_min(), f_eval_info.as_min()
        lowers = loss_eval <= loss  # False for a NaN loss too
        strict = accept & (first_step | lowers)
        step_size = jnp.where(strict | ~accept, step_size, self.low_constant * state.step_size)
        predicted = -self.predict_reduction(jax.tree.map(jnp.subtract, y_eval, y), f_info)  # a decrease: positive
        actual = loss - loss_eval
        if self.nielsen:
            rho = actual / jnp.where(predicted > 0, predicted, 1.0)
            grow = 1.0 / jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            step_size = jnp.where(strict & ~first_step & (predicted > 0), grow * state.step_size, step_size)
        tol = self.ftol * loss
        flat = (~first_step) & (jnp.abs(actual) <= tol) & (predicted <= tol) & (actual <= 2.0 * predicted)
        return step_size, strict, result, _StrictState(step_size, flat)


class _LevenbergMarquardt(optx.LevenbergMarquardt):
    """`optimistix.LevenbergMarquardt` that also stops when its search says the last step was flat."""

    def terminate(self, fn, y, args, options, state, tags):
        done, result = super().terminate(fn, y, args, options, state, tags)
        flat = getattr(state.search_state, "flat", jnp.array(False))
        return done | flat, result


class _LazyState(eqx.Module):
    first_step: Bool[Array, ""]
    y_eval: Array
    search_state: _StrictState
    f_info: optx.FunctionInfo.ResidualJac  # at the last accepted point, its Jacobian a dense matrix
    aux: PyTree
    descent_state: PyTree
    terminate: Bool[Array, ""]
    result: optx.RESULTS
    num_steps: Int[Array, ""]
    num_accepted_steps: Int[Array, ""]


def _converged(rtol, atol, norm, y, y_diff, f, f_diff):
    """optimistix's Cauchy test: every unknown and every residual moved by under `atol + rtol |.|`."""
    small_step = norm(jnp.abs(y_diff) / (atol + rtol * jnp.abs(y))) < 1
    return small_step & (norm(jnp.abs(f_diff) / (atol + rtol * jnp.abs(f))) < 1)


class _JacobianOnAcceptance(_LevenbergMarquardt):
    """`_LevenbergMarquardt` that evaluates only the residuals at a trial point and forms the Jacobian
    (`jax.jacfwd`, a dense matrix) once the step is taken (see the module's docstring). The unknowns
    and the residuals are 1-D arrays, as the engine gives them."""

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        jac = lx.MatrixLinearOperator(jnp.zeros(f_struct.shape + y.shape, f_struct.dtype))
        f_info = optx.FunctionInfo.ResidualJac(jnp.zeros(f_struct.shape, f_struct.dtype), jac)
        return _LazyState(
            first_step=jnp.array(True),
            y_eval=y,
            search_state=self.search.init(y, f_info),
            f_info=f_info,
            aux=jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), aux_struct),
            descent_state=self.descent.init(y, f_info),
            terminate=jnp.array(False),
            result=optx.RESULTS.successful,
            num_steps=jnp.array(0),
            num_accepted_steps=jnp.array(0),
        )

    def step(self, fn, y, args, options, state, tags):
        residual, aux_eval = fn(state.y_eval, args)
        # The trust region reads only the trial point's loss: its Jacobian is not formed yet.
        trial = optx.FunctionInfo.ResidualJac(residual, state.f_info.jac)
        step_size, accept, search_result, search_state = self.search.step(
            state.first_step, y, state.y_eval, state.f_info, trial, state.search_state
        )

        def accepted(descent_state):
            matrix = jax.jacfwd(lambda z: fn(z, args)[0])(state.y_eval)
            f_info = optx.FunctionInfo.ResidualJac(residual, lx.MatrixLinearOperator(matrix))
            descent_state = self.descent.query(state.y_eval, f_info, descent_state)
            terminate = _converged(
                self.rtol,
                self.atol,
                self.norm,
                state.y_eval,
                state.y_eval - y,
                residual,
                residual - state.f_info.residual,
            )
            return state.y_eval, f_info, aux_eval, descent_state, terminate

        def rejected(descent_state):
            return y, state.f_info, state.aux, descent_state, jnp.array(False)

        y, f_info, aux, descent_state, terminate = jax.lax.cond(accept, accepted, rejected, state.descent_state)
        self.verbose(
            num_steps=("Step", state.num_steps),
            accepted_steps=("Accepted steps", state.num_accepted_steps),
            loss_this_step=("Loss on this step", 0.5 * jnp.sum(residual**2)),
            loss_last_accepted_step=("Loss on the last accepted step", 0.5 * jnp.sum(state.f_info.residual**2)),
            step_size=("Step size", step_size),
        )
        y_descent, descent_result = self.descent.step(step_size, descent_state)
        result = optx.RESULTS.where(search_result == optx.RESULTS.successful, descent_result, search_result)
        new = _LazyState(
            first_step=jnp.array(False),
            y_eval=y + y_descent,
            search_state=search_state,
            f_info=f_info,
            aux=aux,
            descent_state=descent_state,
            terminate=terminate,
            result=result,
            num_steps=state.num_steps + 1,
            num_accepted_steps=state.num_accepted_steps + jnp.where(accept, 1, 0),
        )
        return y, new, jax.tree.map(lambda a, b: jnp.where(state.first_step, a, b), aux, state.aux)


def levenberg_marquardt(
    rtol: float,
    atol: float,
    *,
    norm=optx.max_norm,
    linear_solver=lx.QR(),
    verbose=False,
    jacobian: str = "every_step",
    damping: str = "classical",
) -> optx.LevenbergMarquardt:
    """`optimistix.LevenbergMarquardt(rtol, atol, ...)` with the `StrictTrustRegion` and MINPACK's
    relative-reduction test at `ftol = rtol` (see the module's docstring); same arguments.

    `jacobian="accepted"` forms the Jacobian only at the points it takes, by `jax.jacfwd`, as
    MINPACK does (the same iterates; for unbatched solves of 1-D unknowns and residuals: under `vmap`
    it costs one more evaluation of the residuals a step). The default `"every_step"` is optimistix's.
    `damping="nielsen"` sets the damping after each accepted step by Nielsen's rule; the default
    `"classical"` is optimistix's trust-region update.
    """
    if jacobian not in ("every_step", "accepted"):
        raise ValueError(f"levenberg_marquardt: `jacobian` must be 'every_step' or 'accepted', got {jacobian!r}")
    if damping not in ("classical", "nielsen"):
        raise ValueError(f"levenberg_marquardt: `damping` must be 'classical' or 'nielsen', got {damping!r}")
    cls = _JacobianOnAcceptance if jacobian == "accepted" else _LevenbergMarquardt
    solver = cls(rtol=rtol, atol=atol, norm=norm, linear_solver=linear_solver, verbose=verbose)
    return eqx.tree_at(lambda s: s.search, solver, StrictTrustRegion(ftol=rtol, nielsen=damping == "nielsen"))
