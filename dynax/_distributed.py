r"""Multi-process runs on JAX's own multi-controller runtime (`jax.distributed`).

Every process runs the same script. `initialize_distributed` connects it to the others (through
`jax.distributed.initialize`, which also reads SLURM's and other clusters' environment), after
which `jax.devices()` lists every process's devices and dynax's batched work (PGPE populations and
sweeps, `simulation_error`'s start times) is split across all of them with a global mesh. Each
process holds the whole input (the same seeds give the same populations everywhere), computes its
devices' share, and gets the whole result back, the same as one process would compute.

??? cite

    The multi-controller programming model: JAX documentation, "Introduction to multi-controller
    JAX (aka multi-process/multi-host JAX)", https://docs.jax.dev/en/latest/multi_process.html.
"""

import functools

import jax
from jax.sharding import Mesh, NamedSharding, PartitionSpec
import numpy as np

from ._errors import UsageError


def initialize_distributed(
    coordinator_address: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    local_device_ids: int | list[int] | None = None,
    *,
    cpu_collectives: str | None = "gloo",
    **kwargs,
) -> None:
    """Join a multi-process run: call once at the top of the script, before any other JAX call.

    With no arguments the coordinator, the number of processes and this process's rank come from
    the cluster's environment, as `jax.distributed.initialize` detects it (SLURM, Open MPI, Cloud
    TPU, Kubernetes and others). Elsewhere give them explicitly; every process passes the same
    `coordinator_address` and `num_processes` and its own `process_id`.

    **Arguments:**

    - `coordinator_address`: `"host:port"` of process 0, which every process can reach.
    - `num_processes`: the number of processes.
    - `process_id`: this process's rank, `0 .. num_processes - 1`.
    - `local_device_ids`: the local accelerators this process uses (default all it sees).
    - `cpu_collectives`: the implementation of cross-process collectives between CPU devices,
      set as `jax_cpu_collectives_implementation` (`"gloo"`, default; `"mpi"`; `None` leaves
      JAX's setting alone). Without one, CPU-only processes cannot exchange data. It does not
      affect GPUs, which use NCCL.
    - `**kwargs`: passed on to `jax.distributed.initialize` (e.g. `initialization_timeout`).

    **Raises:** `UsageError` when JAX's backend was already started in this process (call this
    first), or when `cpu_collectives` is not one JAX knows.
    """
    if cpu_collectives is not None:
        try:
            jax.config.update("jax_cpu_collectives_implementation", cpu_collectives)
        except Exception as error:  # an unknown value, or a JAX without the option
            raise UsageError(
                f"initialize_distributed: `cpu_collectives={cpu_collectives!r}` is not available in "
                f"jax {jax.__version__}: {error}"
            ) from error
    try:
        jax.distributed.initialize(coordinator_address, num_processes, process_id, local_device_ids, **kwargs)
    except RuntimeError as error:
        if "before" in str(error) or "already" in str(error):
            raise UsageError(
                f"initialize_distributed must be called before any other JAX call in the process (JAX said: {error})"
            ) from error
        raise


def multi_process() -> bool:
    return jax.process_count() > 1


def leading_sharding(n: int) -> NamedSharding | None:
    """A sharding that splits a leading axis of length `n` across every process's devices, or `None`
    with one device or when `n` does not divide evenly."""
    devices = jax.devices()
    if len(devices) < 2 or n % len(devices):
        return None
    return NamedSharding(Mesh(np.asarray(devices), ("batch",)), PartitionSpec("batch"))


def _replicated() -> NamedSharding:
    return NamedSharding(Mesh(np.asarray(jax.devices()), ("batch",)), PartitionSpec())


def global_array(value, sharding: NamedSharding) -> jax.Array:
    """A global array with `sharding` from a value every process holds in full (each process keeps
    its devices' rows)."""
    value = np.asarray(value)
    return jax.make_array_from_callback(value.shape, sharding, lambda index: value[index])


def replicate_in_jit(tree):
    """Inside a compiled function: every output replicated on every process (a no-op in one process)."""
    if not multi_process():
        return tree
    sharding = _replicated()
    return jax.tree.map(
        lambda x: jax.lax.with_sharding_constraint(x, sharding) if isinstance(x, jax.Array) else x, tree
    )


@functools.cache
def _gather(devices: tuple):
    return jax.jit(lambda xs: xs, out_shardings=NamedSharding(Mesh(np.asarray(devices), ("batch",)), PartitionSpec()))


def replicate(tree):
    """Outside a compiled function: gather arrays split across processes so that every process holds
    them whole (a no-op in one process)."""
    if not multi_process():
        return tree
    leaves, treedef = jax.tree.flatten(tree)
    split = [i for i, x in enumerate(leaves) if isinstance(x, jax.Array) and not x.is_fully_addressable]
    if split:
        gathered = _gather(tuple(jax.devices()))([leaves[i] for i in split])
        for i, g in zip(split, gathered):
            leaves[i] = g
    return jax.tree.unflatten(treedef, leaves)
