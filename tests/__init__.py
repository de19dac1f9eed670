from tests import typecheck as typecheck  # the test-time type checker (`--jaxtyping-packages`) finds it here
