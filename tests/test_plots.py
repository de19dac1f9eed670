"""Plots return matplotlib Figures (no pyplot, no backend), drawn from the same numbers as the metrics."""

import jax.numpy as jnp
from matplotlib.figure import Figure
import numpy as np
import pytest

import dynax


@pytest.fixture(scope="module")
def acrobot_run():
    ts = np.arange(0, 2.0, 0.01)
    us = (0.5 * np.sin(3 * ts))[:, None]
    sim = dynax.simulate(dynax.Acrobot(), jnp.array([0.3, 0.0, 0.0, 0.0]), ts, us)
    return dynax.Trajectory(
        jnp.asarray(ts), sim.xs, jnp.asarray(us), ("q1", "q2", "dq1", "dq2"), ("tau2",), "acrobot", "run.csv"
    )


def test_plot_compare_shows_the_fit_of_each_model_per_run(acrobot_run, tmp_path):
    wrong = dynax.Acrobot(theta4=dynax.Acrobot().theta4 * 1.3)
    fig = dynax.plot_compare([acrobot_run, acrobot_run.slice(50, None)], {"true": dynax.Acrobot(), "wrong": wrong})
    assert isinstance(fig, Figure)
    axes = fig.get_axes()
    assert len(axes) == 4  # q1, q2 for two runs
    labels = [t.get_text() for t in axes[0].get_legend().get_texts()]
    assert labels[0] == "measured" and labels[1] == "true: fit 100.0 %"
    wrong_fit = float(labels[2].split("fit ")[1].split(" %")[0])
    simulated = dynax.simulate(wrong, acrobot_run.x0, acrobot_run.ts, acrobot_run.us).xs
    assert wrong_fit == pytest.approx(float(dynax.nrmse_fit(acrobot_run.xs[:, 0], simulated[:, 0])[0]), abs=0.051)
    assert wrong_fit < 90
    fig.savefig(tmp_path / "compare.png")
    assert (tmp_path / "compare.png").stat().st_size > 1000
    with pytest.raises(ValueError, match="not states"):
        dynax.plot_compare(acrobot_run, dynax.Acrobot(), states=["x"])


def test_plot_error_horizon_takes_simulation_errors(acrobot_run):
    wrong = dynax.Acrobot(theta4=dynax.Acrobot().theta4 * 1.3)
    curve = dynax.simulation_error(wrong, acrobot_run, horizons_s=(0.1, 0.5))
    fig = dynax.plot_error_horizon({"wrong": curve, "given": ([0.1, 0.5], [1e-3, 1e-2])}, unit="rad")
    lines = fig.get_axes()[0].get_lines()
    np.testing.assert_allclose(lines[0].get_ydata(), np.asarray(curve.rmse))
    assert fig.get_axes()[0].get_ylabel() == "RMSE [rad]"


def test_plot_residuals_draws_the_bands_of_the_tests():
    rng = np.random.default_rng(0)
    u = rng.normal(size=(1000, 1))
    e = np.column_stack([rng.normal(size=1000), 0.1 * rng.normal(size=1000) + 0.5 * np.roll(u[:, 0], 2)])
    fig = dynax.plot_residuals(e, u, names=["white", "leaky"], input_names=["tau"])
    axes = fig.get_axes()
    assert len(axes) == 4
    titles = [ax.get_title() for ax in axes]
    assert "white: autocorrelation (white" in titles[0]
    assert "leaky vs tau (correlated" in titles[3]
    assert "white vs tau (independent" in titles[1]
    assert isinstance(fig, Figure)
