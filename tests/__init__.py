def __getattr__(name):
    """`tests.typecheck`, the test-time type checker that `--jaxtyping-packages` names, found on first use: importing
    `tests` (the experiments read `tests.hidden_cases`) does not need beartype."""
    if name == "typecheck":
        import importlib

        return importlib.import_module("tests.typecheck")
    raise AttributeError(name)
