"""The identification hooks: what least-squares identification needs to know about a system whose
inverse dynamics is linear in named base parameters (`AbstractLinearInParameters`), and the one
place that answers them for any system (`identification_hooks`)."""

import abc
from collections.abc import Mapping
from typing import Any, Literal, NoReturn

import equinox as eqx
from jaxtyping import Array, ArrayLike, Float

from .._errors import UsageError
from ._system import AbstractSystem

_BOUNDS = {"positive": ("positive", lambda v: v > 0), "nonnegative": ("non-negative", lambda v: v >= 0)}


def violated_bound(name: str, value: float, kind: str | None, group: str = "", meaning: str = "") -> str | None:
    """The sentence for `name = value` breaking the sign bound of its consistency `kind` (`"positive"`,
    `"nonnegative"`; other kinds have none here), e.g. `gravity: theta4 = -0.1 must be positive (...)`;
    `None` when it holds. One wording for base parameters and joint terms alike."""
    bound = _BOUNDS.get(kind or "")
    if bound is None or bound[1](value):
        return None
    return f"{group + ': ' if group else ''}{name} = {value:.4g} must be {bound[0]}" + (
        f" ({meaning})" if meaning else ""
    )


class AbstractLinearInParameters(AbstractSystem):
    r"""A system whose inverse dynamics is linear in named base parameters, $Y(x, \dot x)\,\theta = u$:
    what least-squares identification (`dynax.identify` with `Dynamic`, `Power` or `Energy`) fits.

    Subclass it beside the dynamics' class (`class Arm(AbstractManipulator, AbstractLinearInParameters)`)
    and give `check_least_squares`, `base_parameter_names`, `energy_parameter_names` and
    `coulomb_friction_terms`; the other hooks have defaults. The regressors, the consistency checks and
    `identify` only call these hooks, through `identification_hooks`; a system that does not subclass
    this is still simulated, fitted by `SimulationFit` and diagnosed.
    """

    @abc.abstractmethod
    def check_least_squares(self, terms: tuple = ()) -> None:
        """Raise a `UsageError` naming the system if the least-squares methods cannot identify it
        extended with the joint `terms` (`dynax.Extended`)."""

    @abc.abstractmethod
    def base_parameter_names(self, friction: Literal["viscous", "coulomb"] = "viscous") -> tuple[str, ...]:
        """The base parameters the inverse dynamics is linear in, in the regressor's column order
        (joint terms' coefficients follow them), for the friction model `friction`."""

    @abc.abstractmethod
    def energy_parameter_names(self) -> tuple[str, ...]:
        """The base parameters the stored energy depends on (the others enter through dissipation only)."""

    @abc.abstractmethod
    def coulomb_friction_terms(self) -> tuple:
        """The joint terms `friction="coulomb"` adds to the identified model, at zero (empty for a
        system whose Coulomb friction is a base parameter)."""

    def with_base_parameters(self, parameters: Mapping[str, Float[ArrayLike, ""]]) -> AbstractSystem:
        """This system carrying the base parameters `parameters` (by name), e.g. an estimate.
        Default: the fields of those names are replaced, the rest are kept."""
        return replace_fields(self, parameters)

    def base_parameter_kinds(self) -> dict[str, str]:
        r"""How physical consistency bounds each base parameter (`dynax.internal.consistent_least_squares`):
        `"positive"`, `"nonnegative"`, `"free"`, or `"inertia1"` ($\theta_1 \ge \theta_3^2 / \theta_2$,
        a two-link arm's Schur complement). Joint terms' coefficients are bounded by their own kind.
        Default: no conditions (an empty dict: every parameter is free)."""
        return {}

    def upright_zero_signs(self) -> dict[tuple[str, ...], tuple[str, ...]]:
        """Per set of joints, the base parameters whose sign an angle measured from the other end
        (upright instead of hanging down: the angle shifted by pi) reverses, the equations being
        otherwise the same; `identify` names such a zero where negating them makes an inconsistent
        estimate consistent. Default: none."""
        return {}

    def base_parameter_meanings(self) -> dict[str, tuple[str, str]]:
        """Per base parameter, the group of its consistency condition and what the bound means, e.g.
        `{"theta4": ("gravity", "hanging straight down is the stable rest")}`: the words of
        `base_parameter_conditions`' sentences. Default: none."""
        return {}

    def base_parameter_conditions(self, parameters: dict[str, float]) -> tuple[str, ...]:
        """The physical-consistency conditions the base parameters `parameters` (by name) violate,
        as sentences naming them (`dynax.internal.check_consistency`).

        Default: each given parameter against its bound in `base_parameter_kinds` (`"positive"`,
        `"nonnegative"`), in the words of `base_parameter_meanings`; a system with a coupled condition
        (`"inertia1"`) adds it in its override. One statement of the bounds: the consistency-constrained
        fit reads the same kinds."""
        kinds, meanings = self.base_parameter_kinds(), self.base_parameter_meanings()
        sentences = (
            violated_bound(name, value, kinds.get(name), *meanings.get(name, ("", "")))
            for name, value in parameters.items()
        )
        return tuple(s for s in sentences if s is not None)

    def mass_check_configurations(self, qs: Float[Array, "time n_joints"]) -> Float[Array, "k n_joints"] | None:
        """Where `dynax.internal.check_consistency` evaluates the mass matrix; `None` (the default): the
        system has none to check (a manipulator checks every sample, see
        `AbstractManipulator.mass_check_configurations`)."""
        return None

    def refinement_terms(self) -> tuple | None:
        """The joint terms (at zero) that `identify`'s output-error refinement adds to the
        least-squares model, e.g. a geared motor's rotor inertia; `None` (the default) when the
        system has no output-error refinement (`identify`'s `refine="auto"` then skips it)."""
        return None


