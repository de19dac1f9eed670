"""The typed result of `diagnose`: `Report` and its parts. `report.json` is written from it (`Report.to_json`).

The contract's keys (`/CONTRACT.md` section 3: `system`, `data`, `nominal`, `verdict`, `findings`,
`extended`, `gain`, `reference_horizon_s`) come first, in that order, with the contract's meaning;
everything else is an extension after them.
"""

import equinox as eqx

from .._model._system import AbstractSystem
from .._simulate import SimulationError
from .._validate import Horizon
from ._residuals import Structure
from ._verdict import Verdict


class ResidualTests(eqx.Module):
    """MATLAB `resid`-style tests of one held-out run's one-step residuals (see `validation_summary`).

    **Fields:** `run`; `channels` (the velocities whose residuals are tested); `inputs`; `lag_s`
    (the spacing of the tested lags); `max_lag`; `confidence`; `whiteness_p` and `white` per
    channel (Ljung-Box); `cross_correlation_p` and `independent` per channel and input (Bartlett's
    covariance, chi-square over all lags); `peak_autocorrelation` (largest |rho| over lags 1..M)
    and `autocorrelation_bound`, per channel; `peak_cross_correlation` per channel and input and
    `cross_correlation_bound`.
    """

    run: str
    channels: tuple[str, ...]
    inputs: tuple[str, ...]
    lag_s: float
    max_lag: int
    confidence: float
    whiteness_p: tuple[float, ...]
    white: tuple[bool, ...]
    peak_autocorrelation: tuple[float, ...]
    autocorrelation_bound: float
    cross_correlation_p: tuple[tuple[float, ...], ...]
    independent: tuple[tuple[bool, ...], ...]
    peak_cross_correlation: tuple[tuple[float, ...], ...]
    cross_correlation_bound: tuple[tuple[float, ...], ...]

    def to_json(self) -> dict:
        return {
            "run": self.run,
            "lag_s": self.lag_s,
            "max_lag": self.max_lag,
            "confidence": self.confidence,
            "whiteness": {
                c: {"p_value": p, "white": w, "peak_autocorrelation": r, "bound": self.autocorrelation_bound}
                for c, p, w, r in zip(self.channels, self.whiteness_p, self.white, self.peak_autocorrelation)
            },
            "cross_correlation": {
                c: {
                    u: {"p_value": p, "independent": i, "peak": r, "bound": b}
                    for u, p, i, r, b in zip(self.inputs, ps, ind, rs, bs)
                }
                for c, ps, ind, rs, bs in zip(
                    self.channels,
                    self.cross_correlation_p,
                    self.independent,
                    self.peak_cross_correlation,
                    self.cross_correlation_bound,
                )
            },
            "white": all(self.white),
            "independent": all(all(row) for row in self.independent),
        }


class Validation(eqx.Module):
    """How a model does on the held-out runs in the terms system-identification users know.

    **Fields:** `horizon_s` (the reference horizon); `fit_percent` per state: MATLAB `compare`'s
    NRMSE fit $100(1 - \\lVert y - \\hat y\\rVert / \\lVert y - \\bar y\\rVert)$ of the
    `horizon_s`-ahead open-loop prediction from every held-out window (`dynax.nrmse_fit`; `None`
    where a window diverged); `residual_tests` one `ResidualTests` per held-out run.
    """

    horizon_s: float
    fit_percent: dict[str, float | None]
    residual_tests: tuple[ResidualTests, ...]

    def to_json(self) -> dict:
        return {
            "horizon_s": self.horizon_s,
            "fit_percent": dict(self.fit_percent),
            "residual_tests": [t.to_json() for t in self.residual_tests],
        }


class ModelSummary(eqx.Module):
    """The contract's `nominal` / `extended` object: parameters and held-out simulation error, plus extensions.

    **Fields:** `parameters` by report name; `sim_error` (a `SimulationError`: held-out open-loop
    position RMSE against horizon, written `null` where a window diverged); `terms` (`cause@where` of an extended
    model's terms, `None` for the nominal model); `validation` (fit % and residual tests, or `None`).
    """

    parameters: dict[str, float]
    sim_error: SimulationError
    terms: tuple[str, ...] | None = None
    validation: Validation | None = None

    def to_json(self) -> dict:
        out: dict = {}
        if self.terms is not None:
            out["terms"] = list(self.terms)
        out["parameters"] = dict(self.parameters)
        out["sim_error"] = self.sim_error.to_json(null_diverged=True)
        if self.validation is not None:
            out["validation"] = self.validation.to_json()
        return out


class DataSummary(eqx.Module):
    """The contract's `data` object: record names and sizes, plus the sampling interval and the runs."""

    train: str
    validation: str
    n_train: int
    n_validation: int
    dt: float
    train_runs: tuple[str, ...]
    validation_runs: tuple[str, ...]
    velocities: str = "as measured"  # or how they were estimated (`diagnose(velocities=...)`)

    def to_json(self) -> dict:
        return {
            "train": self.train,
            "validation": self.validation,
            "n_train": self.n_train,
            "n_validation": self.n_validation,
            "dt": self.dt,
            "train_runs": list(self.train_runs),
            "validation_runs": list(self.validation_runs),
            "velocities": self.velocities,
        }


