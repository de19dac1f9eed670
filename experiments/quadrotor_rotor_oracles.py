"""Battery sag and ground effect hidden in synthetic flights: how much held-out gain is there to find?

For each hidden effect, fits the rigid-body nominal model (one-step least squares) on the training
flights and scores on the held-out flight, at 0.1 and 0.5 s, (a) the nominal, (b) the nominal's motor
map held with the true effect added at its true size (the candidate's best case in a diagnosis that
holds the map), and (c) the oracle: the model family that has the effect, its map fitted one-step with
it (battery sag: the motor map that reads `vbat`). The gain is the relative drop of the position MAE
at 0.5 s against the nominal's.

Run: `python experiments/quadrotor_rotor_oracles.py [--case sag|ground|all]`; writes
`experiments/results/quadrotor_rotor_oracles/oracles.json`.
"""

import argparse
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import dynax
from dynax.internal import body_frame_system, write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.quadrotor.synthetic_flight import quadrotor_flight  # noqa: E402

STEPS = (10, 50)
ALTITUDE = 0.07  # the low flights' mean height over the floor [m]


def _world(body, like):
    from dynax.internal import WorldFrameQuadrotor

    return WorldFrameQuadrotor(body, like.input_scale)


def _score(model, flights):
    err = dynax.flight_error(model, flights, STEPS)
    groups = list(err.state_names)
    mae = err.mae_per_state
    return {g: [float(mae[k][i]) for k in range(len(STEPS))] for i, g in enumerate(groups)}


def case(name, train, validation, battery, term):
    t0 = time.perf_counter()
    quad = dynax.fit_quadrotor(
        dynax.Quadrotor.from_flights("nominal", train, battery=battery), train, dynax.OneStep()
    ).model
    body = body_frame_system(quad, train[0].input_names)
    out = {"nominal": _score(_world(body, quad), validation)}
    out["held map + true term"] = _score(_world(dynax.Extended(body, (term,)), quad), validation)
    if name == "sag":
        oracle = dynax.fit_quadrotor(
            dynax.Quadrotor.from_flights("nominal", train, battery=True), train, dynax.OneStep()
        )
        out["oracle (map reads vbat)"] = _score(oracle.model, validation)
    nominal = out["nominal"]["position"][-1]
    for k, v in out.items():
        print(
            f"{name:7s} {k:28s} pos@0.1 {v['position'][0] * 1e3:7.2f} mm  pos@0.5 {v['position'][-1] * 1e3:7.2f} mm  "
            f"rate@0.5 {v['body_rate'][-1]:.3f}  gain {1 - v['position'][-1] / nominal:+.1%}"
        )
    print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", default="all")
    args = parser.parse_args()
    results = {}
    if args.case in ("sag", "all"):  # the designs of tests/quadrotor/test_rotor_terms.py
        train = [quadrotor_flight(15.0, seed=5, sag=(4.2, 3.9)), quadrotor_flight(15.0, seed=15, sag=(3.8, 3.5))]
        validation = [quadrotor_flight(20.0, seed=105, sag=(4.1, 3.6))]
        results["sag"] = case("sag", train, validation, False, dynax.BatterySag(2.0))
    if args.case in ("ground", "all"):
        train = [
            quadrotor_flight(15.0, seed=6, ground=0.08),
            quadrotor_flight(15.0, seed=16, altitude=ALTITUDE, ground=0.08),
        ]
        validation = [quadrotor_flight(15.0, seed=s, altitude=ALTITUDE, ground=0.08) for s in (106, 126)]
        results["ground"] = case("ground", train, validation, None, dynax.GroundEffect(0.08**2 / 16, floor=0.0))
    out = pathlib.Path("experiments/results/quadrotor_rotor_oracles")
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "oracles.json", results)


if __name__ == "__main__":
    main()
