"""The data checks on the six DFKI runs as a user loads them (`load_trajectory` with the rig's map, logged velocities).

    DYNAX_SHARED=../shared python experiments/dfki_data_checks.py

Prints every finding of `dynax.check_records` per run (on these runs: the logged velocities' `lag`, and the
`stamps` taken late by the rig's logger) and writes them to `experiments/results/dfki_data_checks.json`.
Data: DFKI RIC Underactuated Robotics Lab, `double_pendulum`, design C.0 (BSD-3-Clause), read from
`../shared/datasets/dfki_double_pendulum/sys_id/`.
"""

import json
import pathlib
import sys
import warnings

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from dfki_simulation import DFKI, MAPPING  # noqa: E402

import dynax  # noqa: E402

RUNS = ("00", "01", "02", "03", "05", "12")


def main() -> None:
    out = {}
    for run in RUNS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            record = dynax.load_trajectory(
                DFKI / "sys_id" / f"trajectory_{run}.csv", "double_pendulum", mapping=MAPPING, check=False
            )
        findings = dynax.check_records([record]).findings
        out[run] = [f.to_json() for f in findings]
        for f in findings:
            print(run, f.describe(), flush=True)
    path = pathlib.Path(__file__).resolve().parent / "results" / "dfki_data_checks.json"
    path.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
