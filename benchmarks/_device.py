"""What the benchmarks ran on: the JAX device (its kind, e.g. "NVIDIA H100 80GB HBM3") or the CPU.

The benchmarks are device-agnostic: the same script runs on a CPU or, unchanged, on a GPU when JAX
sees one (install `jax[cuda12]`), and records the device with its absolute numbers.
"""

import os
import platform

import jax


def device_info() -> dict:
    """`platform`, `device_kind`, `device_count`, `accelerator` and the host CPU, for a results file."""
    device = jax.devices()[0]
    return {
        "platform": device.platform,
        "device_kind": device.device_kind,
        "device_count": jax.device_count(),
        "accelerator": device.platform != "cpu",
        "host_cpu": platform.processor() or platform.machine(),
        "host_cores": os.cpu_count(),
        "jax": jax.__version__,
    }


def describe(info: dict) -> str:
    """One line for the console: on which device the absolute numbers were taken."""
    if info["accelerator"]:
        return (
            f"device: {info['device_count']} x {info['device_kind']} ({info['platform']}); the absolute numbers "
            "below are for this accelerator (numpy, MuJoCo and gymnasium references run on the host CPU)"
        )
    return (
        f"device: CPU only ({info['device_count']} XLA host device(s) on {info['host_cores']} cores of "
        f"{info['host_cpu']}); no GPU visible to JAX, so these are CPU numbers"
    )
