"""`Trajectory`: measured (or simulated) times, states and inputs with their names."""

import equinox as eqx
from jax.core import Tracer
import jax.numpy as jnp
from jaxtyping import Array, Real
import numpy as np

from .._errors import DataError, UsageError


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

    ts: Real[Array | np.ndarray, " time"]  # integers too (`__check_init__`)
    xs: Real[Array | np.ndarray, "time n_states"]
    us: Real[Array | np.ndarray, "time n_inputs"]
    state_names: tuple[str, ...] | list[str] = eqx.field(static=True)
    input_names: tuple[str, ...] | list[str] = eqx.field(static=True)
    system: str = eqx.field(static=True, default="")
    source: str = eqx.field(static=True, default="")

    def __check_init__(self):
        # Shapes, dtypes and names only (host metadata, nothing computed): a record built in a script is refused
        # here, by argument, rather than deep inside a fit. Values (NaN, times that do not increase) are the
        # consumers' to refuse (`identify`, `diagnose`, `simulate` name the row), as this runs under `jit` too.
        for name in ("ts", "xs", "us"):
            arr = getattr(self, name)
            if not hasattr(arr, "ndim") or not hasattr(arr, "dtype"):
                raise UsageError(
                    f"Trajectory: `{name}` must be an array (numpy or JAX; `np.asarray` a list), "
                    f"got {type(arr).__name__}"
                )
            if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
                raise UsageError(f"Trajectory: `{name}` must hold real numbers, got dtype {arr.dtype}")
        for name in ("state_names", "input_names"):
            names = getattr(self, name)
            if isinstance(names, str) or not all(isinstance(n, str) for n in names):
                raise UsageError(f"Trajectory: `{name}` must be a tuple of column names (str), got {names!r}")
            repeated = sorted({n for n in names if list(names).count(n) > 1})
            if repeated:
                raise UsageError(f"Trajectory: `{name}` names {repeated} more than once: {tuple(names)}")
        if self.ts.ndim != 1:
            raise UsageError(f"Trajectory: `ts` must be 1-d, got shape {self.ts.shape}")
        n = self.ts.shape[0]
        for name, arr, names in (("xs", self.xs, self.state_names), ("us", self.us, self.input_names)):
            if arr.ndim != 2 or arr.shape != (n, len(names)):
                raise UsageError(
                    f"Trajectory: `{name}` must have shape ({n}, {len(names)}) for columns {tuple(names)}, "
                    f"got {arr.shape}"
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


def check_record_columns(record: Trajectory, system, caller: str, label: str) -> None:
    """Refuse a record whose columns are not `system`'s: state names other than the system's, in its order, or an
    input the system does not have (a record may leave out an optional input, as a quadrotor's `vbat`). Another
    system's record, or columns in another order, would otherwise be fitted as this system's. `system` is read
    for `state_names` and `input_names` only; `label` names the record in the message.
    """
    others = [n for n in record.input_names if n not in system.input_names]
    if tuple(record.state_names) != tuple(system.state_names) or others:
        raise UsageError(
            f"{caller}: {label} has columns {tuple(record.state_names)}, {tuple(record.input_names)} but "
            f"{type(system).__name__} has {tuple(system.state_names)} and {tuple(system.input_names)}"
        )


def check_record_values(record: Trajectory, caller: str, label: str) -> None:
    """Refuse a record a fit cannot read: states or inputs that are not floating point, or a NaN or an infinity
    in them (named by column, row and time). On the host, with NumPy: nothing compiled, and a traced record
    (under `jit`) is left alone. `label` names the record in the message (`"record 0 of `data`"`).
    """
    for name in ("xs", "us"):
        arr = getattr(record, name)
        if not np.issubdtype(arr.dtype, np.floating):
            raise UsageError(
                f"{caller}: {label}: `{name}` holds {arr.dtype}, not floating point; give float arrays "
                "(`trajectory.astype(jnp.float64)`)"
            )
    if any(isinstance(a, Tracer) for a in (record.xs, record.us)):
        return
    for arr, names in ((record.xs, record.state_names), (record.us, record.input_names)):
        values = np.asarray(arr)
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            row, col = (int(i) for i in bad[0])
            t = np.asarray(record.ts)[row]
            raise DataError(
                f"{caller}: {label}: a sample of {values[row, col].item()!r} at t = {float(t):g} s "
                f"({len(bad)} non-finite sample(s) in all); cut the stretch (`dynax.exclude_stretches`) or fill it",
                path=record.source or None,
                column=names[col],
                row=row + 1,
            )
