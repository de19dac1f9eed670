"""How often the held-out length an `inconclusive` verdict states would detect the gain it speaks of.

The verdict's `needed_s` (and `observed_needed_s`) is the held-out length at which the paired test would detect a
25 % gain with 80 % power (`dynax._diagnose._statistics.length_for_shift`). This study checks the statement by
simulating the test it speaks of, on window differences made here (AR(1), independent of any dynax model): for each
configuration (held-out runs, windows per run, the candidates' level), a pilot record gives the test's degrees of
freedom; the true standard error of the mean (AR(1) long-run variance) gives the stated length; records of that
length whose mean shifts by the 25 % gain are tested `TRIALS` times. It reports the detection rate at the length
stated now (degrees of freedom growing with the runs) and at the length holding the degrees of freedom fixed
(the rule until 2026-12-02).

Run: `python experiments/power_length.py [--trials N]` (about a minute); writes
`experiments/results/power_length/{rates.json,rates.png}`.
"""

import argparse
import json
import pathlib
import sys

import numpy as np

from dynax.internal import detectable_shift, length_for_shift, paired_block_test

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.reference import ar1_runs  # noqa: E402

OUT = pathlib.Path(__file__).parent / "results" / "power_length"
PHI, LAGS, POWER = 0.5, 4, 0.8
SHIFT = -np.log(0.75)  # a 25 % gain in mean squared window error
CONFIGS = [  # (held-out runs, windows per run, level: 0.01 over the candidates tested)
    (1, 40, 0.01 / 10),
    (1, 120, 0.01 / 10),
    (2, 40, 0.01 / 4),
    (3, 40, 0.01 / 2),
    (3, 40, 0.01 / 20),
    (3, 120, 0.01 / 20),
    (6, 60, 0.01 / 20),
    (8, 200, 0.01 / 20),
]


def rate(rng, runs, windows, level, trials):
    hits = sum(
        paired_block_test(*ar1_runs(rng, runs, windows, PHI, SHIFT), overlap=1, batch=LAGS).p_value < level
        for _ in range(trials)
    )
    return hits / trials


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=400)
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    rows = []
    for i, (runs, windows, level) in enumerate(CONFIGS, 1):
        pilot = paired_block_test(*ar1_runs(rng, runs, windows, PHI, 0.0), overlap=1, batch=LAGS)
        se = np.sqrt(1 / (1 - PHI) ** 2 / (runs * windows))
        now = length_for_shift(SHIFT, se, pilot.df, pilot.df_offset, level, POWER)
        held = (detectable_shift(se, pilot.df, level, POWER) / SHIFT) ** 2
        row = {
            "runs": runs,
            "windows": windows,
            "level": level,
            "df": pilot.df,
            "df_offset": pilot.df_offset,
            "factor_now": now,
            "factor_df_held": held,
            "rate_now": rate(rng, runs, max(int(round(now * windows)), 3 * LAGS), level, args.trials),
            "rate_df_held": rate(rng, runs, max(int(round(held * windows)), 3 * LAGS), level, args.trials),
        }
        rows.append(row)
        print(
            f"[{i}/{len(CONFIGS)}] {runs} run(s) x {windows} windows, level {level:.2g}, df {pilot.df:.1f}: "
            f"stated x{now:.2f} detects {row['rate_now']:.0%}; df held x{held:.2f} detects {row['rate_df_held']:.0%}",
            flush=True,
        )
    OUT.mkdir(parents=True, exist_ok=True)
    summary = {"power": POWER, "trials": args.trials, "ar1_phi": PHI, "lag_window": LAGS, "rows": rows}
    (OUT / "rates.json").write_text(json.dumps(summary, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["rate_now"] for r in rows], 0.4, label="stated length (df grows with the runs)")
    ax.bar(x + 0.2, [r["rate_df_held"] for r in rows], 0.4, label="df held fixed (until 2026-12-02)")
    ax.axhline(POWER, color="k", lw=0.8, ls="--")
    ax.set_xticks(x, [f"{r['runs']}x{r['windows']}\ndf {r['df']:.0f}" for r in rows], fontsize=7)
    ax.set_ylabel("detection rate of a 25 % gain")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(OUT / "rates.png", dpi=120)
    print(f"wrote {OUT / 'rates.json'} and rates.png")


if __name__ == "__main__":
    main()