def replace_fields(system: AbstractSystem, parameters: Mapping[str, Float[ArrayLike, ""]]) -> AbstractSystem:
    """`system` with the fields named in `parameters` replaced by their values."""
    names = list(parameters)
    return eqx.tree_at(lambda s: [getattr(s, n) for n in names], system, [parameters[n] for n in names])


class NotLinearInParameters(eqx.Module):
    """The identification hooks' answers for a system that is not an `AbstractLinearInParameters` (the
    helicopter, the quadrotor, an `Extended` wrapper, a user's own): least squares refuses it by name,
    no parameter is bounded, there is no refinement; a manipulator's mass matrix is still checked."""

    system: Any

    def check_least_squares(self, terms: tuple = ()) -> NoReturn:
        raise UsageError(
            f"least-squares identification supports Acrobot, DoublePendulum and LinearAxis (optionally Extended with "
            f"joint terms), got {type(self.system).__name__}; use SimulationFit() for other systems"
        )

    def base_parameter_names(self, friction: Literal["viscous", "coulomb"] = "viscous") -> tuple[str, ...]:
        raise self._no_linear_model("base_parameter_names")

    def energy_parameter_names(self) -> tuple[str, ...]:
        raise self._no_linear_model("energy_parameter_names")

    def coulomb_friction_terms(self) -> tuple:
        raise self._no_linear_model("coulomb_friction_terms")

    def with_base_parameters(self, parameters: Mapping[str, Float[ArrayLike, ""]]) -> AbstractSystem:
        return replace_fields(self.system, parameters)

    def base_parameter_kinds(self) -> dict[str, str]:
        return {}

    def upright_zero_signs(self) -> dict[tuple[str, ...], tuple[str, ...]]:
        return {}

    def base_parameter_meanings(self) -> dict[str, tuple[str, str]]:
        return {}

    def base_parameter_conditions(self, parameters: dict[str, float]) -> tuple[str, ...]:
        return ()

    def mass_check_configurations(self, qs: Float[Array, "time n_joints"]) -> Float[Array, "k n_joints"] | None:
        # a manipulator names them (every sample) whether or not it is linear in its parameters
        configurations = getattr(self.system, "mass_check_configurations", None)
        return None if configurations is None else configurations(qs)

    def refinement_terms(self) -> tuple | None:
        return None

    def _no_linear_model(self, method: str) -> NotImplementedError:
        name = type(self.system).__name__
        return NotImplementedError(
            f"{name}.{method}: {name} declares no model linear in base parameters, so least-squares "
            "identification cannot fit it; use SimulationFit()"
        )


def identification_hooks(system) -> AbstractLinearInParameters | NotLinearInParameters:
    """The identification hooks of any system: `system` itself when it is linear in its parameters
    (`AbstractLinearInParameters`), else `NotLinearInParameters(system)`, whose answers say it is not.
    The one place a generic layer asks; no call site checks the class."""
    return system if isinstance(system, AbstractLinearInParameters) else NotLinearInParameters(system)


def least_squares_system(system, terms: tuple = ()) -> AbstractLinearInParameters:
    """`system` when least squares can identify it extended with the joint `terms`; else the
    `UsageError` of its `check_least_squares`, naming it (a system not linear in its parameters is
    refused by `NotLinearInParameters`)."""
    if not isinstance(system, AbstractLinearInParameters):
        NotLinearInParameters(system).check_least_squares(terms)
    system.check_least_squares(terms)
    return system


def friction_parameter_names(system) -> set[str]:
    """The base parameters `base_parameter_meanings` puts in the group `"friction"` (`theta6`, `theta7`;
    the axis's `viscous`, `coulomb`)."""
    meanings = identification_hooks(system).base_parameter_meanings()
    return {n for n, (group, _) in meanings.items() if group == "friction"}


def size_parameter_names(system) -> list[str]:
    """The base parameters that set the machine's size: not friction, and positive by consistency
    (`theta1`, `theta2`, `theta4`, `theta5`; the axis's `mass`). Empty for a system without kinds."""
    friction = friction_parameter_names(system)
    kinds = identification_hooks(system).base_parameter_kinds()
    return [n for n, kind in kinds.items() if kind in ("positive", "inertia1") and n not in friction]
