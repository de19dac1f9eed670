"""The nominal model of `dynax diagnose`: from `--nominal`, or the default checked against the data."""

import math
import warnings

from .._errors import DataError, UsageError


def nominal_system(name: str, parameters: dict | None = None):
    """The nominal model dynax diagnoses for a contract system name, with `parameters` (from `--nominal`) set
    (linear_axis: Coulomb friction and offset 0 unless given)."""
    from .._model import Acrobot, DoublePendulum, LinearAxis

    if name == "helicopter":
        # The Tempest acceleration model; --nominal may give its free weights by name (`du/u`, `dv/1`, ...).
        from .._diagnose._fit import nominal_parameter_names, with_nominal_values
        from .._model._helicopter import Helicopter

        system = Helicopter()
        names = nominal_parameter_names(system)
        unknown = sorted(set(parameters or {}) - set(names))
        if unknown:
            raise UsageError(f"--nominal: {unknown} are not weights of the helicopter's Tempest model {list(names)}")
        import jax.numpy as jnp

        values = dict(zip(names, system.body_model.parameter_vector()))
        values.update({k: float(v) for k, v in (parameters or {}).items()})
        return with_nominal_values(system, names, [jnp.asarray(float(values[n])) for n in names])
    else:
        cls = {"acrobot": Acrobot, "double_pendulum": DoublePendulum, "linear_axis": LinearAxis}[name]
        defaults = {"coulomb": 0.0, "offset": 0.0} if name == "linear_axis" else {}
    import jax.numpy as jnp

    values = {**defaults, **(parameters or {})}
    try:
        return cls(**{k: jnp.asarray(float(v)) for k, v in values.items()})
    except TypeError as e:
        raise UsageError(f"--nominal: parameters {sorted(values)} do not fit {cls.__name__}: {e}") from None


def check_nominal(system, path) -> None:
    """Refuse a `--nominal` model that is physically impossible, naming the file and the parameter: a
    base parameter outside its sign bound (negative inertia, mass or gravity term, negative friction)
    or an inconsistent mass matrix (`theta1 * theta2 < theta3^2`), by `dynax.internal.consistency_conditions`.
    A model whose gravity terms are negative is most often one whose angles count from upright; the
    message says so. The helicopter's Tempest weights have no such bounds."""
    from .._identify import consistency_conditions
    from .._model._linear_in_parameters import identification_hooks

    names = tuple(identification_hooks(system).base_parameter_kinds())
    violated = consistency_conditions(system, names, [float(getattr(system, n)) for n in names])
    if violated:
        hint = ""
        if any(s.startswith("gravity") for s in violated):
            hint = (
                "; negative gravity terms are what a model of angles counted from upright gives: the contract's "
                "angles are 0 hanging down (read such a rig's data with --offset q1=3.141593)"
            )
        raise DataError("the nominal model is physically impossible: " + "; ".join(violated) + hint, path=path)


def split_term_coefficients(system_name: str, parameters: dict) -> tuple[dict, str | None]:
    """`--nominal` parameters that are coefficients of the vocabulary's terms (`fc2`, `Ir2`: what `dynax
    identify --friction coulomb` and its refinement write for a two-link arm) rather than fields of the
    nominal system: set aside, since the nominal model has no such term, with a note saying so; the
    candidates of those causes test them from zero. Other unknown names are left for `nominal_system`
    to refuse."""
    if system_name == "helicopter":
        return parameters, None
    from .._diagnose._candidates import default_candidates

    system = nominal_system(system_name)
    terms = {t.parameter_name(system): t for t in default_candidates(system)}
    aside = {k: v for k, v in parameters.items() if k in terms and not hasattr(system, k)}
    if not aside:
        return parameters, None
    listed = ", ".join(f"{k} = {v:.4g} ({terms[k].cause} at {terms[k].where(system)})" for k, v in aside.items())
    note = (
        f"--nominal gave {listed}; the nominal model has no such term, so the value was set aside and the "
        f"candidates of that cause test it from zero (the diagnosis may name it again)."
    )
    return {k: v for k, v in parameters.items() if k not in aside}, note


