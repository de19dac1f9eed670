"""`Trajectory`: measured (or simulated) times, states and inputs with their names."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float
import numpy as np

from .._errors import UsageError


class Trajectory(eqx.Module):
    """A record of a system's states and inputs at sample times.

    Sampling may be irregular. Inputs are read as a zero-order hold: `us[k]` acts on
    $[t_k, t_{k+1})$. Being an `eqx.Module`, a `Trajectory` can be passed through `jax.jit` and
    `jax.vmap` (stack several of equal length with `jax.tree.map(jnp.stack, ...)`).

    **Fields:**

    - `ts`: sample times [s], strictly increasing, shape `(time,)`; a float64 numpy array when
      loaded from a file (times stay float64 on the host whatever JAX's mode), or a JAX array.
    - `xs`: states, shape `(time, n_states)`, columns named by `state_names`.
    - `us`: inputs, shape `(time, n_inputs)`, columns named by `input_names`.
    - `state_names`, `input_names`: the contract's column names (static).
    - `system`: the contract's system name (`"acrobot"`, ...), or `""` (static).
    - `source`: where the data came from (a file path), or `""` (static).
    """

    ts: Float[Array | np.ndarray, " time"]
    xs: Float[Array | np.ndarray, "time n_states"]
    us: Float[Array | np.ndarray, "time n_inputs"]
    state_names: tuple[str, ...] = eqx.field(static=True)
    input_names: tuple[str, ...] = eqx.field(static=True)
    system: str = eqx.field(static=True, default="")
    source: str = eqx.field(static=True, default="")

    def __check_init__(self):
        if self.ts.ndim != 1:
            raise ValueError(f"Trajectory: `ts` must be 1-d, got shape {self.ts.shape}")
        n = self.ts.shape[0]
        for name, arr, names in (("xs", self.xs, self.state_names), ("us", self.us, self.input_names)):
            if arr.ndim != 2 or arr.shape != (n, len(names)):
                raise ValueError(
                    f"Trajectory: `{name}` must have shape ({n}, {len(names)}) for columns {names}, got {arr.shape}"
                )

    def __len__(self) -> int:
        return self.ts.shape[0]

    @property
    def x0(self) -> Array:
        """The first state."""
        return self.xs[0]

    @property
    def duration(self) -> float:
        """Recorded time span [s]."""
        ts = np.asarray(self.ts)  # on the host: the same subtraction, without compiling two slices and a subtraction
        return float(ts[-1] - ts[0])

    @property
    def dt(self) -> float:
        """Median sample interval [s]."""
        return float(np.median(np.diff(np.asarray(self.ts))))

    @property
    def is_uniform(self) -> bool:
        """Whether the sampling is uniform to within 1 % of the median interval."""
        d = np.diff(np.asarray(self.ts))
        median = np.median(d)
        return bool(np.all(np.abs(d - median) <= 0.01 * median))

    def state(self, name: str) -> Array | np.ndarray:
        """The state column `name`."""
        return self.xs[:, self._index(self.state_names, name, "state")]

    def input(self, name: str) -> Array | np.ndarray:
        """The input column `name`."""
        return self.us[:, self._index(self.input_names, name, "input")]

    @staticmethod
    def _index(names, name, kind):
        if name not in names:
            raise UsageError(f"no {kind} column '{name}'; the {kind}s are {names}")
        return names.index(name)

    def slice(self, start: int | np.integer | None = None, stop: int | np.integer | None = None) -> "Trajectory":
        """The samples `start:stop` (Python slice semantics), as a new `Trajectory`."""
        s = slice(start, stop)
        return Trajectory(
            self.ts[s], self.xs[s], self.us[s], self.state_names, self.input_names, self.system, self.source
        )

    def split(self, fraction: float) -> tuple["Trajectory", "Trajectory"]:
        """Split into the first `fraction` of samples and the rest (e.g. train and held-out)."""
        if not 0 < fraction < 1:
            raise UsageError(f"split: `fraction` must be in (0, 1), got {fraction}")
        k = int(round(fraction * len(self)))
        return self.slice(None, k), self.slice(k, None)

    def astype(self, dtype) -> "Trajectory":
        """Cast the states and inputs to `dtype` (e.g. `jnp.float32` for throughput).

        Times held on the host in float64 (as `load_trajectory` gives them) stay so; times that are
        JAX arrays are cast too.
        """
        ts = self.ts if isinstance(self.ts, np.ndarray) else jnp.asarray(self.ts, dtype)
        return Trajectory(
            ts,
            jnp.asarray(self.xs, dtype),
            jnp.asarray(self.us, dtype),
            self.state_names,
            self.input_names,
            self.system,
            self.source,
        )
