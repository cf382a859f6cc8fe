"""The method library: one small module per method family, and the registry.

Each method module exposes ``NAME``, ``SUMMARY``, ``applies(system) -> str |
None`` (None when the method applies, else the reason it does not) and
``build(system) -> Scheme``.
"""

from __future__ import annotations

import dataclasses
from types import ModuleType

from ...errors import InputError, MethodNotApplicable
from ...problem.poisson import PoissonSystem, is_poisson
from ...problem.problem import Hamiltonian
from . import energy_collocation, energy_momentum, gauss, kahan, midpoint, projected, stormer_verlet, trapezoidal
from .base import Scheme, Traits, is_quadratic_field, method_key
from .discrete_gradients import AVF, Gonzalez, ItohAbe
from .rattle import Rattle, Shake

__all__ = ["METHODS", "SYMMETRIC_METHODS", "POISSON_METHODS", "Scheme", "Traits", "discretize", "applicable_methods",
           "method_names", "composition_for", "method_key", "scheme_options"]

METHODS: dict[str, ModuleType] = {m.NAME: m for m in (
    midpoint, energy_momentum, trapezoidal, kahan, AVF, Gonzalez, ItohAbe, stormer_verlet,
    Rattle, Shake, gauss, energy_collocation, projected)}


def method_names() -> list[str]:
    return list(METHODS)


def applicable_methods(system: Hamiltonian) -> list[str]:
    """Names of the methods that apply to ``system`` (a time-dependent one: to its autonomous
    extension, :func:`methodgen.autonomise`)."""
    from ..timetransform import autonomise

    system = autonomise(system)
    return [name for name in METHODS if _applies(name, system) is None]


#: Methods for Poisson systems ``y' = S(y)∇H``: the midpoint rule and the discrete gradients
#: as ``y1 = y0 + h S(ȳ)∇̄H`` (:func:`methodgen.symbolic.schemes.base.gradient_scheme`), and Kahan's
#: Jacobian form on the quadratic field ``f = S∇H``.  The others need canonical (q, p).
POISSON_METHODS = ("midpoint", "avf", "gonzalez", "itoh-abe", "kahan")


def _applies(name: str, system) -> str | None:
    """None when method ``name`` applies to ``system``, else the reason (Poisson systems included)."""
    if is_poisson(system):
        if name not in POISSON_METHODS:
            return (f"{name} needs canonical coordinates (q, p) (a Hamiltonian, not a Poisson system "
                    "y' = S(y)∇H)")
        if name == "kahan" and not is_quadratic_field(system):
            return ("Kahan's method on a Poisson system is generated in its Jacobian form, which "
                    "needs a quadratic vector field f = S∇H")
    return METHODS[name].applies(system)


