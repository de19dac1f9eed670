"""What scoring the held-out flights per group adds to a quadrotor diagnosis.

`dynax.diagnose` on a `Quadrotor` ends by scoring its held-out flights per group at 1, 10 and 50 steps:
the nominal and extended models and constant velocity (`dynax.internal.quadrotor_flight_errors`, the
report's `flight_error`), and the short-horizon note. This times that step on the held-out stretches of
`experiments/nanobench_diagnosis.py --slice-s 8 --max-terms 2` (8 s from the middle of each star, trefoil
and oval run of at least 1000 samples) with that diagnosis's models: the rigid body's one-step fit on the
training slices and, extended, the two rate dampings it names (`rotor_drag@q`, `@p`; their coefficients
are arguments). Cold (a fresh process: every program compiled on the way, what a diagnosis pays) and warm
(compiled once already), wall and CPU time.

Run: `python benchmarks/flight_scoring.py [--slice-s S] [--drag-q D] [--drag-p D] [--out DIR]` (default DIR
`benchmarks/results`). Writes `DIR/flight_scoring.json`. Timings on a shared CPU are indicative; run it on
an idle 2-core machine for the figure of record (`taskset -c 0,1`).
"""

import argparse
import pathlib
import sys
import time
import types

import jax

jax.config.update("jax_enable_x64", True)

import dynax
from dynax.internal import body_frame_system, quadrotor_flight_errors, short_horizon_note, write_json

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "experiments"))
sys.path.insert(0, str(HERE))
from _device import describe, device_info  # noqa: E402
from nanobench_diagnosis import middle  # noqa: E402
from nanobench_heldout import flights, TEST, TRAIN  # noqa: E402


def timed(call):
    wall, cpu = time.perf_counter(), time.process_time()
    out = call()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--slice-s", type=float, default=8.0, help="seconds from the middle of each run (0: whole)")
    parser.add_argument("--drag-q", type=float, default=117.18, help="the extended model's rate damping on q [1/s]")
    parser.add_argument("--drag-p", type=float, default=65.88, help="the extended model's rate damping on p [1/s]")
    parser.add_argument("--out", default="benchmarks/results")
    args = parser.parse_args()

    def cut(runs):
        return [middle(r, args.slice_s) if args.slice_s > 0 else r for r in runs if len(r) >= 1000]

    train, test = cut(flights(TRAIN)[0]), cut(flights(TEST)[0])
    quad = dynax.fit_quadrotor(dynax.Quadrotor.from_flights("nominal", train), train).model
    body = body_frame_system(quad, train[0].input_names)
    extended = dynax.Extended(body, (dynax.RotorDrag(4, args.drag_q), dynax.RotorDrag(3, args.drag_p)))
    labels = ["rotor_drag@q", "rotor_drag@p"]
    report = types.SimpleNamespace(nominal_model=body, extended_model=extended, findings=[])

    def score():
        errors = quadrotor_flight_errors(report, quad, test, (1, 10, 50))
        return errors, short_horizon_note(errors, labels)

    (errors, note), cold_wall, cold_cpu = timed(score)
    _, warm_wall, warm_cpu = timed(score)
    result = {
        "device": device_info(),
        "slice_s": args.slice_s,
        "held_out_runs": len(test),
        "held_out_samples": sum(len(r) for r in test),
        "cold": {"wall_s": cold_wall, "cpu_s": cold_cpu},
        "warm": {"wall_s": warm_wall, "cpu_s": warm_cpu},
        "mae": {name: e.table("mae") for name, e in errors.items()},
        "note": note,
    }
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "flight_scoring.json", result)
    print(describe(result["device"]))
    print(
        f"{len(test)} held-out runs, {result['held_out_samples']} samples: cold {cold_wall:.1f} s ({cold_cpu:.1f} s "
        f"CPU), warm {warm_wall:.2f} s ({warm_cpu:.2f} s CPU); note: {'yes' if note else 'none'}"
    )


if __name__ == "__main__":
    main()
