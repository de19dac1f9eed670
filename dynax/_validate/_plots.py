"""Plots as API: measured against simulated, error against horizon, residual tests; each returns a Figure.

The figures are `matplotlib.figure.Figure` objects made without pyplot, so no backend is chosen
and nothing is kept in a global figure registry: show one in a notebook by leaving it as the
cell's value, save it with `fig.savefig(path)`. matplotlib is imported when a plot is made, not
when dynax is imported.
"""

from collections.abc import Mapping, Sequence

from jaxtyping import ArrayLike, Float
import numpy as np

from .._data._trajectory import Trajectory
from .._model._system import AbstractSystem
from .._simulate import complete_state, simulate
from ._metrics import cross_correlation_test, nrmse_fit, whiteness_test


def _figure(rows: int, cols: int, *, width: float, height: float, **kwargs):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * cols, height * rows), layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False, **kwargs)


def _simulate_run(system: AbstractSystem, run: Trajectory) -> np.ndarray:
    x0 = complete_state(system, run.xs[0], run.us[0])
    sim = simulate(system, x0, run.ts, run.us, throw=False)
    return np.asarray(sim.xs)[:, : run.xs.shape[1]]


def plot_compare(
    runs: Trajectory | Sequence[Trajectory],
    models: AbstractSystem | Mapping[str, AbstractSystem],
    *,
    states: Sequence[str] | None = None,
):
    """Measured against simulated, per run, with MATLAB `compare`'s fit % in the legend.

    Each model is simulated open loop from each run's first measured state under its recorded
    inputs (`dynax.simulate`, the model's default solver). A diverged simulation stops where it
    diverged and its fit is shown as `-inf`.

    **Arguments:**

    - `runs`: a `Trajectory` or a list of them (one column of axes each).
    - `models`: a system, or label -> system for several.
    - `states`: the state names to draw (one row each); default the positions (names not starting
      with `d`), or all states of a helicopter's velocity block.

    **Returns:** a `matplotlib.figure.Figure`.
    """
    runs = [runs] if isinstance(runs, Trajectory) else list(runs)
    if not runs:
        raise ValueError("plot_compare: `runs` is empty")
    if isinstance(models, AbstractSystem):
        models = {"simulated": models}
    names = runs[0].state_names
    if states is None:
        states = [s for s in names if not s.startswith("d")] if runs[0].system != "helicopter" else ["u", "v", "w"]
    unknown = [s for s in states if s not in names]
    if unknown:
        raise ValueError(f"plot_compare: {unknown} are not states of the runs; the states are {names}")
    index = [names.index(s) for s in states]
    fig, axes = _figure(len(index), len(runs), width=5.5, height=2.4, sharex="col")
    for col, run in enumerate(runs):
        ts = np.asarray(run.ts)
        measured = np.asarray(run.xs)
        simulated = {label: _simulate_run(system, run) for label, system in models.items()}
        for row, i in enumerate(index):
            ax = axes[row, col]
            ax.plot(ts, measured[:, i], color="k", lw=1.2, label="measured")
            for label, xs in simulated.items():
                finite = np.all(np.isfinite(xs[:, i]))
                fit = float(nrmse_fit(measured[:, i], xs[:, i])[0]) if finite else -np.inf
                ax.plot(ts, xs[:, i], lw=1.0, label=f"{label}: fit {fit:.1f} %")
            ax.set_ylabel(states[row])
            ax.legend(fontsize=7, loc="best")
        axes[0, col].set_title(run.source.rsplit("/", 1)[-1] or f"run {col + 1}", fontsize=9)
        axes[-1, col].set_xlabel("t [s]")
    return fig


def plot_error_horizon(curves: Mapping[str, object], *, unit: str = ""):
    """Open-loop simulation error against horizon, one line per model.

    **Arguments:**

    - `curves`: label -> a `dynax.SimulationError` (from `dynax.simulation_error`) or a pair
      `(horizons_s, rmse)`.
    - `unit`: the error's unit for the axis label.

    **Returns:** a `matplotlib.figure.Figure`.
    """
    fig, axes = _figure(1, 1, width=6, height=4)
    ax = axes[0, 0]
    for label, curve in curves.items():
        if hasattr(curve, "horizons_s") and hasattr(curve, "rmse"):
            horizons, rmse = curve.horizons_s, curve.rmse
        else:
            horizons, rmse = curve
        ax.plot(np.asarray(horizons), np.asarray(rmse), "o-", label=label)
    ax.set_xlabel("horizon [s]")
    ax.set_ylabel(f"RMSE [{unit}]" if unit else "RMSE")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    ax.set_title("open-loop simulation error against horizon")
    return fig


def plot_residuals(
    residuals: Float[ArrayLike, " time *channels"],
    inputs: Float[ArrayLike, " time *n_inputs"] | None = None,
    *,
    names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
    max_lag: int = 25,
    confidence: float = 0.99,
):
    """The residual tests of MATLAB's `resid` drawn with their confidence bands.

    Left: the residual autocorrelation at lags $1..M$ with the band of `whiteness_test`. Right
    (when `inputs` is given): the residual-input cross-correlation at lags $-M..M$ with the band of
    `cross_correlation_test`, one column per input. Bars outside the shaded band are
    significant at the `confidence` level.

    **Arguments:**

    - `residuals`: shape `(time,)` or `(time, channels)` (one row of axes per channel).
    - `inputs`: optional recorded inputs, shape `(time,)` or `(time, n_inputs)`.
    - `names`, `input_names`: labels of the channels and inputs.
    - `max_lag`, `confidence`: as `whiteness_test`.

    **Returns:** a `matplotlib.figure.Figure`.
    """
    white = whiteness_test(residuals, max_lag=max_lag, confidence=confidence)
    cross = (
        None if inputs is None else cross_correlation_test(residuals, inputs, max_lag=max_lag, confidence=confidence)
    )
    n_channels = white.autocorrelation.shape[0]
    n_inputs = 0 if cross is None else cross.cross_correlation.shape[1]
    names = list(names) if names is not None else [f"e{i + 1}" for i in range(n_channels)]
    input_names = list(input_names) if input_names is not None else [f"u{j + 1}" for j in range(n_inputs)]
    fig, axes = _figure(n_channels, 1 + n_inputs, width=4.2, height=2.4)
    for i in range(n_channels):
        ax = axes[i, 0]
        ax.axhspan(-white.bound, white.bound, color="tab:blue", alpha=0.15, lw=0)
        ax.vlines(white.lags, 0, white.autocorrelation[i], color="k")
        verdict = "white" if white.white[i] else "not white"
        ax.set_title(f"{names[i]}: autocorrelation ({verdict}, p = {white.p_value[i]:.2g})", fontsize=8)
        ax.set_xlabel("lag [samples]")
        for j in range(n_inputs):
            ax = axes[i, 1 + j]
            bound = cross.bound[i, j]
            ax.axhspan(-bound, bound, color="tab:blue", alpha=0.15, lw=0)
            ax.vlines(cross.lags, 0, cross.cross_correlation[i, j], color="k")
            verdict = "independent" if cross.independent[i, j] else "correlated"
            ax.set_title(f"{names[i]} vs {input_names[j]} ({verdict}, p = {cross.p_value[i, j]:.2g})", fontsize=8)
            ax.set_xlabel("lag [samples] (input leads for > 0)")
    fig.suptitle(f"residual tests, {confidence:.0%} confidence bands", fontsize=9)
    return fig
