"""The NanoBench flights' motor and battery levels in flight: the spread behind `load_flights`' refusal of
flights given together whose motors or battery are logged in different units (`check_input_levels`).

For each flight, loaded as `dynax fit quadrotor` loads it, the median over its usable samples of the mean motor
command and of the battery voltage (`dynax.internal.input_levels`), and their ratio to the median of all 16;
then whether `check_input_levels` accepts the 16 together, and what it says of the star flight with its motors
in percent of the 16-bit range, or its battery in millivolts, among the other 15.

    nice -n 5 python experiments/flight_input_levels.py [OUT]

Writes `OUT/levels.json` (default `experiments/results/flight_input_levels`) and prints the table.
"""

import pathlib
import sys
import warnings

import numpy as np

import dynax
from dynax.internal import check_input_levels, input_levels, write_json

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from nanobench_heldout import DATA, NANOBENCH_MAP  # noqa: E402


def main():
    out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "experiments/results/flight_input_levels")
    warnings.simplefilter("ignore", dynax.DataWarning)
    levels = {}
    for path in sorted(DATA.glob("*.csv.gz")):
        trajectory, notes = dynax.load_flight(path, mapping=NANOBENCH_MAP)
        levels[path.name] = input_levels(trajectory, notes.usable)
    median = {k: float(np.median([v[k] for v in levels.values()])) for k in ("m1", "vbat")}
    for name, found in levels.items():
        print(
            f"{name:34s} motors {found['m1']:8.0f} ({found['m1'] / median['m1']:.3f})  "
            f"vbat {found['vbat']:.3f} V ({found['vbat'] / median['vbat']:.3f})"
        )
    spread = {k: float(max(abs(np.log(v[k] / median[k])) for v in levels.values())) for k in median}
    print("largest ratio to the median: " + ", ".join(f"{k} {np.exp(v):.3f}" for k, v in spread.items()))
    answers = {}
    for label, edit in (
        ("all 16 as logged", {}),
        ("star in percent", {"m1": 100 / 65535}),
        ("star in mV", {"vbat": 1e3}),
    ):
        given = {n: dict(v) for n, v in levels.items()}
        for key, factor in edit.items():
            given["B8_star_fast_rep1.csv.gz"][key] *= factor
        try:
            check_input_levels(given, columns=NANOBENCH_MAP)
            answers[label] = "accepted"
        except dynax.DataError as e:
            answers[label] = f"refused: {e}"
        print(f"{label}: {answers[label]}")
    write_json(out / "levels.json", {"levels": levels, "median": median, "largest_ratio": spread, "answers": answers})
    print(f"written to {out / 'levels.json'}")


if __name__ == "__main__":
    main()
