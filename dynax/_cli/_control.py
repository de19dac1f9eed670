"""`dynax control`: tune a from-rest acrobot swing-up for the RealAIGym leaderboard, and score one."""

import argparse
import json
import math
import pathlib
import time

from .._errors import UsageError


def register(subparsers):
    parser = subparsers.add_parser(
        "control",
        help="tune and score acrobot swing-up controllers (RealAIGym leaderboard rules)",
        description=(
            "`dynax control acrobot --out POLICY.npz` designs a swing-up from the hanging rest for the "
            "RealAIGym acrobot (a reference by many-start direct collocation against the score, time-varying "
            "LQR, LQR balance with an energy-shaping recovery; minutes on 2 CPU cores) and saves it; "
            "`dynax control evaluate POLICY.npz` scores a saved controller by the "
            "leaderboard's rules: the performance score on the nominal plant and the robustness score "
            "over the six perturbation families."
        ),
    )
    sub = parser.add_subparsers(dest="control_command", metavar="ACTION")
    sub.required = True
    tune = sub.add_parser("acrobot", help="design a from-rest swing-up and save it (.npz)")
    tune.add_argument("--out", required=True, help="the controller file to write (.npz)")
    tune.add_argument("--horizon", type=float, default=None, help="length of the swing-up reference [s] (default 1.5)")
    tune.add_argument(
        "--starts", type=int, default=None, help="how many pumping patterns start the collocation (default all 16)"
    )
    tune.add_argument(
        "--iterations", type=int, default=None, help="Adam steps per augmented-Lagrangian round (default 200)"
    )
    tune.add_argument(
        "--seed",
        type=int,
        default=0,
        help="0: the pumping patterns as they are; N > 0: their amplitudes drawn at random",
    )
    tune.add_argument("--evaluate", action="store_true", help="score the result (adds about a minute)")
    tune.add_argument(
        "--reference",
        default=None,
        help="design the feedback around this saved controller's reference instead of searching for one (.npz)",
    )
    tune.set_defaults(run=run_tune)
    evaluate = sub.add_parser("evaluate", help="score a saved controller by the leaderboard's rules")
    evaluate.add_argument("policy", help="a controller saved by `dynax control acrobot`")
    evaluate.add_argument("--json", default=None, help="also write the scores to this JSON file")
    evaluate.add_argument("--performance-only", action="store_true", help="skip the robustness evaluation")
    evaluate.set_defaults(run=run_evaluate)


def _check_out(path: str, suffix: str, option: str) -> pathlib.Path:
    out = pathlib.Path(path)
    if out.suffix != suffix:
        raise UsageError(f"{option} must name a {suffix} file, got {path!r}")
    if out.is_dir():
        raise UsageError(f"{option} {path!r} is a directory")
    if not out.parent.is_dir():
        raise UsageError(f"{option} {path!r}: the directory {str(out.parent)!r} does not exist")
    return out


def run_tune(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import equinox as eqx

    from .._control._collocation import PumpingStarts, ReferenceSearch
    from .._control._from_rest import design_swing_up, load_controller, SwingUpDesign
    from .._control._leaderboard import LeaderboardRules

    out = _check_out(args.out, ".npz", "--out")
    reference = None
    if args.reference is not None:
        import jax.numpy as jnp

        saved = load_controller(args.reference)
        reference = (jnp.asarray(saved.x_ref), jnp.asarray(saved.u_ref))
    for name in ("horizon", "starts", "iterations"):
        value = getattr(args, name)
        if value is not None and not (value > 0 and math.isfinite(value)):  # NaN compares False both ways
            raise UsageError(f"--{name} must be a positive number, got {value}")
    episode = LeaderboardRules().t_final
    if args.horizon is not None and args.horizon > episode:
        raise UsageError(f"--horizon must be at most the leaderboard's episode, {episode} s, got {args.horizon}")
    if args.seed < 0:
        raise UsageError(f"--seed must be a non-negative integer, got {args.seed}")
    search = ReferenceSearch(starts=PumpingStarts(number=args.starts, seed=args.seed))
    if args.horizon is not None:
        n = round(args.horizon / search.knot_spacing)
        if n < 3 or abs(n * search.knot_spacing - args.horizon) > 1e-9:
            raise UsageError(
                f"--horizon must be a multiple of {search.knot_spacing} s (at least 3), got {args.horizon}"
            )
        search = eqx.tree_at(lambda s: s.horizon, search, args.horizon)
    if args.iterations is not None:
        stages = tuple(eqx.tree_at(lambda s: s.inner, st, args.iterations) for st in search.stages)
        search = eqx.tree_at(lambda s: s.stages, search, stages)
    design = SwingUpDesign(seed=args.seed)
    start = time.perf_counter()
    controller = design_swing_up(design=design, reference=reference, search=search)
    tmp = out.with_name(out.name + ".partial.npz")
    controller.save(tmp)
    tmp.replace(out)
    print(f"wrote {out} in {time.perf_counter() - start:.0f} s")
    if args.evaluate:
        _print_scores(_scores(controller, robust=True))
    return 0


def _scores(controller, robust: bool) -> dict:
    from .._control._leaderboard import performance, robustness

    perf = performance(controller)
    out = {"performance": perf.as_dict()}
    if robust:
        rob = robustness(controller)
        out["robustness"] = {"score": rob.score, "families": rob.table(), "seconds": rob.seconds}
    return out


def _print_scores(scores: dict) -> None:
    p = scores["performance"]
    print(
        f"performance {p['score']:.3f} (success {p['success']}; swing-up {p['swingup_time']:.2f} s, "
        f"energy {p['energy']:.2f} J, torque cost {p['torque_cost']:.2f}, smoothness {p['torque_smoothness']:.4f}, "
        f"velocity cost {p['velocity_cost']:.1f})"
    )
    if "robustness" in scores:
        r = scores["robustness"]
        table = ", ".join(f"{k} {100 * v:.1f} %" for k, v in r["families"].items())
        print(f"robustness {r['score']:.3f} ({table}; {r['seconds']:.0f} s)")


def run_evaluate(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from .._control._from_rest import load_controller

    json_out = _check_out(args.json, ".json", "--json") if args.json else None
    controller = load_controller(args.policy).to_benchmark()
    scores = _scores(controller, robust=not args.performance_only)
    _print_scores(scores)
    if json_out is not None:
        json_out.write_text(json.dumps(scores, indent=2))
    return 0
