"""JAX's persistent compilation cache for the command line: compile once, across runs.

Every `dynax` call is a fresh process, so without a cache each one compiles its rollouts, fits and
candidate batches from scratch (most of a short run's time). JAX can keep compiled executables on
disk (`jax_compilation_cache_dir`); the command line turns that on, in a folder of the user's cache
directory, unless `--no-cache` or `DYNAX_NO_CACHE=1` says otherwise. The library itself never does:
a Python user decides for their own process (`jax.config.update("jax_compilation_cache_dir", ...)`).
"""

import os
import pathlib

ENV_DISABLE = "DYNAX_NO_CACHE"
ENV_DIR = "DYNAX_CACHE_DIR"


def cache_directory() -> pathlib.Path:
    """Where the command line keeps compiled code: `$DYNAX_CACHE_DIR`, else `$XDG_CACHE_HOME/dynax/jax`,
    else `~/.cache/dynax/jax`."""
    if os.environ.get(ENV_DIR):
        return pathlib.Path(os.environ[ENV_DIR]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(base) / "dynax" / "jax"


def enable_compilation_cache(disabled: bool = False) -> pathlib.Path | None:
    """Turn on JAX's persistent compilation cache for this process; the folder, or None when off.

    Off when `disabled` (`--no-cache`), when `DYNAX_NO_CACHE` is set to anything but `0`, or when the
    folder cannot be created (a read-only home): the cache only saves time, so its absence is never
    an error.
    """
    if disabled or os.environ.get(ENV_DISABLE, "0") not in ("", "0"):
        return None
    folder = cache_directory()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    if not os.access(folder, os.W_OK):
        return None
    import jax

    jax.config.update("jax_compilation_cache_dir", str(folder))
    # Cache every program: a demo compiles about 140 small ones (1.4 MB in all), and with JAX's default
    # threshold (1 s of compile time) most of them were compiled again on every run.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder
