"""Every `from dynax... import name` in the benchmark and experiment scripts resolves.

The scripts are not run by the suite (they take minutes), so a name moved inside the package
(`synthetic_trajectory` went from the diagnosis package to `dynax.synthetic`) would otherwise break
them unnoticed, as it once broke `benchmarks/diagnose.py`.
"""

import ast
import importlib

import pytest

from tests.conftest import REPO

SCRIPTS = sorted([*REPO.glob("benchmarks/*.py"), *REPO.glob("experiments/*.py")])


def _dynax_imports(path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "dynax":
            for alias in node.names:
                yield node.module, alias.name


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_script_imports_resolve(script):
    missing = []
    for module_name, name in _dynax_imports(script):
        module = importlib.import_module(module_name)
        if hasattr(module, name):
            continue
        try:
            importlib.import_module(f"{module_name}.{name}")
        except ImportError:
            missing.append(f"from {module_name} import {name}")
    assert not missing, f"{script.relative_to(REPO)}: {missing}"