def discretize(system: Hamiltonian, method: str, *, order: int = 2, composition: str | None = None,
               **options) -> Scheme:
    """Discretise ``system`` with ``method`` and return the symbolic :class:`Scheme`.

    Parameters
    ----------
    system : Hamiltonian
        A time-dependent system (``time="t"``) is discretised as its autonomous extension
        ``K = H(q, p, t) + e`` on ``(q, t; p, e)`` (:func:`methodgen.autonomise`): the
        scheme's system is K.
    method : str
        One of :data:`METHODS` (``methodgen methods`` lists them).
    order : {2, 4, 6, 8, 10}
        Order of the method.  Above 2 the (symmetric, order-2) base method is
        composed symmetrically, ``Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}``
        (:mod:`methodgen.symbolic.compositions`); exact invariants, symplecticity and
        symmetry of the base method are kept.
    composition : str, optional
        Coefficient family for ``order > 2``: one of
        :data:`methodgen.symbolic.compositions.FAMILIES`; default
        :data:`methodgen.symbolic.compositions.DEFAULT_FAMILY` ``[order]``.
    **options
        Method options, e.g. ``form="rk"`` for Kahan, ``nodes=`` for AVF quadrature.

    Raises
    ------
    InputError
        Unknown method name (the message lists the known ones).
    MethodNotApplicable
        The method does not apply to this system (the message says why and lists
        the methods that do).
    """
    if not isinstance(system, (Hamiltonian, PoissonSystem)):
        raise InputError(f"discretize expects a methodgen.Hamiltonian or PoissonSystem, got "
                         f"{type(system).__name__}")
    if method not in METHODS:
        from ..nbody import FAMILIES as WH_FAMILIES
        hint = (f" ({method!r} is a Wisdom–Holman splitting of [nbody] scenes: methodgen.wisdom_holman(scene, "
                f"{method!r}), methodgen run SCENE --method {method})" if method in WH_FAMILIES else "")
        raise InputError(f"unknown method {method!r}; known methods: {', '.join(METHODS)}{hint}")
    from ..timetransform import autonomise

    system = autonomise(system)
    mod = METHODS[method]
    reason = _applies(method, system)
    if reason is not None:
        ok = applicable_methods(system)
        tt = getattr(system, "time_transform", None)
        if tt is not None and tt.autonomised:
            # The method was asked for K, not for the H the user wrote: say so.
            why = (f" (its kinetic part T(p) + {tt.energy} is linear in {tt.energy}: no mass matrix)"
                   if "kinetic" in reason else "")
            reason = (f"a time-dependent H is integrated as its autonomous extension K = H(q, p, "
                      f"{tt.time}) + {tt.energy} on ({', '.join(s.name for s in system.q)}; "
                      f"{', '.join(s.name for s in system.p)}){why}: {reason}")
        raise MethodNotApplicable(f"{reason}. Methods that apply to this system: "
                                  f"{', '.join(ok) if ok else '(none)'}")
    comp = composition_for(order, composition)
    if getattr(comp, "kind", None) == "splitting":
        _check_splitting(comp, method, system)   # before deriving the base step
    # ``project=``: symmetric projection of the (composed) step, applied last (methodgen.symbolic.projection)
    project = options.pop("project", None)
    implied = getattr(mod, "PROJECT", None)   # a method name that stands for a projection
    try:
        scheme = mod.build(system, **options)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            raise InputError(f"method {method!r} does not take options {sorted(options)}") from None
        raise
    if system.time_transform is not None and scheme.resolution is not None:
        # The Jacobian's h·ω reading is a norm, not an eigenvalue: after a time transformation
        # the variables are badly scaled near the encounter (Kepler, g = |q|: ∂q'/∂p ~ r,
        # ∂p'/∂q ~ 1/r², eigenvalues ~ r^(-1/2)), so it would refuse resolved steps.  The
        # local error estimate, which is relative to the step, guards every step instead.
        scheme = dataclasses.replace(scheme, resolution=None)
    if comp is None:
        return _projected(scheme, project, implied, method)
    if getattr(comp, "kind", None) == "splitting":
        return _projected(scheme.compose(comp), project, implied, method)
    t = scheme.traits
    if not (t.symmetric and t.order == 2):
        ok = [m for m in applicable_methods(system) if m in SYMMETRIC_METHODS]
        raise MethodNotApplicable(
            f"order {order} is built by symmetric composition, which needs a symmetric method of "
            f"order 2; {method} is {'not symmetric' if not t.symmetric else f'of order {t.order}'} "
            f"for this system. Symmetric methods that apply: {', '.join(ok) if ok else '(none)'}")
    return _projected(scheme.compose(comp), project, implied, method)


def _projected(scheme: Scheme, project, implied, method: str) -> Scheme:
    """``scheme`` with the symmetric projection ``project``, or the one its method name
    stands for (``implied``: the projected scheme then carries that name; an explicit
    ``project`` equal to it is not repeated in the key)."""
    if project is None and implied is None:
        return scheme
    from ..projection import project_scheme

    out = project_scheme(scheme, project or implied, record=project not in (None, implied))
    return dataclasses.replace(out, method=method) if implied is not None else out


