"""What the verdict's one unit moves, read from the stored results (nothing is diagnosed again).

It reads every stored power block as written before 2026-11-29 (an RMS reading); rows stored since speak mean
squared error already, and the DFKI rows this change moved are stored with their new verdicts.

Until 2026-11-29 the verdict's power (`test.power.detectable_gain`, `needed_s`) read the paired test's detectable
shift $\\Delta$ of the mean log ratio of mean squared window errors as an RMS gain, $1 - e^{-\\Delta/2}$, from the
shortcut $\\Delta = (t_{1-a} + t_{0.8})\\,s$; and the probe's structure was of practical size at $R^2 \\ge 0.4375$
(25 % of the residuals' RMS). Now the shift is the noncentral t's and a gain in mean squared error,
$1 - e^{-\\Delta}$, and the probe's threshold is $R^2 \\ge 0.25$. Both changes only tighten the rule: `none` can
only become `inconclusive` (or `unexplained`), `explained` only `unexplained`. For every stored case with a power
block this prints the stored figure, the same shift read in mean squared error, and a bound with the noncentral
t's correction (at most `NCT_BOUND` times the shortcut's shift for 3 or more degrees of freedom at a level of
1e-4 or more); `needed_s` grows by 4 times that factor squared. Every stored verdict whose probe $R^2$ lies in
[0.25, 0.4375) with significant structure is listed: those move from `explained` (or `none`) to `unexplained`.

    python experiments/verdict_units.py
"""

import glob
import json
import pathlib

NCT_BOUND = 1.2  # the noncentral t's shift over the shortcut's: 1.19 at 3 degrees of freedom and level 1e-4, less above
OLD_R2, NEW_R2 = 1 - 0.75**2, 0.25

ROOT = pathlib.Path(__file__).resolve().parent / "results"


def mse(rms_gain: float, factor: float = 1.0) -> float:
    """The stored RMS reading's shift, $-2\\log(1 - g)$, times `factor`, read as a gain in mean squared error."""
    return 1.0 - (1.0 - rms_gain) ** (2.0 * factor)


def rows():
    """`(source, name, verdict, power, r2, significant)` of every stored diagnosis."""
    for path in sorted(glob.glob(str(ROOT / "calibration_battery*/cases.json"))):
        for r in json.loads(pathlib.Path(path).read_text()):
            sig = r["structure_p"] is not None and r["structure_p"] < 0.01 and (r["structure_r2"] or 0) > 0.05
            yield path, r["name"], r["verdict"], r["power"], r["structure_r2"], sig
    paths = glob.glob(str(ROOT / "diagnose_real_splits*/splits.json")) + glob.glob(
        str(ROOT / "diagnose_real_variants/*/splits.json")
    )
    for path in sorted(paths):
        for r in json.loads(pathlib.Path(path).read_text()):
            s = r["structure"]["extended" if r["findings"] else "nominal"]
            name = f"{r['split']} {r['mode']} {r.get('variant', '5ms')}"
            yield path, name, r["verdict"], r.get("power"), s["r2"], s["significant"]
    for path in sorted(glob.glob(str(ROOT / "*/report.json")) + glob.glob(str(ROOT / "*/report/report.json"))):
        j = json.loads(pathlib.Path(path).read_text())
        if "verdict" not in j or "structure" not in j:
            continue
        s = j["structure"]["extended" if j["findings"] else "nominal"]
        yield path, "report", j["verdict"], j["test"].get("power"), s["r2"], s["significant"]


def main():
    moved = []
    print("stored power blocks (detectable gain: stored RMS reading, the same shift in MSE, with the nct bound)")
    for path, name, verdict, power, r2, significant in rows():
        where = pathlib.Path(path).relative_to(ROOT.parent.parent)
        if power and power.get("detectable_gain") is not None:
            d = power["detectable_gain"]
            new = mse(d, NCT_BOUND)
            needed = power.get("needed_s")
            grown = "-" if needed is None else f"{needed:.3g} -> {4 * needed:.3g}..{4 * NCT_BOUND**2 * needed:.3g} s"
            flag = "  ** none would become inconclusive" if verdict == "none" and new > 0.25 else ""
            print(f"  {where}: {name}: {verdict}; {d:.3f} -> {mse(d):.3f}..{new:.3f}; needed {grown}{flag}")
            if flag:
                moved.append((name, verdict, "inconclusive"))
        if significant and r2 is not None and NEW_R2 <= r2 < OLD_R2 and verdict in ("explained", "none"):
            print(f"  {where}: {name}: {verdict}, probe R2 {r2:.3f} significant  ** becomes unexplained")
            moved.append((name, verdict, "unexplained"))
    print(f"verdicts that move: {len(moved)}")
    for m in moved:
        print("  ", *m)


if __name__ == "__main__":
    main()
