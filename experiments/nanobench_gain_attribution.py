"""Which physical terms carry the lagged acceleration model's 0.5 s gain over the rigid body on NanoBench.

The lagged acceleration model predicts the held-out star, trefoil and oval flights 0.5 s ahead far better
than the rigid-body nominal model fitted by the same criterion (`experiments/nanobench_heldout.py`). It
differs from the nominal model by seven groups of body-frame terms (`Quadrotor.from_flights`'s
`acceleration` family):

- linear drag: $u, v, w$ on their own axes (rotor drag, linear in velocity);
- thrust-scaled drag: $u\\sum m, v\\sum m, w\\sum m$ (rotor drag in proportion to the rotors' speed);
- quadratic drag: $|u|u, |v|v, |w|w$ (the airframe's);
- body force bias: a constant on $u, v, w$;
- rate damping: $p, q, r$ on their own axes;
- velocity-to-moment: $v$ on $p$, $u$ on $q$ (the rotors' flapping moment);
- moment bias: a constant on $p, q, r$.

Every model here is the acceleration model's layout with some terms masked out (zero), fitted on
the circle, figure-eight, helix, linear-ramp and lissajous flights and scored on the star, trefoil and oval
flights as in `nanobench_heldout.py` (its loaders; MAE and RMSE per group at h = 1, 10, 50):

- `nominal (one-step)`: the rigid body fitted one step ahead (the model the diagnosis holds);
- `nominal (lagged)`: the same terms fitted by the lagged criterion (H = 0.5 s): the motor map refitted;
- `acceleration (lagged)`: every group;
- `nominal + G (lagged)`: one group added to the rigid body, all weights fitted;
- `acceleration - G (lagged)`: one group taken out of the acceleration model;
- `one-step map + G (lagged)`: the rigid body's weights held at the one-step fit and only group G fitted
  by the lagged criterion (what a diagnosis that holds the one-step motor map can find);
- `one-step map + G + moment weights refitted (lagged)`: as the last, with the roll, pitch and yaw motor weights
  refitted too (what `Refit(parameters=...)` over the moment weights can find), beside `one-step map +
  moment weights refitted (lagged)`, the same without G (that refit's own reference);
- `lagged map + G (lagged)`: the rigid body's weights held at its lagged fit and only G fitted (what a
  diagnosis of the lagged rigid body, trusted with `Known()`, can find);
- `nominal + rate damping + linear drag (lagged)`, `acceleration - velocity drag (lagged)` (all three drag
  groups out): the two largest groups together, and the drag groups, which stand in for each other.

A held weight cannot be masked out (the mask says which weights a body model uses, and a criterion fits every
weight it uses), so the "map" plans move the held weights into the known part of the model (`HeldMap`).

Run: `python experiments/nanobench_gain_attribution.py [--out DIR] [--plans NAME,...] [--merge]` (default DIR
`experiments/results/nanobench_gain_attribution`; about 20 minutes on a shared two-core machine). Writes
`DIR/attribution.json` after each model (the position, velocity, attitude and body-rate scores, the fitted
weights of the added terms, the fit time) and `DIR/attribution.png` (held-out position and body-rate MAE at
0.5 s per model).
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import dynax
from dynax.internal import write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import flights, HORIZON_S, scores, STEPS, TEST, TRAIN  # noqa: E402

AXES = ("u", "v", "w", "p", "q", "r")
# The acceleration family's terms beyond the rigid body, by physical group: {axis: features}.
GROUPS = {
    "linear drag": {"u": ("u",), "v": ("v",), "w": ("w",)},
    "thrust-scaled drag": {"u": ("u sum(m)",), "v": ("v sum(m)",), "w": ("w sum(m)",)},
    "quadratic drag": {"u": ("|u|u",), "v": ("|v|v",), "w": ("|w|w",)},
    "body force bias": {"u": ("1",), "v": ("1",), "w": ("1",)},
    "rate damping": {"p": ("p",), "q": ("q",), "r": ("r",)},
    "velocity-to-moment": {"p": ("v",), "q": ("u",)},
    "moment bias": {"p": ("1",), "q": ("1",), "r": ("1",)},
}


def entries(body) -> set[tuple[str, str]]:
    """The (axis, feature) pairs a body model uses."""
    return {(a, f) for a, row in zip(AXES, body.mask) for f, used in zip(body.feature_names, row) if used}


def group_entries(group: str) -> set[tuple[str, str]]:
    return {(a, f) for a, fs in GROUPS[group].items() for f in fs}


class HeldMap(dynax.AccelerationModel):
    """An acceleration model with some weights held: `held` (6 x features, zero at the free entries) adds its terms
    to the known part, so that a criterion fits the masked weights with the held ones in place (the mask says which
    weights a body model uses and fits alike)."""

    held: jax.Array = eqx.field(default=None)

    def known(self, quat, s, u):
        return super().known(quat, s, u) + self.held @ self.features(quat, s, u)


def with_terms(layout: dynax.Quadrotor, free: set[tuple[str, str]], weights=None) -> dynax.Quadrotor:
    """`layout` (the acceleration family) with only the `free` terms fitted, starting from `weights`'s values
    ((axis, feature) -> value, zero where absent); with `weights` the other terms are held at their values."""
    body = layout.body_model
    assert free <= entries(body), free - entries(body)
    mask = tuple(tuple((a, f) in free for f in body.feature_names) for a in AXES)
    w = np.zeros((len(AXES), len(body.feature_names)))
    for (a, f), value in (weights or {}).items():
        w[AXES.index(a), body.feature_names.index(f)] = value
    m = np.asarray(mask, bool)
    kwargs = dict(weights=jnp.asarray(w * m), feature_names=body.feature_names, mask=mask, gravity=body.gravity)
    if weights is None:
        return layout.with_body_model(dynax.AccelerationModel(**kwargs))
    return layout.with_body_model(HeldMap(**kwargs, held=jnp.asarray(w * ~m)))


def weights_of(quad: dynax.Quadrotor) -> dict[tuple[str, str], float]:
    """Every weight the model uses, fitted or held: (axis, feature) -> value."""
    body = quad.body_model
    w = np.asarray(body.masked_weights()) + (np.asarray(body.held) if isinstance(body, HeldMap) else 0.0)
    return {
        (a, f): float(w[i, j]) for i, a in enumerate(AXES) for j, f in enumerate(body.feature_names) if w[i, j] != 0
    }


def is_moment_motor_weight(entry: tuple[str, str]) -> bool:
    axis, feature = entry
    return axis in ("p", "q", "r") and any(f"m{i}" in feature for i in range(1, 5))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="experiments/results/nanobench_gain_attribution")
    parser.add_argument("--stride", type=int, default=20, help="lagged fit: every N-th start (default 20)")
    parser.add_argument("--plans", default="", help="comma-separated model names to fit (default all)")
    parser.add_argument(
        "--merge", action="store_true", help="keep the other models' rows of an earlier DIR/attribution.json"
    )
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    begin = time.perf_counter()

    train, _ = flights(TRAIN)
    test, _ = flights(TEST)
    print(
        f"train: {len(train)} runs, {sum(len(r) for r in train)} samples; "
        f"test: {len(test)} runs, {sum(len(r) for r in test)} samples",
        flush=True,
    )
    layout = dynax.Quadrotor.from_flights("acceleration", train)
    nominal = entries(dynax.Quadrotor.from_flights("nominal", train).body_model)
    every = entries(layout.body_model)
    lagged = dynax.Lagged(horizon=HORIZON_S, stride=args.stride, max_iterations=10)

    held = {"nominal (one-step)": {}, "nominal (lagged)": {}}  # the rigid body's fits: the held maps of the last plans
    one_step = held["nominal (one-step)"]

    def plans():
        yield "nominal (one-step)", lambda: (with_terms(layout, nominal), dynax.OneStep(), False), ()
        yield "nominal (lagged)", lambda: (with_terms(layout, nominal), lagged, False), ()
        yield "acceleration (lagged)", lambda: (with_terms(layout, every), lagged, False), tuple(GROUPS)
        order = ("rate damping", "linear drag", *(g for g in GROUPS if g not in ("rate damping", "linear drag")))
        for g in order:
            yield (
                f"nominal + {g} (lagged)",
                lambda g=g: (with_terms(layout, nominal | group_entries(g)), lagged, False),
                (g,),
            )
            yield (
                f"acceleration - {g} (lagged)",
                lambda g=g: (with_terms(layout, every - group_entries(g)), lagged, False),
                tuple(h for h in GROUPS if h != g),
            )
        drag = ("linear drag", "thrust-scaled drag", "quadratic drag")
        both = ("rate damping", "linear drag")
        pair = group_entries(both[0]) | group_entries(both[1])
        yield (
            "nominal + rate damping + linear drag (lagged)",
            lambda: (with_terms(layout, nominal | pair), lagged, False),
            both,
        )
        yield (
            "acceleration - velocity drag (lagged)",
            lambda: (with_terms(layout, every - set().union(*map(group_entries, drag))), lagged, False),
            tuple(h for h in GROUPS if h not in drag),
        )
        moments = {e for e in nominal if is_moment_motor_weight(e)}
        for g in ("rate damping", "linear drag"):
            yield (
                f"one-step map + {g} (lagged)",
                lambda g=g: (with_terms(layout, group_entries(g), one_step), lagged, True),
                (g,),
            )
            yield (
                f"one-step map + {g} + moment weights refitted (lagged)",
                lambda g=g: (with_terms(layout, group_entries(g) | moments, one_step), lagged, True),
                (g,),
            )
        yield (
            "one-step map + moment weights refitted (lagged)",
            lambda: (with_terms(layout, moments, one_step), lagged, True),
            (),
        )
        for g in ("rate damping", "linear drag"):
            yield (
                f"lagged map + {g} (lagged)",
                lambda g=g: (with_terms(layout, group_entries(g), held["nominal (lagged)"]), lagged, True),
                (g,),
            )

    wanted = {p.strip() for p in args.plans.split(",") if p.strip()}
    table = {"constant velocity": scores(dynax.flight_error(dynax.ConstantVelocity(), test, STEPS))}
    if args.merge and (out / "attribution.json").exists():
        import json

        table = json.loads((out / "attribution.json").read_text())["table"] | table
    for name, make, groups in plans():
        if wanted and name not in wanted and name not in held:
            continue
        start = time.perf_counter()
        system, criterion, warm = make()
        solution = dynax.fit_quadrotor(system, train, criterion, warm_start=warm)
        seconds = time.perf_counter() - start
        if name in held:
            held[name].update(weights_of(solution.model))
        row = scores(dynax.flight_error(solution.model, test, STEPS))
        fitted = weights_of(solution.model)
        row.update(
            fit_seconds=seconds,
            groups=list(groups),
            n_free=int(solution.value.shape[0]),
            added_weights={
                g: {f"d{a}/{f}": fitted.get((a, f), 0.0) for a, f in sorted(group_entries(g))} for g in groups
            },
        )
        table[name] = row
        mae, rmse = row["mae"], row["rmse"]
        print(
            f"[{time.perf_counter() - begin:7.1f} s] {name:52s} fit {seconds:6.1f} s  h=50: position MAE "
            f"{mae['position'][-1]:.4f} RMSE {rmse['position'][-1]:.4f} m, attitude {mae['attitude'][-1]:.4f} rad, "
            f"body rate {mae['body_rate'][-1]:.4f} rad/s",
            flush=True,
        )
        write_json(
            out / "attribution.json",
            {
                "train": list(TRAIN),
                "test": list(TEST),
                "steps": list(STEPS),
                "stride": args.stride,
                "groups": {g: {a: list(fs) for a, fs in axes.items()} for g, axes in GROUPS.items()},
                "table": table,
                "seconds": time.perf_counter() - begin,
            },
        )
    figure(table, out / "attribution.png")
    print(f"wrote {out} in {time.perf_counter() - begin:.0f} s", flush=True)


def colour(name: str) -> str:
    """Grey: the rigid body; blue: a group added to it; orange: the acceleration model less a group; green: a
    group added to a held map."""
    for prefix, c in (("nominal (", "tab:grey"), ("nominal +", "tab:blue"), ("acceleration", "tab:orange")):
        if name.startswith(prefix):
            return c
    return "tab:green"


def figure(table, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [n for n in table if n != "constant velocity"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 0.32 * len(names) + 1.5), sharey=True)
    y = np.arange(len(names))
    for ax, group, unit in zip(axes, ("position", "body_rate"), ("m", "rad/s")):
        values = [table[n]["mae"][group][-1] for n in names]
        colours = [colour(n) for n in names]
        ax.barh(y, values, color=colours)
        for ref in ("nominal (lagged)", "acceleration (lagged)"):
            if ref in table:
                ax.axvline(table[ref]["mae"][group][-1], color="k", lw=0.8, ls="--")
        ax.axvline(table["constant velocity"]["mae"][group][-1], color="tab:red", lw=0.8, ls=":")
        ax.set_xlabel(f"held-out {group.replace('_', ' ')} MAE at 0.5 s [{unit}]")
    axes[0].set_yticks(y, names, fontsize=8)
    axes[0].invert_yaxis()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
