"""Feed the command line (and `simulate`) malformed inputs and tally what happens: issue 13's table.

Each case of `tests/cli/malformed_cases.py` (a careless or hostile user's input: corrupted files,
absurd options, unwritable outputs, degenerate records) runs through the console script's entry
point in its own folder, and is judged: refused correctly (exit 2, one line naming the problem,
nothing written), accepted correctly (exit 0, an output that passes an independent check), silent
failure (exit 0 with a wrong or non-finite answer, or a bad `simulate` call that returns), traceback
(an exception escaping as exit 1), refused badly (exit 2 but the message misses the point, or
something was written).

Run from the repository root: `python experiments/malformed_inputs.py [--code PATH] [--out FILE]`.
`--code` puts another checkout's `dynax` first on the path (e.g. the code before the fixes) so that
the same cases judge it; the default is this checkout. Writes a JSON list of outcomes to `--out`
(default `experiments/results/malformed_inputs/after.json`) and prints a Markdown table and the
counts. `--compare BEFORE.json AFTER.json` prints the two side by side instead of running anything.
"""

import argparse
import collections
import importlib.util
import json
import pathlib
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--code", default=str(REPO), help="checkout whose dynax is judged (default: this one)")
    parser.add_argument("--out", default=str(REPO / "experiments" / "results" / "malformed_inputs" / "after.json"))
    parser.add_argument("--only", default=None, help="comma-separated case ids")
    parser.add_argument("--compare", nargs=2, default=None, metavar=("BEFORE", "AFTER"))
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    sys.path.insert(0, str(pathlib.Path(args.code).resolve()))
    import jax

    jax.config.update("jax_enable_x64", True)
    import dynax
    from dynax.internal import cli_main

    print(f"judging dynax from {pathlib.Path(dynax.__file__).parent}", file=sys.stderr)
    spec = importlib.util.spec_from_file_location("malformed_cases", REPO / "tests" / "cli" / "malformed_cases.py")
    cases = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cases)

    only = set(args.only.split(",")) if args.only else None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        fixtures = cases.make_fixtures(tmp)
        for case in cases.CASES:
            if only and case.id not in only:
                continue
            start = time.perf_counter()
            o = cases.run_case(case, tmp / case.id, fixtures, cli_main)
            rows.append(
                {
                    "id": case.id,
                    "kind": "cli",
                    "expect": case.expect,
                    "verdict": o.verdict,
                    "status": o.status,
                    "message": o.message[:200],
                    "seconds": round(time.perf_counter() - start, 1),
                }
            )
            print(f"{case.id}: {o.verdict} ({o.status}) {o.message[:120]}", file=sys.stderr, flush=True)
        for id_, call, message in cases.simulate_cases():
            if only and id_ not in only:
                continue
            verdict = cases.run_simulate_case(call, message)
            rows.append(
                {
                    "id": f"simulate-{id_}",
                    "kind": "simulate",
                    "expect": "refuse",
                    "verdict": verdict,
                    "status": None,
                    "message": "",
                    "seconds": None,
                }
            )
            print(f"simulate-{id_}: {verdict}", file=sys.stderr, flush=True)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1) + "\n")
    counts = collections.Counter(r["verdict"].split(" (")[0] for r in rows)
    print("| case | expected | outcome | exit | message |\n|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['id']} | {r['expect']} | {r['verdict']} | {r['status']} | {r['message'][:90].replace('|', '/')} |")
    print(f"\n{len(rows)} inputs tried: " + ", ".join(f"{n} {k}" for k, n in counts.most_common()))


def _short(verdict):
    return verdict.split(" (")[0]


def compare(before_path, after_path):
    """A Markdown table of two runs' outcomes, case by case, and both tallies."""
    before = {r["id"]: r for r in json.loads(pathlib.Path(before_path).read_text())}
    after = json.loads(pathlib.Path(after_path).read_text())
    print("| input | expected | before | after |\n|---|---|---|---|")
    for r in after:
        b = before.get(r["id"])
        was = "-" if b is None else _short(b["verdict"]) + (f" (exit {b['status']})" if b["status"] is not None else "")
        print(f"| `{r['id']}` | {r['expect']} | {was} | {_short(r['verdict'])} |")
    for name, rows in (("before", [before[r["id"]] for r in after if r["id"] in before]), ("after", after)):
        counts = collections.Counter(_short(r["verdict"]) for r in rows)
        print(f"\n{name}: {len(rows)} inputs: " + ", ".join(f"{n} {k}" for k, n in counts.most_common()))


if __name__ == "__main__":
    main()
