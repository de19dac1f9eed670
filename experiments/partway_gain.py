"""How small a change of an input's gain part way through a record `identify` names (`_warn_if_input_scaled_partway`),
and how close clean records come to being named.

For each record set: the least-squares stage only (`identify(..., refine=False)`), the search's best stretch
(`dynax.internal.partway_search_seen`: its gain, and its squared error over the stage's, `ratio`, before any
gate; a stretch is named at 0.5 or less) and whether it warns. Faulted:
the elbow's torque multiplied by each gain from mid-record on, on DFKI run 00 and on a synthetic acrobot
(`dynax.synthetic.synthetic_trajectory`, 20 s at 100 Hz, default noise).

Run from the repository root: `python experiments/partway_gain.py [clean|gains|all]` (prints one line per case).
"""

import os
import pathlib
import sys
import warnings

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import dynax  # noqa: E402
import dynax.internal  # noqa: E402

REPO = pathlib.Path(__file__).resolve().parents[1]
SHARED = pathlib.Path(os.environ.get("DYNAX_SHARED", REPO.parent / "shared")) / "datasets"
MAPPING = dict(
    t="time", q1="pos_meas1", q2="pos_meas2", dq1="vel_meas1", dq2="vel_meas2", tau1="tau_meas1", tau2="tau_meas2"
)
RUNS = ("00", "01", "02", "03", "05", "12")
GAINS = (0.5, 0.7, 0.8, 0.9, 1.1, 1.25, 1.5, 2.0, -1.0)


def dfki(run):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return dynax.load_trajectory(
            SHARED / "dfki_double_pendulum" / "sys_id" / f"trajectory_{run}.csv",
            "double_pendulum",
            mapping=MAPPING,
            velocities="positions",
        )


def emps():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return dynax.load_trajectory(
            SHARED / "emps" / "DATA_EMPS.mat",
            "linear_axis",
            mapping={"t": "t", "q": "qm", "force": "vir"},
            scale={"force": 35.15065188},
        )


def acrobot():
    import dataclasses

    truth = dynax.Acrobot()
    record = dynax.synthetic.synthetic_trajectory(truth, duration=20.0, seed=3)
    return dataclasses.replace(record, source="acrobot.csv")


def scaled(record, gain, input_index, start_s):
    us = np.asarray(record.us).copy()
    us[np.asarray(record.ts) >= start_s, input_index] *= gain
    import dataclasses

    return dataclasses.replace(record, us=jnp.asarray(us))


def probe(system, records, friction):
    """`(best, said)`: the search's best stretch (`dynax.internal.PartwayStretch`: its gain, and `ratio`, the
    squared equation error it keeps over the stage's, before any gate) and the partway warnings given."""
    with warnings.catch_warnings(record=True) as caught, dynax.internal.partway_search_seen() as seen:
        warnings.simplefilter("always")
        dynax.identify(system, records, friction=friction, refine=False)
    said = [str(w.message) for w in caught if "looks scaled" in str(w.message) or "reversed fr" in str(w.message)]
    if not seen:
        return None, said
    best = seen[0]
    side = "after" if best.after else "before"
    return f"{best.input} {best.record} {side} row {best.row}: gain {best.gain:.3g}, ratio {best.ratio:.3f}", said


def main(which):
    pendulum, arm = dynax.DoublePendulum(), dynax.Acrobot()
    if which in ("clean", "all"):
        sets = {f"dfki {r}": [dfki(r)] for r in RUNS}
        sets["dfki 00-05"] = [dfki(r) for r in RUNS[:5]]
        sets["dfki 00-05,12"] = [dfki(r) for r in RUNS]
        for name, recs in sets.items():
            for friction in ("viscous", "coulomb"):
                print(name, friction, *probe(pendulum, recs, friction), flush=True)
        print("emps", *probe(dynax.LinearAxis(), [emps()], "coulomb"), flush=True)
        print("acrobot clean", *probe(arm, [acrobot()], "viscous"), flush=True)
    if which in ("gains", "all"):
        run, synthetic = dfki("00"), acrobot()
        for g in GAINS:
            print("dfki 00 tau2 x", g, "from 5 s:", *probe(pendulum, [scaled(run, g, 1, 5.0)], "coulomb"), flush=True)
            print(
                "acrobot tau2 x", g, "from 10 s:", *probe(arm, [scaled(synthetic, g, 0, 10.0)], "viscous"), flush=True
            )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "all")