# A size parameter whose least-squares standard error exceeds this fraction of its value is named in
# the note: the nominal model built from it is uncertain there.
LOOSE = 0.1


def nominal_from_data(system, train) -> tuple[object, str]:
    """Without `--nominal`: the default model if the training runs agree with its size, else the rigid
    body identified from them.

    Least squares (`identify(system, train, Dynamic(), refine=False, validation=Validate(holdout=0))`:
    filter settings from the data, consistency constrained) estimates the base parameters. If every size parameter
    (non-friction base parameters that consistency requires positive: theta1, theta2, theta4, theta5;
    the axis's mass; `size_parameter_names`) lies within `OTHER_MACHINE_FACTOR` of the default's (the
    defaults describe one machine: Drake's acrobot, the EMPS axis), the default model is kept.
    Otherwise the nominal model is that estimate with its friction set to zero, so that the friction
    candidates test friction (viscous and Coulomb) from zero rather than inherit the least-squares
    viscous coefficient, which absorbs part of a Coulomb friction's effect. Returns the model and a note.
    """
    import jax.numpy as jnp

    from .._diagnose._forward import OTHER_MACHINE_FACTOR
    from .._identify import Dynamic, identify, poorly_determined, PoorlyDeterminedWarning, Validate
    from .._model._linear_in_parameters import friction_parameter_names, identification_hooks, size_parameter_names

    try:
        with warnings.catch_warnings():  # said in the note, at its own threshold (`LOOSE`)
            warnings.simplefilter("ignore", PoorlyDeterminedWarning)
            identified = identify(system, train, Dynamic(), refine=False, validation=Validate(holdout=0))
    except DataError as e:  # too little excitation to tell: keep the default, and say so
        return (
            system,
            f"No --nominal: the default {type(system).__name__} parameters (least squares could not check them: {e}).",
        )
    estimate = identified.parameters
    kinds = identification_hooks(system).base_parameter_kinds()
    friction = friction_parameter_names(system)
    size = size_parameter_names(system)
    default = {n: float(getattr(system, n)) for n in size}
    ratios = {n: estimate[n] / default[n] for n in size}
    far = {n: r for n, r in ratios.items() if not 1 / OTHER_MACHINE_FACTOR <= r <= OTHER_MACHINE_FACTOR}
    listed = ", ".join(f"{n} {estimate[n]:.4g} (default {default[n]:.4g})" for n in size)
    if not far:
        return system, (
            f"No --nominal: the default {type(system).__name__} parameters, which least squares on the "
            f"training runs confirms within a factor {OTHER_MACHINE_FACTOR:g} ({listed})."
        )
    values = {n: jnp.asarray(v) for n, v in estimate.items() if n in kinds and n not in friction}
    values.update({n: jnp.zeros_like(jnp.asarray(getattr(system, n))) for n in friction})
    nominal = identification_hooks(system).with_base_parameters(values)
    worst = max(far, key=lambda n: abs(math.log(far[n])))
    note = (
        f"No --nominal, and the training runs are not the default {type(system).__name__} "
        f"(least squares: {listed}; {worst} is {far[worst]:.3g} times the default): the nominal model is "
        "the rigid body identified from the training runs by least squares, with zero friction, which "
        "the friction candidates test. Pass --nominal to diagnose against a model of your own."
    )
    loose = poorly_determined(identified.names, identified.estimate, identified.std_errors, size, threshold=LOOSE)
    if loose:
        note += (
            " Least squares determines "
            + ", ".join(f"{n} only to ±{r:.0%}" for n, r in loose.items())
            + f": the training runs excite {'them' if len(loose) > 1 else 'it'} little, and the nominal model "
            "inherits that (train on runs that move every joint, or pass --nominal)."
        )
    return nominal, note
