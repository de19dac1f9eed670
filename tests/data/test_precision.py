"""The float64 policy: times stay float64 on the host, float32 work that needs float64 is warned about once."""

import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np

import dynax
from tests.conftest import REPO


def _run_float32(code: str) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter where JAX is in its default float32 mode."""
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", "JAX_PLATFORMS": "cpu"},
    )


def test_a_long_record_keeps_float64_times_and_is_named_in_float32_mode(tmp_path):
    # 20 minutes at 1 kHz: float32 resolves t = 1200 s only to 1.2e-4 s, 12 % of the interval.
    path = tmp_path / "long.npz"
    t = np.arange(1_200_000) * 1e-3
    np.savez(path, t=t, q=np.sin(t), force=np.cos(t))
    out = _run_float32(f"""
        import warnings, numpy as np, dynax
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            run = dynax.load_trajectory({str(path)!r}, "linear_axis")
        print(type(run.ts).__name__, run.ts.dtype, run.xs.dtype, run.is_uniform, abs(run.dt - 1e-3) < 1e-12)
        print([str(w.message) for w in caught if issubclass(w.category, dynax.PrecisionWarning)])
        print(np.asarray(run.astype(np.float32).ts).dtype)
    """)
    assert out.returncode == 0, out.stderr
    first, warned, cast = out.stdout.splitlines()
    assert first == "ndarray float64 float32 True True"
    assert "long.npz" in warned and "jax_enable_x64" in warned and "12%" in warned
    assert cast == "float64"  # .astype(float32) keeps the host times


def test_identification_in_float32_warns_once_naming_the_switch():
    out = _run_float32("""
        import warnings, numpy as np, jax.numpy as jnp, dynax
        axis = dynax.LinearAxis(mass=2.0, viscous=3.0, coulomb=0.0, offset=0.0)
        ts = np.arange(0, 2.0, 0.01); force = np.sin(3 * ts)[:, None]
        xs = dynax.simulate(axis, jnp.zeros(2), ts, force).xs
        run = dynax.Trajectory(ts, xs, jnp.asarray(force), ("q", "dq"), ("force",), "linear_axis")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            dynax.identify(axis, run)
            dynax.identify(axis, run)
        messages = [str(w.message) for w in caught if issubclass(w.category, dynax.PrecisionWarning)]
        print(len(messages)); print(messages[0])
    """)
    assert out.returncode == 0, out.stderr
    count, message = out.stdout.splitlines()[:2]
    assert count == "1" and 'jax.config.update("jax_enable_x64", True)' in message and "identification" in message


def test_float64_mode_loads_float64_and_warns_nothing(tmp_path, recwarn):
    path = tmp_path / "run.npz"
    t = np.arange(2000) * 1e-3
    np.savez(path, t=t, q=np.sin(t), force=np.cos(t))
    run = dynax.load_trajectory(path, "linear_axis")
    assert run.ts.dtype == np.float64 and run.xs.dtype == jnp.float64
    assert not [w for w in recwarn if issubclass(w.category, dynax.PrecisionWarning)]


def test_central_difference_is_jnp_gradient_and_jits():
    rng = np.random.default_rng(0)
    ts = np.cumsum(rng.uniform(0.005, 0.015, 300))  # jittered sampling
    ys = np.column_stack([np.sin(3 * ts), ts**2])
    expected = np.gradient(ys, ts, axis=0)  # numpy's second-order central differences
    np.testing.assert_allclose(dynax.central_difference(ts, ys), expected, rtol=1e-10, atol=1e-10)
    jitted = jax.jit(dynax.central_difference)(jnp.asarray(ts), jnp.asarray(ys))
    np.testing.assert_allclose(jitted, expected, rtol=1e-9, atol=1e-9)
    # exact for a quadratic in the interior, whatever the spacing
    np.testing.assert_allclose(np.asarray(jitted)[1:-1, 1], 2 * ts[1:-1], rtol=1e-9)
    batched = jax.vmap(dynax.central_difference, in_axes=(None, 0))(jnp.asarray(ts), jnp.stack([jnp.asarray(ys)] * 2))
    assert batched.shape == (2, 300, 2)
