"""What to fit: a filter over a model's pytree, flattened to one vector with names from the tree paths."""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree
import numpy as np

from .._errors import UsageError


def _resolve(filter_spec, model):
    """A mask per leaf of `model`: `filter_spec` is a prefix of `model` whose leaves are bools,
    callables on leaves (as for `eqx.partition`), or boolean arrays shaped like the leaf (select
    elements)."""

    def expand(f, sub):
        return jax.tree.map(lambda x: f(x) if callable(f) else f, sub)

    return jax.tree.map(expand, filter_spec, model)


def _path_name(path) -> str:
    return jax.tree_util.keystr(path).lstrip(".")


class Parameters(eqx.Module):
    r"""The free parameters of a model: which array elements move, in one flat vector, with names.

    This is dynax's one way to say what to fit. It is made from a *filter* over the model's pytree,
    exactly as `eqx.partition` takes one (a prefix pytree of bools or of callables such as
    `eqx.is_inexact_array`), with one extension: a leaf of the filter may be a boolean NumPy array
    shaped like the model's leaf, which frees only those elements (the helicopter's feature mask).

    Names come from the tree paths, `keystr` style without the leading dot: `theta1`,
    `system.theta5`, `terms[0].coefficient`, `body_model.weights[2,4]`; a system may give readable
    labels instead (`names=`), in the same order. The same names appear in results, JSON, reports
    and standard errors.

    All fields are static: a `Parameters` is hashable and costs nothing to pass through `jit`.

    **Fields:**

    - `names`: one per free element, in vector order.
    - `selection`: per model leaf (in `jax.tree.leaves` order), the flat indices of its free elements.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    selection: tuple[tuple[int, ...], ...] = eqx.field(static=True)

    @classmethod
    def of(
        cls, model: PyTree, filter_spec: PyTree[Any] | None = None, *, names: tuple[str, ...] | None = None
    ) -> "Parameters":
        """The parameters of `model` selected by `filter_spec`.

        **Arguments:**

        - `model`: any pytree (an `AbstractSystem`, an `Extended` model, a parameter vector).
        - `filter_spec`: the filter; default the model's own `parameter_filter()` (and its
          `parameter_labels()` as names) where it has one, otherwise every inexact array leaf.
        - `names`: labels to use instead of the tree-path names (same count).
        """
        if filter_spec is None:
            default = getattr(model, "parameter_filter", None)
            filter_spec = default() if callable(default) else eqx.is_inexact_array
            labels = getattr(model, "parameter_labels", None)
            if names is None and callable(labels):
                names = labels()
        try:
            masks = _resolve(filter_spec, model)
        except ValueError as error:
            raise UsageError(f"Parameters: the filter does not match the model's structure ({error})") from None
        leaves = jax.tree_util.tree_flatten_with_path(model)[0]
        mask_leaves = jax.tree.leaves(masks, is_leaf=lambda m: isinstance(m, np.ndarray))
        if len(mask_leaves) != len(leaves):
            raise UsageError(f"Parameters: the filter has {len(mask_leaves)} leaves, the model {len(leaves)}")
        selection, found = [], []
        for (path, leaf), mask in zip(leaves, mask_leaves):
            if not eqx.is_inexact_array(leaf) or mask is False or mask is None:
                selection.append(())
                continue
            shape = np.shape(leaf)
            if isinstance(mask, np.ndarray):
                if mask.shape != shape:
                    raise UsageError(
                        f"Parameters: the mask of `{_path_name(path)}` has shape {mask.shape}, the leaf {shape}"
                    )
                flat = tuple(int(i) for i in np.flatnonzero(mask.astype(bool)))
            elif mask is True:
                flat = tuple(range(int(np.prod(shape, dtype=int))))
            else:
                raise UsageError(f"Parameters: the filter's leaf for `{_path_name(path)}` is {mask!r}, not a bool")
            selection.append(flat)
            base = _path_name(path)
            if shape == ():
                found.extend([base] * len(flat))
            else:
                found.extend(f"{base}[{','.join(map(str, np.unravel_index(i, shape)))}]" for i in flat)
        if names is not None:
            names = tuple(names)
            if len(names) != len(found):
                raise UsageError(f"Parameters: {len(names)} names for {len(found)} free elements")
            found = names
        return cls(tuple(found), tuple(selection))

    @property
    def size(self) -> int:
        return len(self.names)

    def vector(self, model: PyTree) -> Float[Array, " n"]:
        """The free elements of `model`, flattened in `names` order."""
        parts = [jnp.ravel(leaf)[jnp.asarray(idx)] for leaf, idx in zip(jax.tree.leaves(model), self.selection) if idx]
        if not parts:
            return jnp.zeros(0)
        return jnp.concatenate([jnp.asarray(p) for p in parts])

    def with_vector(self, model: PyTree, vector: Float[Array, " n"]) -> PyTree:
        """A copy of `model` with the free elements set from `vector` (differentiable in `vector`)."""
        leaves, treedef = jax.tree.flatten(model)
        out, start = [], 0
        for leaf, idx in zip(leaves, self.selection):
            if not idx:
                out.append(leaf)
                continue
            values = vector[start : start + len(idx)]
            start += len(idx)
            arr = jnp.asarray(leaf)
            if len(idx) == arr.size:
                out.append(values.reshape(arr.shape).astype(jnp.result_type(arr.dtype, vector.dtype)))
            else:
                dtype = jnp.result_type(arr.dtype, vector.dtype)
                out.append(jnp.ravel(arr).astype(dtype).at[jnp.asarray(idx)].set(values).reshape(arr.shape))
        return jax.tree.unflatten(treedef, out)

    def named(self, vector) -> dict[str, float]:
        """`{name: value}` for a vector of this length."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(vector))}
