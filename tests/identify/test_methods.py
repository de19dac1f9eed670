"""Methods own their fit: `identify` and `fit_vehicle` call a method's `fit`, never check its class, and
every built-in method's `fit` gives the estimate a computation outside it gives."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import AbstractMethod, Dynamic, Energy, identify, Power, StageKind, Trajectory, UsageError, Validate
from dynax.internal import FitSettings, Prepared, stacked_equations

TRUE = dynax.Acrobot()
NAMES = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7")


@pytest.fixture(scope="module")
def records():
    """Two noisy acrobot records (different starts and torques): least squares is not exact on them."""
    rng = np.random.default_rng(4)
    out = []
    for x0, gain in (([0.2, 0.0, 0.0, 0.0], 1.0), ([-0.3, 0.4, 0.0, 0.0], -0.8)):
        ts = np.arange(0.0, 4.0, 0.005)
        us = gain * (2.0 * np.sin(1.3 * ts) + np.sin(3.7 * ts + 0.5) + 0.5 * np.sin(6.1 * ts))[:, None]
        xs = np.asarray(dynax.simulate(TRUE, jnp.asarray(x0), jnp.asarray(ts), jnp.asarray(us)).xs)
        xs = xs + rng.normal(0.0, [1e-5, 1e-5, 2e-4, 2e-4], xs.shape)
        out.append(Trajectory(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us), TRUE.state_names, TRUE.input_names))
    return out


CALLS: list[int] = []  # the number of records of each call of `EngineLeastSquares.fit`


class EngineLeastSquares(AbstractMethod):
    """Unweighted least squares of the power equations, solved by the engine's Levenberg-Marquardt (a
    method of a user's own: `identify` knows nothing of it but its `fit`)."""

    def fit(self, system, records, settings=FitSettings()):
        _, a, y, _, names, _, _, _, _, _ = stacked_equations(system, records, Power(), settings.friction, None, 1e-7)
        CALLS.append(len(records))

        def residuals(theta, args):
            a, y = args
            return a @ theta - y

        start = jnp.ones(a.shape[1], a.dtype)
        solution = dynax.fit_least_squares(
            residuals, start, dynax.Parameters.of(start, names=names), (a, y), max_steps=50
        )
        fitted = dynax.Acrobot.from_base_parameters(dict(zip(names, np.asarray(solution.value))))
        scaled = np.asarray(a) / np.linalg.norm(np.asarray(a), axis=0)
        _, singular, directions = np.linalg.svd(scaled, full_matrices=False)
        statistics = dynax.internal.Statistics(
            condition_number=jnp.asarray(singular[0] / singular[-1]),
            rank=jnp.asarray(len(names)),
            singular_values=jnp.asarray(singular),
            directions=jnp.asarray(directions),
            residual_rms=jnp.sqrt(2 * solution.loss / a.shape[0]),
            n_rows=a.shape[0],
        )
        # the engine's `Solution`, carrying the fitted system and the regressor's statistics
        return eqx.tree_at(
            lambda s: (s.model, s.statistics), solution, (fitted, statistics), is_leaf=lambda x: x is None
        )


def _lstsq(method, system, records, friction="viscous"):
    """numpy's least-squares solution of the method's stacked equations: the reference."""
    _, a, y, _, _, _, _, _, _, _ = stacked_equations(system, records, method, friction, None, 1e-7)
    return np.linalg.lstsq(np.asarray(a), np.asarray(y), rcond=None)[0]


def test_identify_runs_a_users_method_through_its_fit(records):
    CALLS.clear()
    result = identify(dynax.Acrobot(theta1=5.0), records, EngineLeastSquares(), validation=Validate(holdout=0))
    assert CALLS == [2]  # called once, with both records
    assert result.stages[0].kind == StageKind.FIT and result.method == "engineleastsquares"
    assert result.names == NAMES and isinstance(result.system, dynax.Acrobot)
    np.testing.assert_allclose(np.asarray(result.value), _lstsq(Power(), TRUE, records), rtol=1e-7)
    np.testing.assert_allclose(float(result.system.theta3), result.parameters["theta3"])
    assert result.consistency is not None and not result.consistency.violated  # asked of every method
    assert result.n_samples == sum(len(r) for r in records)
    assert result.to_json()["stages"]["fit"]["parameters"] == result.parameters
    assert float(result.condition_number) == pytest.approx(
        float(Power().fit(TRUE, records).statistics.condition_number)
    )
    # and it is validated like any other method's fit
    held = identify(dynax.Acrobot(), [r.slice(0, 600) for r in records], EngineLeastSquares(), validation=records[1])
    assert held.validation is not None and held.validation.horizons_s == (0.1, 0.25, 0.5)


