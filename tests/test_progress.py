"""Progress bars: shown when asked, silent when not, and reported from inside compiled loops."""

import jax
import jax.numpy as jnp
import pytest

import dynax
from dynax.internal import bar_token, progress_enabled, progress_mode, progress_report, ProgressBar
from tests.typecheck import standing_aside


def quadratic(params, key):
    del key
    return -jnp.sum((params - 1.0) ** 2)


class _Stderr:
    def __init__(self, capsys):
        self.capsys = capsys

    def getvalue(self):
        return self.capsys.readouterr().err


@pytest.fixture
def stderr(capsys):
    return _Stderr(capsys)


def test_auto_mode_follows_the_terminal(stderr):
    assert not progress_enabled()  # a StringIO is not a terminal
    with progress_mode("always"):
        assert progress_enabled()
        assert not progress_enabled(False)  # an explicit argument wins
    with progress_mode("never"):
        assert not progress_enabled() and progress_enabled(True)
    with standing_aside(), pytest.raises(ValueError, match="'auto', 'always' or 'never'"):  # no Literal, on purpose
        with progress_mode("loud"):
            pass


def test_disabled_bar_writes_nothing(stderr):
    with ProgressBar(10, "work") as bar:
        bar.update(3, loss=1.0)
    assert bar.token == 0 and stderr.getvalue() == ""


def test_compiled_scan_reports_every_step_and_the_best_value(stderr):
    @jax.jit
    def loop(token, values):
        def body(carry, inputs):
            i, v = inputs
            progress_report(token, i, best=v)
            return carry, None

        return jax.lax.scan(body, 0.0, (jnp.arange(values.shape[0]), values))[0]

    values = jnp.array([0.5, 3.0, 2.0, 1.0])
    with ProgressBar(4, "scan", progress=True, reduce="max") as bar:
        jax.block_until_ready(loop(bar_token(bar), values))
        jax.effects_barrier()
        assert bar._bar.n == 4
        assert bar.values["best"] == 3.0
    text = stderr.getvalue()
    assert "scan" in text and "4/4" in text and "best=3" in text


def test_run_pgpe_bar_shows_generations_and_best_reward(stderr):
    pgpe = dynax.control.PGPE(population_size=8, init_sigma=0.5)
    key = jax.random.PRNGKey(0)
    quiet_state, quiet_history = dynax.control.run_pgpe(pgpe, quadratic, jnp.zeros(2), key, 5)
    assert stderr.getvalue() == ""
    state, history = dynax.control.run_pgpe(pgpe, quadratic, jnp.zeros(2), key, 5, progress=True)
    text = stderr.getvalue()
    assert "5/5" in text and f"best_reward={float(history.best_reward[-1]):.4g}" in text
    # the bar does not change the result
    assert jnp.array_equal(history.best_reward, quiet_history.best_reward)


def test_sweep_pgpe_bar_reports_best_over_runs(stderr):
    pgpe = dynax.control.PGPE(population_size=8, init_sigma=0.5)
    keys = jax.random.split(jax.random.PRNGKey(1), 3)
    with progress_mode("always"):
        states, history = dynax.control.sweep_pgpe(pgpe, quadratic, jnp.zeros(2), keys, 4)
    text = stderr.getvalue()
    assert "4/4" in text and f"best_reward={float(history.best_reward[:, -1].max()):.4g}" in text


def test_no_bar_inside_a_users_jit(stderr):
    pgpe = dynax.control.PGPE(population_size=8, init_sigma=0.5)
    with progress_mode("always"):
        jax.jit(lambda k: dynax.control.run_pgpe(pgpe, quadratic, jnp.zeros(2), k, 3))(jax.random.PRNGKey(0))
    assert stderr.getvalue() == ""


def test_say_writes_stage_lines_above_a_bar_or_as_log_lines(stderr):
    with ProgressBar(None, "diagnose", unit="stage") as bar:  # stderr is not a terminal: plain lines
        bar.say("round 1: screening")
    assert stderr.getvalue() == "round 1: screening\n"
    with progress_mode("never"), ProgressBar(None, "diagnose") as bar:
        bar.say("round 1: screening")
    assert stderr.getvalue() == ""
    with progress_mode("always"), ProgressBar(None, "diagnose", unit="stage") as bar:
        bar.say("round 1: screening")
        bar.say("round 2: refit")
    text = stderr.getvalue()
    assert "round 1: screening\n" in text and "round 2: refit" in text and "2stage" in text.replace(" ", "")


def test_output_error_fit_reports_each_iteration(capsys):
    """The engine's Levenberg-Marquardt reports through optimistix's verbose hook from compiled code."""
    import jax.numpy as jnp

    from dynax import fit_simulation_error

    def axis(m, b):
        return dynax.LinearAxis(
            mass=jnp.asarray(m), viscous=jnp.asarray(b), coulomb=jnp.asarray(0.0), offset=jnp.asarray(0.0)
        )

    ts = jnp.linspace(0.0, 2.0, 201)
    us = jnp.sin(3.0 * ts)[:, None]
    xs = dynax.simulate(axis(0.8, 0.3), jnp.zeros(2), ts, us).xs
    trajectory = dynax.Trajectory(ts, xs, us, ("q", "dq"), ("F",), "linear_axis", "")
    result = fit_simulation_error(axis(1.5, 1.0), trajectory, dynax.SimulationFit(segment_s=10.0), progress=True)
    err = capsys.readouterr().err
    assert "output-error fit" in err and "loss=" in err
    assert abs(float(result.value[0]) - 0.8) < 1e-6  # the bar does not disturb the fit
