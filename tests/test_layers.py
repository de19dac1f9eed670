"""The package's layers: a module imports only from its own layer and the layers below it.

The pipeline, lowest first: utilities -> data -> model -> simulate -> fit (the engine) -> identify
-> validate -> diagnose -> control -> synthetic -> cli (`docs/architecture.md`,
`docs/devdocs/vocabulary.md`). Synthetic data sits above everything that fits, so nothing that fits
can reach for the truth; the command line sits on top. Every import counts, function-local ones
included: a local import that dodges a cycle still ties the lower layer to the upper one. The
public namespaces (`dynax`, `dynax.synthetic`, `dynax.internal`, `dynax.control`) only re-export;
no private module imports them.
"""

import ast
import inspect
import pathlib

import pytest

import dynax

PACKAGE = pathlib.Path(dynax.__file__).parent

LAYERS = (
    "utilities",
    "data",
    "model",
    "simulate",
    "fit",
    "identify",
    "validate",
    "diagnose",
    "control",
    "synthetic",
    "cli",
)

# The first component under `dynax.` of every private module or package, and its layer.
LAYER_OF = {
    "_version": "utilities",
    "_errors": "utilities",
    "_compiled_code": "utilities",
    "_precision": "utilities",
    "_progress": "utilities",
    "_context": "utilities",
    "_distributed": "utilities",
    "_data": "data",
    "_model": "model",
    "_simulate": "simulate",
    "_fit": "fit",
    "_identify": "identify",
    "_validate": "validate",
    "_diagnose": "diagnose",
    "_control": "control",
    "_synthetic": "synthetic",
    "_cli": "cli",
    "__main__": "cli",
}

# The public namespaces: they re-export the layers and belong to none.
FACADES = {"__init__", "synthetic", "internal", "control"}

# Imports that break the order today, each with the reason it stays for now: (importer, imported).
ALLOWED: dict[tuple[str, str], str] = {}


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports_of(module: str, is_package: bool, source: str):
    """`(line, module)` for every import in a module's source, relative ones resolved, `from package
    import submodule` read as the submodule."""
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                imported = ".".join(base + ([node.module] if node.module else []))
            else:
                imported = node.module or ""
            for alias in node.names:
                candidate = PACKAGE.parent.joinpath(*f"{imported}.{alias.name}".split("."))
                is_submodule = candidate.with_suffix(".py").exists() or (candidate / "__init__.py").exists()
                yield node.lineno, f"{imported}.{alias.name}" if is_submodule else imported


def _imported_modules(path: pathlib.Path):
    return _imports_of(_module_name(path), path.name == "__init__.py", path.read_text())


def _layer(module: str) -> str | None:
    """The layer of a `dynax...` module; `"facade"` for the public namespaces; `None` outside dynax."""
    parts = module.split(".")
    if parts[0] != "dynax":
        return None
    if len(parts) == 1 or parts[1] in FACADES:
        return "facade"
    if parts[1] not in LAYER_OF:
        raise AssertionError(f"{module}: no layer; add its top-level name to LAYER_OF in tests/test_layers.py")
    return LAYER_OF[parts[1]]


MODULES = sorted(PACKAGE.rglob("*.py"))


def _violations():
    found = {}
    for path in MODULES:
        importer = _module_name(path)
        layer = _layer(importer)
        if layer == "facade":
            continue
        for line, imported in _imported_modules(path):
            target = _layer(imported)
            if target is None:
                continue
            if target == "facade" or LAYERS.index(target) > LAYERS.index(layer):
                top = ".".join(imported.split(".")[:2])
                found.setdefault((importer, top), {}).setdefault(
                    f"{path.relative_to(PACKAGE.parent)}:{line}: {layer} imports {imported} ({target})"
                )
    return found


def test_every_module_has_a_layer():
    for path in MODULES:
        _layer(_module_name(path))


def test_no_module_imports_from_a_layer_above_it():
    found = _violations()
    unexpected = [line for key, lines in found.items() if key not in ALLOWED for line in lines]
    assert not unexpected, "imports from a higher layer:\n" + "\n".join(unexpected)


def test_every_allowed_exception_still_occurs():
    # An exception that no longer happens leaves the list, so the list stays the list of what to fix.
    stale = set(ALLOWED) - set(_violations())
    assert not stale, f"no longer needed in ALLOWED: {sorted(stale)}"


@pytest.mark.parametrize(
    "source, expected",
    [
        ("from ..._synthetic import demo_data\n", ["dynax._synthetic"]),
        ("def f():\n    from ..._cli._main import main\n", ["dynax._cli._main"]),
        ("from ... import _control\n", ["dynax._control"]),
        ("import dynax.synthetic\n", ["dynax.synthetic"]),
        ("from .._system import AbstractSystem\n", ["dynax._model._system"]),
    ],
)
def test_the_checker_reads_relative_local_and_package_imports(source, expected):
    # As if in dynax/_model/_extensions/: every form of import resolves to the module it reaches.
    seen = [module for _, module in _imports_of("dynax._model._extensions._probe", False, source)]
    assert seen == expected


# Modules that still import an underscore name from another module, to be emptied by
# tools/finish_boundary_renames.py once the branches that edit these modules are merged.
UNDERSCORE_IMPORTERS = frozenset()


def underscore_imports():
    """`{file: [line, ...]}` of the statements that import an underscore name (not a module) from
    another module of dynax."""
    found = {}
    for path in MODULES:
        importer = _module_name(path)
        package = importer if path.name == "__init__.py" else importer.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = package.split(".")
                module = ".".join(base[: len(base) - (node.level - 1)] + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module.split(".")[0] != "dynax":
                continue
            private = [
                alias.name
                for alias in node.names
                if alias.name.startswith("_")
                and not alias.name.startswith("__")
                and not any(m.startswith(f"{module}.{alias.name}") for m in ALL_MODULES)
            ]
            if private:
                found.setdefault(str(path.relative_to(PACKAGE.parent)), []).append(
                    f"{node.lineno}: from {module} import {', '.join(private)}"
                )
    return found


ALL_MODULES = {_module_name(path) for path in MODULES}


def test_no_underscore_name_is_imported_from_another_module():
    # A helper that another module needs gets a plain name inside its private module.
    found = underscore_imports()
    unexpected = {f: lines for f, lines in found.items() if f not in UNDERSCORE_IMPORTERS}
    assert not unexpected, unexpected
    stale = UNDERSCORE_IMPORTERS - set(found)
    assert not stale, f"no longer import underscore names; drop them from UNDERSCORE_IMPORTERS: {sorted(stale)}"


def test_internal_lists_every_name_it_exports():
    import dynax.internal

    # modules aside: the test-time type checker's import hook adds `jaxtyping` to every module it instruments
    exported = {n for n, v in vars(dynax.internal).items() if not n.startswith("_") and not inspect.ismodule(v)}
    assert set(dynax.internal.__all__) == exported