@pytest.mark.parametrize(
    "method", [Power(), Energy(), Dynamic(offsets=False), Dynamic(offsets=False, lowpass_hz=None)], ids=repr
)
def test_each_least_squares_method_fits_what_numpy_solves(records, method):
    reference = _lstsq(method, TRUE, records)
    direct = method.fit(dynax.Acrobot(theta1=5.0), records)
    np.testing.assert_allclose(np.asarray(direct.value), reference, rtol=1e-7)
    assert direct.names == NAMES and isinstance(direct.model, dynax.Acrobot)
    np.testing.assert_allclose(float(direct.model.theta2), reference[1], rtol=1e-12)
    # `identify` with nothing on top (no offsets, no constraint, no refinement) gives the same estimate
    result = identify(dynax.Acrobot(), records, method, consistency="off", refine=False, validation=Validate(holdout=0))
    assert result.stages[0].kind == StageKind.LEAST_SQUARES
    np.testing.assert_allclose(np.asarray(result.value), reference, rtol=1e-7)
    # and the data's system, to the noise
    np.testing.assert_allclose(
        np.asarray(result.value)[:5], np.asarray(list(TRUE.base_parameters.values()))[:5], rtol=0.05
    )


def test_least_squares_fit_reads_friction_and_weights_from_its_settings(records):
    _, a, y, _, names, _, _, _, _, _ = stacked_equations(TRUE, records, Power(), "coulomb", None, 1e-7)
    w = np.linspace(0.5, 2.0, a.shape[0])
    reference = np.linalg.lstsq(np.asarray(a) * np.sqrt(w)[:, None], np.asarray(y) * np.sqrt(w), rcond=None)[0]
    fit = Power().fit(TRUE, records, FitSettings(friction="coulomb", weights=jnp.asarray(w)))
    assert fit.names == names == NAMES + ("fc1", "fc2")
    np.testing.assert_allclose(np.asarray(fit.value), reference, rtol=1e-7)
    assert isinstance(fit.model, dynax.Extended)  # the model carries the Coulomb terms it fitted


@pytest.mark.wrong_types
def test_methods_are_asked_not_checked():
    with pytest.raises(UsageError, match="AbstractMethod"):
        identify(
            TRUE, Trajectory(jnp.zeros(5), jnp.zeros((5, 4)), jnp.zeros((5, 1)), TRUE.state_names, ("tau2",)), "power"
        )
    with pytest.raises(UsageError, match="unknown criterion"):
        dynax.fit_vehicle(dynax.Helicopter(), None, object())  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        AbstractMethod()  # type: ignore[abstract]


def test_vehicle_criteria_fit_through_the_same_call():
    flight = dynax.synthetic.generate_helicopter_flight("hover", 12.0, seed=3, truth=dynax.Helicopter())
    direct = dynax.OneStep().fit(dynax.Helicopter(), flight)
    # flown by the Tempest model itself: the fitted roll damping is the Tempest's
    assert direct.model.body_model.parameters["dp/p"] == pytest.approx(-12.78, rel=0.01)
    via = dynax.fit_vehicle(dynax.Helicopter(), flight, dynax.OneStep())
    np.testing.assert_array_equal(np.asarray(via.value), np.asarray(direct.value))
    assert direct.statistics.criterion == "one-step" and dynax.OneStep().label == "one-step"
    # `identify` takes the vehicle and the criterion too: the same fit on the head, validated on the tail
    result = identify(dynax.Helicopter(), flight, dynax.OneStep())
    head, tail = flight.split(0.8)
    assert_same_solution(result.solution, dynax.fit_vehicle(dynax.Helicopter(), head, dynax.OneStep()))
    assert result.method == "one-step" and result.stages[0].kind == StageKind.FIT
    # by the vehicle horizon error: 0.1, 0.25 and 0.5 s ahead on the held-out 2.4 s
    validation = result.validation
    assert validation is not None and validation.steps == (10, 25, 50)
    np.testing.assert_array_equal(
        validation.mae_per_state, dynax.flight_error(result.system, tail, (10, 25, 50)).mae_per_state
    )
    # the model that flew the record, learned back: its position half a second ahead within 5 cm
    assert validation.table("mae")["position"][-1] < 0.05
    with pytest.raises(UsageError, match="one record"):
        dynax.OneStep().fit(dynax.Helicopter(), [flight, flight])
    with pytest.raises(UsageError, match="continuous record"):
        dynax.FrequencyDomain().fit(dynax.Helicopter(), flight, FitSettings(breaks=(100,)))


