"""What stands between the NanoBench diagnosis and a 20 % held-out gain: the score, the power, the physics, the map.

The NanoBench diagnosis (`experiments/nanobench_diagnosis.py`) names rate damping (`rotor_drag` at `p, q`) with a
held-out gain under 20 % of the 0.5 s position RMSE, and refits linear drag (`rotor_drag` at `u, v`) at 10-20
times a Crazyflie's 0.5-1 1/s. This experiment reads the candidates by hand, outside the diagnosis, on the same
stretches (8 s from the middle of each run of at least 1000 samples): the rigid body fitted one step at a time on
the training slices (the diagnosis's `Refit()` nominal), optionally also fitted by the lagged criterion at 0.5 s
(`--lagged`), each with one `rotor_drag` term (or a pair) added at a grid of coefficients, held-out windows every
0.05 s over 0.5 s as the diagnosis's test has them. For each model it reports:

- the position RMSE at 0.5 s (the report's gain) and its gain over the nominal;
- the window score the diagnosis tests and refits by (each state over its group's scale: the starting model's
  RMS open-loop error of position, attitude, body velocity, rates on the training windows,
  `dynax.internal.flight_state_scale`), its pooled and typical gains, the paired test's p (one candidate, no
  multiple-comparison correction), and each group's share of the gain;
- the same window score under the earlier scale (each state's spread over the training records).

Coefficients are chosen on the training slices, by the group score (what the diagnosis's refit minimises) and by
the position RMSE at 0.5 s; the chosen models are then scored on the whole held-out runs too (4.4 times the
slices' samples: what more held-out minutes would buy the test).

Run: `python experiments/nanobench_gain_reading.py [--lagged] [--out DIR]` (default
`experiments/results/nanobench_gain_reading`); writes `DIR/gain_reading.json` and prints a table per nominal.
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np

import dynax
from dynax.internal import (
    body_frame_records,
    body_frame_system,
    flight_state_scale,
    paired_block_test,
    vehicle_state_groups,
    window_simulation_errors,
    write_json,
)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_diagnosis import middle  # noqa: E402
from nanobench_heldout import flights, TEST, TRAIN  # noqa: E402

HORIZON_S = 0.5
STRIDE = 5  # windows every 0.05 s, as the diagnosis's
AXES = ("u", "v", "w", "p", "q", "r")
GRIDS = {
    "translation": (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0),
    "rotation": (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 40.0, 80.0),
}
CANDIDATES = (("u",), ("v",), ("w",), ("p",), ("q",), ("r",), ("u", "v"), ("p", "q"))
GROUP_NAMES = ("position", "attitude", "body_velocity", "body_rate")


def errors_of(system, records):
    """`(windows, steps, states)` simulated minus measured on every record, windows every 0.05 s, and each window's
    record index."""
    out, runs = [], []
    for i, rec in enumerate(records):
        e = np.asarray(window_simulation_errors(system, rec, (HORIZON_S,), stride=STRIDE, max_windows=100_000))
        out.append(e)
        runs.append(np.full(e.shape[0], i))
    return np.concatenate(out), np.concatenate(runs)


def log_ratio(ref, new):
    floor = 0.1 * float(np.median(ref))
    return np.log((ref + floor) / (new + floor))


class Reader:
    """Scores of one model's window errors against the nominal's."""

    def __init__(self, body, train_records, n_ref, position, groups):
        self.n_ref, self.position, self.groups = n_ref, position, groups
        dt = float(train_records[0].dt)
        scale = flight_state_scale(body, train_records, HORIZON_S, dt, groups)
        if scale is None:
            raise SystemExit("the starting model diverges on most training windows: no group scale")
        self.group_scale = scale
        self.spread_scale = np.maximum(np.concatenate([np.asarray(r.xs) for r in train_records]).std(axis=0), 1e-9)

    def window_scores(self, e, scale):
        z = np.nan_to_num(e[:, 1 : self.n_ref + 1] / scale, nan=1e3, posinf=1e3, neginf=1e3)
        return np.mean(np.minimum(z**2, 1e6), axis=(1, 2))

    def position_rmse(self, e):
        at = e[:, self.n_ref][:, self.position]
        finite = np.isfinite(at).all(axis=1)
        return float(np.sqrt(np.mean(at[finite] ** 2))) if finite.mean() >= 0.95 else float("inf")

    def group_terms(self, e):
        """Each group's contribution to the mean window score (its states' mean squared scaled error, summed)."""
        z = np.nan_to_num(e[:, 1 : self.n_ref + 1] / self.group_scale, nan=1e3, posinf=1e3, neginf=1e3)
        z2 = np.minimum(z**2, 1e6)
        n = z2.shape[-1]
        return {name: float(np.mean(z2[..., list(g)]) * len(g) / n) for name, g in zip(GROUP_NAMES, self.groups)}

    def read(self, e, runs, nominal=None):
        out = {
            "position_rmse": self.position_rmse(e),
            "group_score": float(np.mean(self.window_scores(e, self.group_scale))),
            "spread_score": float(np.mean(self.window_scores(e, self.spread_scale))),
            "group_terms": self.group_terms(e),
        }
        if nominal is not None:
            ne, _ = nominal
            out["position_gain"] = 1 - out["position_rmse"] / self.position_rmse(ne)
            for name, scale in (("group", self.group_scale), ("spread", self.spread_scale)):
                ref, new = self.window_scores(ne, scale), self.window_scores(e, scale)
                d = log_ratio(ref, new)
                test = paired_block_test(d, runs, self.n_ref // STRIDE)
                out[f"{name}_gain_pooled"] = float(1 - np.mean(new) / np.mean(ref))
                out[f"{name}_gain_typical"] = float(1 - np.exp(-np.mean(d)))
                out[f"{name}_p"] = float(test.p_value)
                out[f"{name}_t"] = float(test.mean / test.std_error) if test.std_error > 0 else float("nan")
            nt = self.group_terms(ne)
            total = sum(nt.values())
            out["group_gain_by_group"] = {k: (nt[k] - out["group_terms"][k]) / total for k in nt}
            out["group_own_gain"] = {k: 1 - out["group_terms"][k] / nt[k] for k in nt}
        return out


def extended(body, axes, d):
    if not axes:
        return body
    return dynax.Extended(body, tuple(dynax.RotorDrag(AXES.index(a), d) for a in axes))


def main():
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--out", default="experiments/results/nanobench_gain_reading")
    parser.add_argument("--slice-s", type=float, default=8.0)
    parser.add_argument("--min-samples", type=int, default=1000)
    parser.add_argument("--lagged", action="store_true", help="also the rigid body fitted by the lagged criterion")
    args = parser.parse_args()
    t0 = time.perf_counter()
    say = lambda line: print(f"[{time.perf_counter() - t0:7.1f} s] {line}", flush=True)  # noqa: E731

    train, _ = flights(TRAIN)
    test, _ = flights(TEST)
    train = [r for r in train if len(r) >= args.min_samples]
    test = [r for r in test if len(r) >= args.min_samples]
    cut = lambda runs: [middle(r, args.slice_s) for r in runs]  # noqa: E731
    d_train, d_test = cut(train), cut(test)
    say(
        f"{len(d_train)} training slices ({sum(map(len, d_train))} samples), {len(d_test)} held-out slices "
        f"({sum(map(len, d_test))} samples), whole held-out runs {sum(map(len, test))} samples"
    )
    start = dynax.Quadrotor.from_flights("nominal", train)
    nominals = {"one-step": dynax.fit_quadrotor(start, d_train, dynax.OneStep()).model}
    say("one-step nominal fitted")
    if args.lagged:
        lagged = dynax.Lagged(horizon=HORIZON_S, stride=20, max_iterations=10)
        nominals["lagged"] = dynax.fit_quadrotor(start, d_train, lagged).model
        say("lagged nominal fitted")

    result = {
        "train": sorted({r.source for r in train}),
        "test": sorted({r.source for r in test}),
        "slice_s": args.slice_s,
        "samples": {"train": sum(map(len, d_train)), "test": sum(map(len, d_test)), "test_whole": sum(map(len, test))},
        "grids": GRIDS,
        "nominals": {},
    }
    for label, quad in nominals.items():
        body = body_frame_system(quad, train[0].input_names)
        tr, te, te_whole = (body_frame_records(quad, x) for x in (d_train, d_test, test))
        dt = float(tr[0].dt)
        n_ref = int(round(HORIZON_S / dt))
        groups = vehicle_state_groups(body)
        reader = Reader(body, tr, n_ref, list(body.position_indices), groups)
        say(
            f"{label}: group scales {[float(reader.group_scale[list(g)[0]]) for g in groups]} "
            f"({', '.join(GROUP_NAMES)})"
        )
        nom_tr, nom_te, nom_whole = errors_of(body, tr), errors_of(body, te), errors_of(body, te_whole)
        entry = {
            "group_scale": {n: float(reader.group_scale[list(g)[0]]) for n, g in zip(GROUP_NAMES, groups)},
            "nominal": {
                "train": reader.read(*nom_tr),
                "test": reader.read(*nom_te),
                "test_whole": reader.read(*nom_whole),
            },
            "candidates": {},
        }
        for axes in CANDIDATES:
            name = "rotor_drag@" + "+".join(axes)
            grid = GRIDS["translation" if axes[0] in "uvw" else "rotation"]
            rows = []
            for d in grid:
                model = extended(body, axes, d)
                e_tr, e_te = errors_of(model, tr), errors_of(model, te)
                rows.append(
                    {"d": d, "train": reader.read(*e_tr, nominal=nom_tr), "test": reader.read(*e_te, nominal=nom_te)}
                )
                r = rows[-1]
                say(
                    f"{label} {name} d={d:g}: train group {r['train']['group_gain_pooled']:+.1%} pos "
                    f"{r['train']['position_gain']:+.1%} | held-out pos {r['test']['position_gain']:+.1%} group "
                    f"{r['test']['group_gain_pooled']:+.1%} (typ {r['test']['group_gain_typical']:+.1%}, p "
                    f"{r['test']['group_p']:.2g}) spread {r['test']['spread_gain_pooled']:+.1%} by group "
                    + " ".join(f"{k[:4]} {v:+.1%}" for k, v in r["test"]["group_own_gain"].items())
                )
            chosen = {}
            for by, key in (("group_score", "group_score"), ("position_rmse", "position_rmse")):
                best = min(rows, key=lambda r: r["train"][key])
                model = extended(body, axes, best["d"])
                chosen[by] = {
                    "d": best["d"],
                    "test": best["test"],
                    "test_whole": reader.read(*errors_of(model, te_whole), nominal=nom_whole),
                }
                w = chosen[by]["test_whole"]
                say(
                    f"  chosen by training {by}: d={best['d']:g}; held-out slices pos "
                    f"{best['test']['position_gain']:+.1%} (group p {best['test']['group_p']:.2g}); whole runs pos "
                    f"{w['position_gain']:+.1%} group {w['group_gain_pooled']:+.1%} (p {w['group_p']:.2g}, t "
                    f"{w['group_t']:.1f} against {best['test']['group_t']:.1f} on the slices)"
                )
            best_test = max(rows, key=lambda r: r["test"]["position_gain"])
            entry["candidates"][name] = {
                "grid": rows,
                "chosen": chosen,
                "best_held_out_position_gain": {"d": best_test["d"], "gain": best_test["test"]["position_gain"]},
            }
        result["nominals"][label] = entry
    result["seconds"] = time.perf_counter() - t0
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "gain_reading.json", result)
    say(f"wrote {out / 'gain_reading.json'}")


if __name__ == "__main__":
    main()
