"""One-off: finish the public/private boundary once the concurrent branches are merged, then delete this file.

Gives every helper that another module imports a plain name inside its private module (as
optimistix's `_misc.py` does) and updates its importers, tests, experiments and benchmarks included;
`dynax/internal.py`'s `_old as new` lines become `new as new`, and the old-name aliases in
`_distributed.py` and `_sim_error.py` go. Run from the repository root:
`python tools/finish_boundary_renames.py [--dry-run]`. A rename whose new name already occurs in a
file it would touch is skipped and listed; uses as an attribute or in a string are listed to check
by hand. Afterwards no statement imports an underscore name from another module (the count the
boundary aims at), which `tests/test_layers.py`-style checks can then hold.
"""

import ast, pathlib, re, sys

RENAMES = {  # defining module (path under dynax/) -> {old: new}
    "_identify/_regressors.py": {"_split": "split_terms", "_positions": "positions_and_velocities"},
    "_identify/_equations.py": {"_equations": "stacked_equations", "_uniform": "uniformly_sampled",
                                "_dynamic_rows": "dynamic_rows"},
    "_identify/_ls_stage.py": {"_fitted_system": "fitted_system", "_joint_positions": "joint_positions",
                               "_least_squares_stage": "least_squares_stage", "_less_offsets": "less_offsets",
                               "_offsets_json": "offsets_json", "_relative_equation_error": "relative_equation_error"},
    "_identify/_offsets.py": {"_record_rows": "record_rows"},
    "_identify/_simulation_fit.py": {"_segments": "simulation_segments",
                                     "_clustered_covariance": "segment_clustered_covariance",
                                     "_record_covariance": "record_jackknife_covariance"},
    "_identify/_identify.py": {"_named_parameters": "named_parameters"},
    "_identify/_least_squares.py": {"_qr_r": "tsqr_r"},
    "_identify/_refine.py": {"_ml_weights": "ml_weights"},
    "_identify/_vehicle/_criteria.py": {"_normal_equations": "normal_equations", "_single": "one_shot_history",
                                        "_solve": "ridge_solve", "_starts": "window_starts", "_with_theta": "with_theta"},
    "_model/_extensions/_terms.py": {"_scalar": "float_scalar"},
    "_model/_system.py": {"_solve_spd": "solve_spd"},
    "_cli/_identify.py": {"_jointly_cell": "jointly_determined_cell"},
    "_diagnose/_problem.py": {"_candidate_family": "candidate_family", "_refit_names": "names_to_refit",
                              "_check_arguments": "check_arguments", "_Options": "Options", "_prepare": "prepare_problem",
                              "_Problem": "Problem"},
    "_diagnose/_forward.py": {"_Current": "Current", "_Nominal": "Nominal", "_Yardstick": "Yardstick",
                              "_forward_selection": "forward_selection"},
    "_diagnose/_records.py": {"_as_records": "as_records", "_prepare_records": "prepare_records",
                              "_velocity_estimates": "velocity_estimates", "_horizon_grid": "horizon_grid",
                              "_reference_horizon": "reference_horizon", "_fit_window": "fit_window"},
    "_diagnose/_summaries.py": {"_merge_repeated_causes": "merge_repeated_causes", "_round_summary": "round_summary",
                                "_gain": "rmse_gain", "_window_scores": "window_scores", "_rmse_curve": "rmse_curve",
                                "_candidate_table": "candidate_table", "_test_summary": "test_summary",
                                "_per_run_table": "per_run_table", "_unexplained_note": "unexplained_note"},
    "_diagnose/_residuals.py": {"_sg_window": "sg_window", "_hidden_trajectory": "hidden_trajectory",
                                "_predicted_accelerations": "predicted_accelerations"},
    # Already renamed in their modules (old names kept as aliases there): only the importers move.
    "_distributed.py": {"_multi_process": "multi_process", "_replicate_in_jit": "replicate_in_jit"},
    "_sim_error.py": {"_window_errors": "rollouts_from_starts"},
}
# New names that occur already only inside a string or a docstring of a touched file.
FORCE = {"relative_equation_error", "candidate_table"}
ALIASES = {"_distributed.py": ["_multi_process", "_replicate_in_jit"], "_sim_error.py": ["_window_errors"]}

ROOT = pathlib.Path.cwd()
DRY = "--dry-run" in sys.argv
FILES = sorted(p for d in ("dynax", "tests", "experiments", "benchmarks") for p in (ROOT / d).rglob("*.py"))


def module_of(path):
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def importers(module, old):
    """Files with `from <module> import old` (absolute or relative, anywhere in the file)."""
    out = []
    for path in FILES:
        name = module_of(path)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module
                if target == module and any(a.name == old for a in node.names):
                    out.append(path)
                    break
    return out


word = lambda n: re.compile(rf"(?<![\w.]){re.escape(n)}\b")
texts = {}
def text(p):
    return texts.setdefault(p, p.read_text())

done, skipped = [], []
for rel, mapping in RENAMES.items():
    path = ROOT / "dynax" / rel
    module = module_of(path)
    for old, new in mapping.items():
        touched = [p for p in dict.fromkeys(([] if rel in ALIASES else [path]) + importers(module, old))]
        touched = [p for p in touched if word(old).search(text(p))]
        if not touched:
            continue
        internal = ROOT / "dynax" / "internal.py"
        clash = [p for p in touched if word(new).search(text(p)) and p != internal]
        if clash and new not in FORCE:
            skipped.append(f"{module}.{old} -> {new}: '{new}' already in {[str(c.relative_to(ROOT)) for c in clash]}")
            continue
        for p in touched:
            if p == internal:
                texts[p] = text(p).replace(f"import {old} as {new}", f"import {new} as {new}")
                texts[p] = re.sub(rf"\b{re.escape(old)} as {re.escape(new)}\b", f"{new} as {new}", texts[p])
            else:
                texts[p] = word(old).sub(new, text(p))
        # `module._old` in prose and attribute uses (`_summaries._window_scores`).
        base = path.stem
        for p in FILES:
            t = text(p)
            if f"{base}.{old}" in t:
                texts[p] = re.sub(rf"\b{re.escape(base)}\.{re.escape(old)}\b", f"{base}.{new}", t)
        done.append(f"{module}.{old} -> {new} ({len(touched)} files)")
for rel, olds in ALIASES.items():
    p = ROOT / "dynax" / rel
    t = text(p)
    t = re.sub(r"\n\n\n# (The )?[Oo]ld names?, still imported by [^\n]*\n(?:_\w+ = \w+\n)+", "\n", t)
    texts[p] = t
# Attribute and string uses that a word rename does not reach (monkeypatching, `module._old`).
warn = []
for p in FILES:
    for rel, mapping in RENAMES.items():
        for old in mapping:
            if re.search(rf"\.{re.escape(old)}\b|[\"']{re.escape(old)}[\"']", text(p)):
                warn.append(f"{p.relative_to(ROOT)}: '{old}' as an attribute or string; check by hand")
print("\n".join(done)); print("SKIPPED:\n" + "\n".join(skipped)); print("CHECK:\n" + "\n".join(sorted(set(warn))))
if not DRY:
    for p, t in texts.items():
        if t != p.read_text():
            p.write_text(t)
