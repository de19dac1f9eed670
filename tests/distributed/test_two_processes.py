"""Two CPU processes on `jax.distributed` compute what one process computes.

Starts two local processes (one CPU device each, gloo collectives, a free localhost port) running
`_worker.py`, and the same worker as one plain process; the PGPE search, a population evaluated
outside `jit`, a `sweep_pgpe` of two runs and a `simulation_error` sweep must agree; so must one
process with two CPU devices (the same sharding within a process). The two-process run splits every
population and the windows across the two processes, so any lost or doubled share, or a result
that only one process holds, shows up.
"""

import os
import pathlib
import socket
import subprocess
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


WORKER = pathlib.Path(__file__).with_name("_worker.py")
TIMEOUT_S = 600  # a loaded machine; about 30 s on an idle 2-core one


def _free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _environment():
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    env["JAX_PLATFORMS"] = "cpu"
    repo = str(pathlib.Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([repo] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def _run(procs):
    outputs = []
    try:
        for p in procs:
            out, _ = p.communicate(timeout=TIMEOUT_S)
            outputs.append(out)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    for p, out in zip(procs, outputs):
        assert p.returncode == 0, out[-4000:]


def test_two_processes_equal_one(tmp_path):
    env = _environment()
    port = _free_port()
    outs = [tmp_path / f"rank{r}.npz" for r in range(2)]
    single, two_devices = tmp_path / "single.npz", tmp_path / "two_devices.npz"
    commands = [[str(out), str(port), "2", str(rank)] for rank, out in enumerate(outs)] + [[str(single)]]
    # All at once (the references beside the pair): one worker compiles for about 10 s of CPU time.
    procs = [
        subprocess.Popen(
            [sys.executable, str(WORKER), *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        for args in commands
    ]
    procs.append(
        subprocess.Popen(
            [sys.executable, str(WORKER), str(two_devices)],
            env=dict(env, DYNAX_TEST_HOST_DEVICES="2"),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
    )
    _run(procs)

    reference = np.load(single)
    assert int(reference["process_count"]) == 1 and int(reference["device_count"]) == 1
    assert int(reference["n_windows"]) == 9
    assert np.all(np.abs(reference["errors"][:, -1]) > 0)  # the wrong model leaves an error to compare
    for out in outs + [two_devices]:
        result = np.load(out)
        assert int(result["process_count"]) == (1 if out == two_devices else 2) and int(result["device_count"]) == 2
        for name in ("mean", "sigma", "best", "history_reward", "rewards", "sweep_mean", "rmse", "errors"):
            assert result[name].shape == reference[name].shape, name
            np.testing.assert_allclose(result[name], reference[name], rtol=1e-12, atol=1e-14, err_msg=name)
        assert int(result["n_windows"]) == 9


@pytest.mark.parametrize("value", ["no-such-collectives"])
def test_unknown_cpu_collectives_is_a_usage_error(value):
    import dynax

    with pytest.raises(dynax.UsageError, match="cpu_collectives"):
        dynax.initialize_distributed("localhost:1", 1, 0, cpu_collectives=value, initialization_timeout=1)
