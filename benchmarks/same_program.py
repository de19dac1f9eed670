"""Do two trees of dynax compile the same programs? A load-free check of "no slower" for unchanged compute.

A timing ratio on a shared machine carries the machine's noise (`redesign_ab.py` pairs runs ABBA and
reports controls for that reason, and a ratio of 1.2 between two rounds is still within it). Where two
trees lower a jitted call to the same XLA program, no timing is needed: the same program on the same
inputs takes the same time. This script lowers and compiles each workload below in each tree (a fresh
subprocess with `PYTHONPATH` at the tree, as `redesign_ab.py` runs them), strips what names the source
(file names, line numbers, function names, instruction numbering) from the optimised HLO text, and
compares the rest by hash.

Workloads (the compiled cores of `simulate_paths.py` and `rollout.py`, spelled the same in both trees):
the acrobot's 5 s rollout at 100 Hz by `dynax.simulate` with `FixedGrid` (Tsit5 with 2 substeps, the
default; Tsit5, RK4 and Dopri8 with 1) and `Adaptive` (Dopri8 at 1e-10, Tsit5 at 1e-8), single and
vmapped over 256 starts, float64; the float32 batch of `rollout.py` (RK4, 1 substep); and the gradient of
a batch rollout's loss with respect to the acrobot's parameters.

Run:

    python benchmarks/same_program.py --before ba17e60 --after HEAD [--json FILE]

Prints one row per workload (`same` or `differs`, with the program sizes); exit status 1 if any differs.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile

from redesign_ab import export  # the same `git archive` of a commit (this folder is on the script's path)

# Run inside a tree: prints a JSON object {workload: [hash, size]}.
PROBE = r"""
import hashlib, json, re
import jax
jax.config.update("jax_enable_x64", True)
import diffrax, jax.numpy as jnp
import dynax

def normalised(compiled):
    text = compiled.as_text()
    keep = []
    for line in text.splitlines():
        if re.match(r'^\s*\d+ [{"]', line):  # the debug tables: file and function names, line numbers
            continue
        line = re.sub(r',?\s*(metadata=\{[^}]*\}|stack_frame_id=\d+)', '', line)
        line = re.sub(r'([A-Za-z_][\w-]*)\.\d+\b', r'\1', line)  # instruction numbering (not constants)
        keep.append(line)
    return "\n".join(keep)

def acrobot(dtype):
    return jax.tree.map(lambda p: jnp.asarray(p, dtype), dynax.Acrobot())

out = {}
for dtype, tag in ((jnp.float64, "f64"), (jnp.float32, "f32")):
    system = acrobot(dtype)
    ts = jnp.linspace(0.0, 5.0, 501, dtype=dtype)
    us = jnp.zeros((501, 1), dtype)
    x0 = jnp.asarray([0.1, 0.0, 0.0, 0.0], dtype)
    methods = {
        "FixedGrid(Tsit5, 2)": dynax.FixedGrid(),
        "FixedGrid(Tsit5, 1)": dynax.FixedGrid(diffrax.Tsit5(), substeps=1),
        "FixedGrid(RK4, 1)": dynax.FixedGrid(dynax.RK4(), substeps=1),
        "FixedGrid(Dopri8, 1)": dynax.FixedGrid(diffrax.Dopri8(), substeps=1),
        "Adaptive(Dopri8, 1e-10)": dynax.Adaptive(),
        "Adaptive(Tsit5, 1e-8)": dynax.Adaptive(diffrax.Tsit5(), rtol=1e-8, atol=1e-8),
    }
    if tag == "f32":  # rollout.py's batch
        methods = {"FixedGrid(RK4, 1)": methods["FixedGrid(RK4, 1)"]}
    for name, method in methods.items():
        one = lambda x, u, m=method: dynax.simulate(system, x, ts, u, method=m, throw=False).xs
        batch = jax.vmap(one)
        xb, ub = jnp.tile(x0, (256, 1)), jnp.tile(us, (256, 1, 1))
        if tag == "f64":
            out[f"{name} single {tag}"] = jax.jit(one).lower(x0, us).compile()
        out[f"{name} batch 256 {tag}"] = jax.jit(batch).lower(xb, ub).compile()
    if tag == "f64":
        method = dynax.FixedGrid(dynax.RK4(), substeps=1)
        def loss(s, xb, ub):
            xs = jax.vmap(lambda x, u: dynax.simulate(s, x, ts, u, method=method, throw=False).xs)(xb, ub)
            return jnp.mean(xs**2)
        xb, ub = jnp.tile(x0, (64, 1)), jnp.tile(us, (64, 1, 1))
        out["FixedGrid(RK4, 1) gradient batch 64 f64"] = jax.jit(jax.grad(loss)).lower(system, xb, ub).compile()
print(json.dumps({k: [hashlib.sha1(normalised(c).encode()).hexdigest(), len(normalised(c))] for k, c in out.items()}))
"""


def programs(tree):
    env = dict(os.environ, PYTHONPATH=str(tree), JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    done = subprocess.run([sys.executable, "-c", PROBE], cwd=tree, env=env, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"the probe failed in {tree}:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="commit of the first tree")
    parser.add_argument("--after", default="HEAD", help="commit of the second tree (default HEAD)")
    parser.add_argument("--json", type=pathlib.Path, help="write the rows here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        shas = {}
        found = {}
        for side, commit in (("before", args.before), ("after", args.after)):
            tree = pathlib.Path(scratch) / side
            shas[side] = export(commit, tree)
            found[side] = programs(tree)
            print(f"{side}: {shas[side][:10]} ({len(found[side])} programs)", flush=True)
    rows = []
    for name in found["before"]:
        (a, size_a), (b, size_b) = found["before"][name], found["after"].get(name, (None, 0))
        rows.append({"workload": name, "same": a == b, "hlo_chars_before": size_a, "hlo_chars_after": size_b})
        print(f"{name:42s} {'same' if a == b else 'differs':8s} {size_a:>8d} {size_b:>8d}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"commits": shas, "rows": rows}, indent=1) + "\n")
    sys.exit(0 if all(r["same"] for r in rows) else 1)


if __name__ == "__main__":
    main()
