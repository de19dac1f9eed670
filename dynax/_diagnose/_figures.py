"""Figures of the diagnosis (matplotlib `Figure`s drawn without pyplot, so no backend is chosen; PNG)."""

import jax.numpy as jnp
import numpy as np  # noqa: E402

from .._simulate import (
    FixedGrid,  # noqa: E402
    rollouts_from_starts,  # noqa: E402  (the one windowed rollout)
)


def _subplots(*args, figsize, **kwargs):
    from matplotlib.figure import Figure  # lazily: importing dynax stays light and sets no backend

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


def plot_measured_vs_simulated(
    trajectory, models: dict, path, *, segment_s: float = 2.0, max_duration_s: float = 10.0, run_name: str | None = None
):
    """Measured positions against open-loop simulations restarted from the measured state every `segment_s`.

    **Arguments:** `trajectory` (held-out data); `models` label -> system; `path` of the PNG;
    `segment_s` restart interval [s]; `max_duration_s` how much of the record to draw; `run_name`
    which run it is (in the title).
    """
    ts = np.asarray(trajectory.ts)
    n = min(len(ts), int(np.searchsorted(ts, ts[0] + max_duration_s)) + 1)
    seg = max(2, int(round(segment_s / trajectory.dt)))
    helicopter = trajectory.system == "helicopter"
    if helicopter:  # world position and body velocities: where a wind or a bias shows first
        positions = [trajectory.state_names.index(s) for s in ("x", "y", "z", "u", "v", "w")]
    else:
        positions = [i for i, s in enumerate(trajectory.state_names) if not s.startswith("d")]
    fig, axes = _subplots(len(positions), 1, figsize=(9, 2.6 * len(positions)), sharex=True, squeeze=False)
    colors = ["tab:red", "tab:green", "tab:purple", "tab:orange"]
    for ax, i in zip(axes[:, 0], positions):
        ax.plot(ts[:n], np.asarray(trajectory.xs)[:n, i], color="k", lw=1.2, label="measured")
        if helicopter:
            ax.set_ylabel(f"{trajectory.state_names[i]} [{'m' if i < 3 else 'm/s'}]")
        else:
            ax.set_ylabel(f"{trajectory.state_names[i]} [rad]" if trajectory.system != "linear_axis" else "q [m]")
    starts = np.arange(0, n - 1, seg)
    ts_pad = np.concatenate([ts, ts[-1] + trajectory.dt * np.arange(1, seg + 1)])
    xs_pad = np.concatenate([np.asarray(trajectory.xs), np.repeat(np.asarray(trajectory.xs)[-1:], seg, axis=0)])
    us_pad = np.concatenate([np.asarray(trajectory.us), np.repeat(np.asarray(trajectory.us)[-1:], seg, axis=0)])
    for c, (label, system) in enumerate(models.items()):
        errors, _ = rollouts_from_starts(
            system, jnp.asarray(ts_pad), jnp.asarray(xs_pad), jnp.asarray(us_pad), jnp.asarray(starts), seg, FixedGrid()
        )
        for w, start in enumerate(starts):
            stop = min(start + seg, n - 1) + 1
            xs = np.asarray(errors[w, : stop - start]) + xs_pad[start:stop]
            t = ts[start:stop]
            for ax, i in zip(axes[:, 0], positions):
                ax.plot(t, xs[:, i], color=colors[c % 4], lw=1.0, ls="--", label=label if start == 0 else None)
                ax.plot(t[:1], xs[:1, i], "o", color=colors[c % 4], ms=2.5)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title(
        (f"{run_name}: " if run_name else "")
        + f"held-out data against open-loop simulation (restarted every {segment_s:g} s)"
    )
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_error_vs_horizon(curves: dict, path, *, unit: str = "rad"):
    """Open-loop RMSE against horizon, one line per model. `curves`: label -> (horizons_s, rmse)."""
    fig, ax = _subplots(figsize=(6, 4))
    for label, (h, r) in curves.items():
        ax.plot(h, r, "o-", label=label)
    ax.set_xlabel("horizon [s]")
    ax.set_ylabel(f"position RMSE [{unit}]")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    ax.set_title("simulation error against horizon (held-out data)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_residuals(ts, residuals, names, path, *, features: dict | None = None, run_name: str | None = None):
    """One-step acceleration residuals: over time, against velocity, autocorrelation and spectrum.

    Friction shows against velocity (a step at zero for Coulomb friction), input dynamics in the
    autocorrelation and at the excitation frequencies of the spectrum; white noise is flat.

    **Arguments:** `ts`; `residuals` of shape `(time, n_joints)`; `names` of the joints' velocities;
    `path`; `features` name -> `(time,)` array to plot residuals against (default the velocities);
    `run_name` which run it is (in the title).
    """
    import scipy.signal

    residuals = np.asarray(residuals)
    ts = np.asarray(ts)
    dt = float(np.median(np.diff(ts)))
    k = residuals.shape[1]
    fig, axes = _subplots(k, 4, figsize=(15, 2.6 * k), squeeze=False)
    max_lag = min(len(ts) // 4, int(round(1.0 / dt)))
    for j in range(k):
        r = residuals[:, j] - residuals[:, j].mean()
        axes[j, 0].plot(ts, residuals[:, j], lw=0.6)
        axes[j, 0].set_ylabel(f"residual d{names[j]}/dt")
        if features is not None and j < len(features):
            fname, fvals = list(features.items())[j]
            axes[j, 1].plot(np.asarray(fvals), residuals[:, j], ".", ms=1.5, alpha=0.5)
            axes[j, 1].set_xlabel(fname)
        acf = np.correlate(r, r, mode="full")[len(r) - 1 : len(r) + max_lag] / max(float(r @ r), 1e-300)
        axes[j, 2].plot(np.arange(max_lag + 1) * dt, acf, lw=1.0)
        axes[j, 2].axhline(0.0, color="k", lw=0.5)
        axes[j, 2].set_xlabel("lag [s]")
        f, psd = scipy.signal.welch(r, fs=1.0 / dt, nperseg=min(len(r), 512))
        axes[j, 3].semilogy(f, psd, lw=1.0)
        axes[j, 3].set_xlabel("frequency [Hz]")
    axes[0, 0].set_title((f"{run_name}: " if run_name else "") + "one-step acceleration residual against time")
    axes[0, 1].set_title("against velocity")
    axes[0, 2].set_title("autocorrelation")
    axes[0, 3].set_title("spectrum (Welch)")
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
