"""The mechanical counts of the one-vocabulary redesign's before/after table (`docs/architecture.md`).

Reads the source tree only (nothing is imported or run) and prints each count, writing them all to
`experiments/results/vocabulary_counts/counts.json`:

- top-level exports: the names `dynax/__init__.py` binds by import (its `__all__` where it has one);
- functions over 8 parameters: positional and keyword-only, `self`/`cls` excluded, private functions
  included, every function in `dynax/` (the list with each one's file and line);
- cross-file underscore imports: `from <dynax module> import _name` statements where `_name` is not a
  module (the rule `tests/test_layers.py` enforces), by folder;
- private-module imports in tests, experiments and benchmarks: lines that import `dynax._...`; a line
  whose comment says `private:` and why (a test that monkeypatches a private function to simulate a
  failure or spy on it, a benchmark that times a private function, an experiment that patches one to
  try a variant) is counted apart as justified;
- the longest guide page: bytes of the largest `docs/**/*.md` outside `docs/devdocs/`;
- the CHANGELOG's unreleased section: its lines, from `## Unreleased` to the next `## ` heading;
- dates and issue numbers in the package's docstrings and comments (ISO dates, a month named with a
  day or year, "issue N", "#N", "PR N");
- lines over 120 characters in the Python files of dynax, tests, experiments and benchmarks.

Run from the repository root: `python experiments/vocabulary_counts.py`.
"""

import ast
import io
import json
import pathlib
import re
import sys
import tokenize

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # `tests.test_layers`, as other experiments import `tests`
PACKAGE = ROOT / "dynax"
OUT = ROOT / "experiments" / "results" / "vocabulary_counts"

PRIVATE_IMPORT = re.compile(r"^\s*(from dynax\._|import dynax\._|from dynax import _[a-z])")
MONTH = r"(Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\.?"
DATED = re.compile(
    r"\b(19|20)\d\d-[01]\d-[0-3]\d\b"  # ISO date
    rf"|\b{MONTH} [0-3]?\d(st|nd|rd|th)?,? (19|20)\d\d\b"  # Month day, year
    rf"|\b[0-3]?\d {MONTH} (19|20)\d\d\b"  # day Month year
    rf"|\b{MONTH} (19|20)\d\d\b"  # Month year
    r"|\b[Ii]ssues? #?\d+\b|(?<![\w&])#\d+\b|\bPR #?\d+\b"  # issue numbers
)


def python_files(*folders):
    for folder in folders:
        yield from sorted((ROOT / folder).rglob("*.py"))


def module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def top_level_exports() -> list[str]:
    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return sorted(ast.literal_eval(node.value))
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
    return sorted(names)


def functions_over_eight() -> list[dict]:
    rows = []
    for path in python_files("dynax"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")]
                if len(names) > 8:
                    where = f"{path.relative_to(ROOT)}:{node.lineno}"
                    rows.append({"function": node.name, "parameters": len(names), "where": where})
    return sorted(rows, key=lambda r: (-r["parameters"], r["where"]))


def underscore_imports() -> list[str]:
    """The statements that import an underscore name from another dynax module: the layer test's count."""
    from tests.test_layers import underscore_imports as by_file  # the rule the test enforces, read once

    return [f"{path}:{line}" for path, lines in by_file().items() for line in lines]


def private_imports() -> tuple[list[str], list[str]]:
    plain, justified = [], []
    for path in python_files("tests", "experiments", "benchmarks"):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if PRIVATE_IMPORT.match(line):
                entry = f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
                (justified if "private:" in line.partition("#")[2] else plain).append(entry)
    return plain, justified


def longest_guide_page() -> dict:
    pages = [p for p in (ROOT / "docs").rglob("*.md") if "devdocs" not in p.relative_to(ROOT / "docs").parts]
    page = max(pages, key=lambda p: p.stat().st_size)
    return {"page": str(page.relative_to(ROOT)), "bytes": page.stat().st_size}


def changelog_unreleased_lines() -> int:
    lines = (ROOT / "CHANGELOG.md").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("## ") and "nreleased" in line)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    return end - start - 1


def docstrings_and_comments(path: pathlib.Path):
    """`(line, text)` of every comment and docstring of a module."""
    source = path.read_text()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            yield token.start[0], token.string
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                if isinstance(first.value.value, str):
                    for offset, text in enumerate(first.value.value.splitlines()):
                        yield first.lineno + offset, text


def dated_passages() -> list[str]:
    found = []
    for path in python_files("dynax"):
        for line, text in docstrings_and_comments(path):
            if DATED.search(text):
                found.append(f"{path.relative_to(ROOT)}:{line}: {text.strip()[:100]}")
    return found


def long_lines() -> list[str]:
    return [
        f"{path.relative_to(ROOT)}:{number}"
        for path in python_files("dynax", "tests", "experiments", "benchmarks")
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if len(line) > 120
    ]


def main():
    exports = top_level_exports()
    over_eight = functions_over_eight()
    underscore = underscore_imports()
    plain, justified = private_imports()
    page = longest_guide_page()
    dated = dated_passages()
    long = long_lines()
    counts = {
        "top_level_exports": len(exports),
        "functions_over_8_parameters": len(over_eight),
        "cross_file_underscore_imports": len(underscore),
        "private_imports_tests_experiments_benchmarks": len(plain),
        "private_imports_justified": len(justified),
        "longest_guide_page_bytes": page["bytes"],
        "longest_guide_page": page["page"],
        "changelog_unreleased_lines": changelog_unreleased_lines(),
        "dates_or_issue_numbers_in_docstrings_and_comments": len(dated),
        "lines_over_120_characters": len(long),
    }
    for key, value in counts.items():
        print(f"{key:50s} {value}")
    print("\nfunctions over 8 parameters:")
    for row in over_eight:
        print(f"  {row['parameters']:3d} {row['function']:32s} {row['where']}")
    for title, lines in (
        ("cross-file underscore imports", underscore),
        ("private-module imports (tests, experiments, benchmarks)", plain),
        ("  justified (`# private:` and why)", justified),
        ("dates or issue numbers", dated),
    ):
        if lines:
            print(f"\n{title}:")
            print("\n".join(f"  {line}" for line in lines))
    details = {
        "top_level_exports": exports,
        "functions_over_8_parameters": over_eight,
        "cross_file_underscore_imports": underscore,
        "private_imports": plain,
        "private_imports_justified": justified,
        "dated_passages": dated,
        "lines_over_120_characters": long,
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "counts.json").write_text(json.dumps({"counts": counts, "details": details}, indent=1) + "\n")
    print(f"\nwritten to {(OUT / 'counts.json').relative_to(ROOT)}", file=sys.stderr)


if __name__ == "__main__":
    main()