def assert_same_solution(a, b):
    """Two vehicle fits' `Solution`s are one: the fitted model, the estimate, its covariance, the losses and
    the criterion's statistics, bit for bit (the wall-clock history aside)."""
    assert jax.tree.structure(a.model) == jax.tree.structure(b.model) and a.names == b.names
    jax.tree.map(np.testing.assert_array_equal, a.model, b.model)
    for field in ("value", "covariance", "std_errors", "loss", "initial_loss", "loss_history", "steps"):
        np.testing.assert_array_equal(np.asarray(getattr(a, field)), np.asarray(getattr(b, field)), err_msg=field)
    assert a.statistics == b.statistics and a.parameters == b.parameters


@pytest.mark.slow  # about 1 min
def test_fit_vehicle_is_identify_fitting_the_whole_record():
    """`fit_vehicle` is `identify` with the vehicle settings and nothing held out: the same `Solution` for an
    iterative criterion, its breaks, warm start and callback; and the record given as two records is joined
    again with the break where the second begins, no window crossing it."""
    flight = dynax.synthetic.generate_helicopter_flight("hover", 6.0, seed=4)
    lagged = dynax.Lagged(horizon=0.1, stride=4, max_iterations=3)
    seen = []
    settings = FitSettings(breaks=(250,), callback=lambda i, loss: seen.append(float(loss)), progress=False)
    whole = Validate(holdout=0)
    via = identify(dynax.Helicopter(), flight, lagged, settings=settings, validation=whole)
    assert via.validation is None and via.method == "lagged" and via.n_samples == len(flight)
    spelled = dynax.fit_vehicle(dynax.Helicopter(), flight, lagged, breaks=np.array([250]), progress=False)
    assert_same_solution(via.solution, spelled)
    assert seen and seen[-1] == float(via.solution.loss)  # called after each accepted iteration
    # a warm start from the lagged fit, by backprop
    backprop = dynax.Backprop(horizon=0.1, stride=4, max_steps=3)
    warm = FitSettings(breaks=(250,), warm_start=True, progress=False)
    assert_same_solution(
        identify(spelled.model, flight, backprop, settings=warm, validation=whole).solution,
        dynax.fit_vehicle(spelled.model, flight, backprop, breaks=[250], warm_start=True, progress=False),
    )
    # two records: joined, the second's start a break
    two = [flight.slice(0, 250), flight.slice(250, None)]
    joined = identify(dynax.Helicopter(), two, lagged, settings=FitSettings(progress=False), validation=whole)
    np.testing.assert_allclose(np.asarray(joined.value), np.asarray(spelled.value), rtol=1e-9, atol=1e-12)
    with pytest.raises(UsageError, match="breaks"):
        identify(dynax.Helicopter(), two, lagged, settings=settings, validation=whole)
    with pytest.raises(UsageError, match="differ"):
        identify(dynax.Helicopter(), two, dynax.OneStep(), friction="viscous", settings=FitSettings(friction="coulomb"))


def test_identify_runs_prepare_fit_refine_then_validates_for_a_method_of_a_users_own(records):
    seen = []

    class Spy(AbstractMethod):
        def prepare(self, system, records, job):
            seen.append(("prepare", [len(r) for r in records], job))
            return Prepared(self, [r.slice(0, len(r) - 1) for r in records], job)  # each one sample shorter

        def fit(self, system, records, settings=FitSettings()):
            seen.append(("fit", [len(r) for r in records], settings))
            return Power().fit(system, records, settings)

        def refine(self, system, prepared, fitted):
            seen.append(("refine", [len(r) for r in prepared.records], fitted.identification.validation))
            return fitted

    result = identify(TRUE, records, Spy(), friction="coulomb", consistency="check", refine=False)
    assert [step for step, _, _ in seen] == ["prepare", "fit", "refine"]
    (_, lengths, job), (_, fitted_lengths, settings), (_, _, unvalidated) = seen
    assert all(n < len(r) for n, r in zip(lengths, records))  # the heads: the tails are held out
    assert fitted_lengths == [n - 1 for n in lengths] and settings == job.settings  # the prepared records
    assert job.held_out.tails_of == (0, 1) and len(job.held_out.records) == 2
    assert (job.settings.friction, job.consistency, job.refine, job.system_name) == (
        "coulomb",
        "check",
        False,
        "acrobot",
    )
    # identify validates the stage after the refinement, on the held-out tails
    assert unvalidated is None and result.validation is not None
    np.testing.assert_array_equal(result.validation.rmse, job.held_out.validate(result.system).rmse)
    assert result.method == "spy" and result.stages[0].kind == StageKind.FIT
    assert result.n_samples == sum(fitted_lengths)
    seen.clear()
    identify(TRUE, records[0], Spy(), validation=records[1])
    _, lengths, job = seen[0]
    assert lengths == [len(records[0])] and job.held_out.tails_of is None  # records of their own
    seen.clear()
    result = identify(TRUE, records, Spy(), validation=Validate(holdout=0))
    assert result.validation is None  # nothing held out, nothing validated