def _check_splitting(comp, method: str, system):
    """``comp`` (a :class:`methodgen.symbolic.splittings.Splitting`) if it applies to ``method`` on
    ``system``, else InputError / MethodNotApplicable saying why."""
    from ..derive import separable_split

    from ..compositions import FAMILIES
    from ..splittings import RKN_FAMILIES, SPLITTING_FAMILIES

    # Worded for the API and the CLI alike (composition= there, --composition here), and the
    # alternatives offered are those with the requested order.
    # (stormer-verlet-projected runs Störmer–Verlet's kicks and drifts, then projects)
    if method not in ("stormer-verlet", "stormer-verlet-projected"):
        alt = [f for f, orders in FAMILIES.items() if comp.order in orders]
        raise InputError(f"the {comp.family} family is a splitting of H = T + U: it is run with method "
                         f"'stormer-verlet' (or 'stormer-verlet-projected') only, not {method!r} "
                         f"(composition families of order "
                         f"{comp.order} for {method}: {', '.join(alt) if alt else '(none)'})")
    sep = separable_split(system)
    if comp.rkn and (sep is None or sep.Minv is None):
        alt = [f for f, orders in SPLITTING_FAMILIES.items() if comp.order in orders and f not in RKN_FAMILIES]
        raise MethodNotApplicable(
            f"the {comp.family} splitting has order {comp.order} for T = p^T M^-1 p / 2 with a constant "
            f"mass matrix only (Runge-Kutta-Nystrom); this T is not of that form. Splitting families "
            f"of order {comp.order} for every T: {', '.join(alt) if alt else '(none)'}")
    return comp


#: Methods that are symmetric of order 2 on every system they apply to (Itoh–Abe is not).
SYMMETRIC_METHODS = ("midpoint", "energy-momentum", "trapezoidal", "kahan", "avf", "gonzalez",
                     "stormer-verlet", "rattle", "shake", "stormer-verlet-projected")


def scheme_options(method: str, options: dict) -> tuple:
    """The options that select a scheme variant, in the order the key lists them: those
    that differ from the method's defaults (``stages=3`` for gauss; ``stages=2`` is the
    default and so the plain ``"gauss"``)."""
    import inspect

    mod = METHODS.get(method)
    if mod is None or not options:
        return ()
    params = inspect.signature(mod.build).parameters
    return tuple((k, v) for k, v in sorted(options.items())
                 if not (k in params and params[k].default == v))


def composition_for(order, family: str | None = None):
    """The :class:`~methodgen.symbolic.compositions.Composition` for ``order`` (None for order 2).

    Raises
    ------
    InputError
        For an order not in :data:`~methodgen.symbolic.compositions.ORDERS`, an unknown family,
        or a family without that order (the message lists what is valid).
    """
    from ..compositions import DEFAULT_FAMILY, ALL_FAMILIES, ORDERS, composition as _composition

    if isinstance(order, bool) or not isinstance(order, int) or order not in ORDERS:
        raise InputError(f"order must be one of {', '.join(map(str, ORDERS))}, got {order!r}")
    if order == 2:
        if family not in (None, "base"):
            raise InputError(f"composition={family!r} needs order > 2 (order 2 is the base method)")
        return None
    if family is not None and family not in ALL_FAMILIES:
        raise InputError(f"unknown composition family {family!r}; families: {', '.join(ALL_FAMILIES)} "
                         f"(default for order {order}: {DEFAULT_FAMILY[order]})")
    if family is not None and order not in ALL_FAMILIES[family]:
        have = [f for f, orders in ALL_FAMILIES.items() if order in orders]
        raise InputError(f"the {family} family has orders {', '.join(map(str, ALL_FAMILIES[family]))}, not "
                         f"{order}; families with order {order}: {', '.join(have)}")
    from ..compositions import PROCESSED_FAMILIES

    if family in PROCESSED_FAMILIES:
        raise InputError(f"the {family} family is a processed composition (a kernel between two processors, "
                         f"three generated modules): methodgen.build(system, method, order={order}, "
                         f"composition={family!r}) builds it, not one composed scheme "
                         "(methodgen.codegen.build.build_processed)")
    return _composition(order, family)