def structure_json(s: Structure) -> dict:
    return {
        "significant": s.significant,
        "r2": s.r2,
        "p_value": s.p_value,
        "top_features": [{"feature": n, "share": w} for n, w in s.top_features],
        "worst_times_s": list(s.worst_times),
        "by_state": s.by_state,
    }


class FlightScores(eqx.Module):
    """A flight diagnosis' held-out scores per state group beside constant velocity, and what they note.

    **Fields:** `models`: `{name: SimulationError}` of `dynax.flight_error` (position, velocity, attitude and body
    rate; MAE and RMSE at each step, the cumulative MAE) for `constant velocity`, `nominal` and, where it has a
    world-frame form, `extended`; `note`: the short-horizon note (`dynax.internal.short_horizon_note`: the extended
    model predicts a group much worse than the nominal one step ahead), or `None`.
    """

    models: dict[str, SimulationError]
    note: str | None = None

    def to_json(self) -> dict:
        """`report.json`'s `flight_error` (and the CLI's `flight_error.json`): `steps`, `dt_s`, the `models`' MAE
        and RMSE per group (`SimulationError.scores`), and the `note` (`null` where there is none)."""
        first = next(iter(self.models.values()))
        return {
            "steps": list(first.steps or ()),
            "dt_s": first.dt,
            "models": {name: e.scores(("mae", "rmse")) for name, e in self.models.items()},
            "note": self.note,
        }

    def summary(self, metrics: tuple[str, ...] = ("mae",)) -> str:
        """The scores as lines of text for a person, one block per model (`SimulationError.summary`)."""
        lines = ["held-out error per group:"]
        for name, e in self.models.items():
            lines += ["  " + line for line in e.summary(name, metrics).splitlines()]
        return "\n".join(lines)


class Report(eqx.Module):
    """The result of `diagnose`. `to_json()` is the contract's `report.json`; `to_markdown()` is for a person.

    **Fields:** `system` (contract name), `data` (`DataSummary`), `mode`, `nominal` and `extended`
    (`ModelSummary`: parameters, held-out simulation error, `terms` of the extended model, and the
    `validation` block: fit % and residual tests), `verdict` (a `Verdict`: `explained`, `unexplained`, `none`,
    `inconclusive`; the rule is in `dynax._diagnose._verdict`),
    `findings` (most important first; dicts as in the contract, with extra keys), `gain`,
    `reference_horizon_s`, `structure` (`Structure` of the residual probe on the nominal and the
    extended model), `not_identifiable`, `not_proposed` (causes of the default vocabulary the records give no
    occasion to try, with the reason: a `stiction` where no joint rests under load), `candidates` (every
    candidate's held-out gain in the first
    round), `notes`, `horizon` (`Horizon`: the reference horizon and how it was chosen), `runs`
    (held-out error per run), `test` (the significance test, and with verdict `none` or `inconclusive`
    the gain it could have detected, the best candidate and the held-out length that would decide), `discovery`, the
    fitted models `nominal_model` and `extended_model`, and `rounds` (each round of the forward selection: every
    refitted candidate's held-out gains, p, and `selected`, `passed` or `stopped` with the rules that stopped it);
    for a quadrotor `flight_error` (`FlightScores`: the held-out scores per group of the nominal and extended models
    and of constant velocity, and the short-horizon note, which `notes` carries too), else `None`; `warnings`: the
    command line's list of what the run warned of and noted (`report.json`'s `warnings`, see docs/cli.md), `None`
    from Python, whose caller receives them as Python warnings.
    """

    system: str
    data: DataSummary
    mode: str
    nominal: ModelSummary
    verdict: Verdict
    findings: list
    extended: ModelSummary
    gain: float
    reference_horizon_s: float
    structure: dict[str, Structure]
    not_identifiable: list
    candidates: list
    notes: list
    horizon: Horizon
    runs: list
    test: dict
    nominal_model: AbstractSystem
    extended_model: AbstractSystem
    discovery: dict = eqx.field(default_factory=dict)
    rounds: list = eqx.field(default_factory=list)
    not_proposed: list = eqx.field(default_factory=list)
    flight_error: FlightScores | None = None
    warnings: list | None = None

    def to_json(self) -> dict:
        """The contract's `report.json` (section 3), with extra keys after the contract's."""
        extended = self.extended.to_json()
        extended.setdefault("terms", [])
        return {
            "system": self.system,
            "data": self.data.to_json(),
            "nominal": self.nominal.to_json(),
            "verdict": str(Verdict(self.verdict)),
            "findings": self.findings,
            "extended": extended,
            "gain": self.gain,
            "reference_horizon_s": self.reference_horizon_s,
            "mode": self.mode,
            "structure": {k: structure_json(v) for k, v in self.structure.items()},
            "not_identifiable": self.not_identifiable,
            "not_proposed": self.not_proposed,
            "candidates": self.candidates,
            "notes": self.notes,
            "horizon": self.horizon.to_json(),
            "runs": self.runs,
            "test": self.test,
            **({"discovery": self.discovery} if self.discovery else {}),
            "rounds": self.rounds,
            **({"flight_error": self.flight_error.to_json()} if self.flight_error is not None else {}),
            **({"warnings": self.warnings} if self.warnings is not None else {}),
        }

    def to_markdown(self) -> str:
        from ._report import report_markdown

        return report_markdown(self)
