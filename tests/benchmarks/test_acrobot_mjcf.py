"""What the rollout benchmark relies on.

`benchmarks/rollout.py` compares throughput against `mujoco.rollout` on `benchmarks/acrobot.xml`;
the comparison is only fair if both integrate the same equations with the same scheme, which the
first tests check in float64. The last ones guard `FixedGrid`'s scan (which a faster step
would replace) against diffrax's own `solver.step`, restarted at every sample.
"""

import pathlib

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax

MJCF = pathlib.Path(__file__).resolve().parents[2] / "benchmarks" / "acrobot.xml"


@pytest.fixture(scope="module")
def model():
    mujoco = pytest.importorskip("mujoco")
    return mujoco.MjModel.from_xml_path(str(MJCF))


def test_model_structure(model):
    mujoco = pytest.importorskip("mujoco")
    # Two hinges, one motor on the elbow, RK4 at 100 Hz, no hidden joint effects.
    assert (model.nq, model.nv, model.nu) == (2, 2, 1)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert model.opt.timestep == pytest.approx(0.01)
    assert np.all(model.dof_armature == 0) and np.all(model.dof_frictionloss == 0)
    np.testing.assert_allclose(model.dof_damping, [0.1, 0.1])
    assert model.actuator_trnid[0, 0] == model.joint("elbow").id


def test_qacc_matches_vector_field(model):
    import mujoco

    system = dynax.Acrobot()
    vector_field = jax.jit(jax.vmap(lambda x, u: system.vector_field(0.0, x, u)))
    rng = np.random.default_rng(0)
    xs = np.concatenate([rng.uniform(-np.pi, np.pi, (64, 2)), rng.uniform(-8.0, 8.0, (64, 2))], axis=1)
    us = rng.uniform(-5.0, 5.0, (64, 1))
    expected = np.asarray(vector_field(jnp.asarray(xs), jnp.asarray(us)))
    assert expected.dtype == np.float64
    data = mujoco.MjData(model)
    for x, u, dx in zip(xs, us, expected):
        data.qpos[:], data.qvel[:], data.ctrl[:] = x[:2], x[2:], u
        mujoco.mj_forward(model, data)
        # Accelerations are O(10-100) rad/s^2; both sides are float64 closed forms of the same
        # equations, so they agree to rounding.
        np.testing.assert_allclose(data.qacc, dx[2:], rtol=1e-9, atol=1e-9)


def test_rk4_rollout_matches_fixed_grid(model):
    import mujoco
    from mujoco import rollout

    # mujoco.rollout with the RK4 integrator and dynax's FixedGrid(RK4, substeps=1) take the
    # same classical RK4 steps with zero-order-hold inputs, so 2 s of rollout agree to rounding.
    n_steps, dt = 200, model.opt.timestep
    rng = np.random.default_rng(1)
    x0 = np.array([0.5, -1.0, 0.3, 0.8])
    us = 2.0 * np.sin(np.linspace(0.0, 6.0, n_steps))[:, None] + 0.1 * rng.standard_normal((n_steps, 1))

    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = x0[:2], x0[2:]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state0, spec)
    states, _ = rollout.rollout(model, data, state0[None], us[None])
    mj_xs = states[0, :, 1:5]  # FULLPHYSICS = [time, qpos, qvel, act, ...]; row k is after step k+1

    ts = dt * np.arange(n_steps + 1)
    sim = dynax.simulate(
        dynax.Acrobot(), x0, ts, np.concatenate([us, us[-1:]]), method=dynax.FixedGrid(dynax.RK4(), substeps=1)
    )
    np.testing.assert_allclose(states[0, :, 0], ts[1:], atol=1e-12)
    np.testing.assert_allclose(np.asarray(sim.xs[1:]), mj_xs, rtol=0, atol=1e-9)


TS_SHORT = jnp.linspace(0.0, 1.0, 101)
US = (2.0 * jnp.sin(3.0 * TS_SHORT) + jnp.where(TS_SHORT > 0.5, 1.0, 0.0))[:, None]
X0 = jnp.array([1.0, 0.5, -0.3, 0.2])


def diffrax_step_rollout(system, solver, substeps):
    """The reference: diffrax's `solver.step`, restarted at every sample as `FixedGrid` does."""
    term = diffrax.ODETerm(lambda t, x, u: system.vector_field(t, x, u))

    def interval(x, inputs):
        t0, t1, u = inputs
        h = (t1 - t0) / substeps
        for i in range(substeps):
            ta = t0 + i * h
            state = solver.init(term, ta, ta + h, x, u)
            x = solver.step(term, ta, ta + h, x, u, state, made_jump=True)[0]
        return x, x

    _, xs = jax.lax.scan(interval, X0, (TS_SHORT[:-1], TS_SHORT[1:], US[:-1]))
    return jnp.concatenate([X0[None], xs])


@pytest.mark.parametrize(
    "solver",
    [diffrax.Tsit5(), diffrax.Dopri5(), dynax.RK4(), diffrax.Euler()],
    ids=lambda s: type(s).__name__,
)
def test_fixed_grid_equals_diffrax_step(solver):
    system = dynax.Acrobot()
    sim = dynax.simulate(system, X0, TS_SHORT, US, method=dynax.FixedGrid(solver, substeps=2))
    reference = diffrax_step_rollout(system, solver, 2)
    assert sim.xs.dtype == jnp.float64
    # A faster step may reorder the arithmetic, nothing more: float64 rounding over 200 substeps.
    np.testing.assert_allclose(np.asarray(sim.xs), np.asarray(reference), rtol=0, atol=1e-12)


def test_float32_rollout_stays_float32_with_float64_parameters():
    sim = dynax.simulate(dynax.Acrobot(), X0.astype(jnp.float32), TS_SHORT.astype(jnp.float32), US.astype(jnp.float32))
    assert sim.xs.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(sim.xs)))
