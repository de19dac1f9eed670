"""Importing dynax must not start a JAX backend: `jax.distributed.initialize` refuses to run after one has
started, so a module-level JAX computation anywhere in the package breaks every multi-process user."""

import subprocess
import sys


def test_importing_dynax_leaves_the_backend_uninitialised():
    code = (
        "import dynax, dynax.control, dynax.synthetic, dynax.internal\n"
        "from jax._src import xla_bridge\n"
        "print(xla_bridge.backends_are_initialized())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stdout + out.stderr
