"""Lowering: a symbolic :class:`~methodgen.schemes.base.Scheme` → frozen IR.

The IR is plain data (strings and tuples) that the templates render without
further thought: every kernel is a list of common-subexpression assignments
followed by its outputs, printed twice —

* a **scalar** flavour on Python floats with :mod:`math` (a single trajectory:
  no array overhead in the Newton loop), and
* a **vector** flavour on numpy arrays with arbitrary leading batch shape.

Printing goes through subclasses of SymPy's code printers (never by hand), CSE
is always on, and every ordering is canonical, so the same scheme always
lowers to the same IR.

User symbol names are used as Python variable names in generated code after
sanitising: a name that collides with a Python builtin, with ``numpy`` or
``math`` gets trailing underscores until it is unique.  Internal names all
start with ``_`` (user names cannot), so they cannot collide.
"""

from __future__ import annotations

import builtins
import keyword
from dataclasses import dataclass

import sympy as sp
from sympy.printing.numpy import NumPyPrinter
from sympy.printing.pycode import PythonCodePrinter

from .derive import Invariant
from .special import HELPER_DEPENDENCIES, SPECIAL_FUNCTIONS

__all__ = ["Kernel", "ModuleIR", "lower", "sanitize_names"]

_RESERVED = set(dir(builtins)) | set(keyword.kwlist) | set(keyword.softkwlist) | {"numpy", "math"}


def sanitize_names(names: list[str]) -> dict[str, str]:
    """Map user names to Python identifiers safe to use as local variables."""
    out: dict[str, str] = {}
    taken = set(names)
    for n in names:
        v = n
        if v in _RESERVED:
            v = n + "_"
            while v in taken or v in _RESERVED:
                v += "_"
            taken.add(v)
        out[n] = v
    return out


def _special_printer(prefix: str):
    def method(self, expr):
        args = ", ".join(self._print(a) for a in expr.args)
        return f"{prefix}{SPECIAL_FUNCTIONS[type(expr)][1:]}({args})"
    return method


class ScalarPrinter(PythonCodePrinter):
    """Python floats + :mod:`math`; half-integer powers through ``math.sqrt``."""

    def _print_Pow(self, expr, rational=False):
        b, e = expr.args
        if e.is_Rational and e.q == 2 and abs(e.p) != 1:
            root = f"math.sqrt({self._print(b)})"
            power = root if abs(e.p) == 1 else f"{root}**{abs(e.p)}"
            return power if e.p > 0 else f"1/{power}"
        return super()._print_Pow(expr, rational=rational)


class VectorPrinter(NumPyPrinter):
    """numpy arrays of any leading (batch) shape."""

    def _print_Max(self, expr):
        args = [self._print(a) for a in expr.args]
        out = args[-1]
        for a in reversed(args[:-1]):
            out = f"numpy.maximum({a}, {out})"
        return out

    def _print_Pow(self, expr, rational=False):
        b, e = expr.args
        if e == -1:
            return f"1/{self.parenthesize(b, sp.printing.precedence.PRECEDENCE['Pow'])}"
        if e.is_Rational and e.q == 2 and abs(e.p) != 1:
            root = f"numpy.sqrt({self._print(b)})"
            power = f"{root}**{abs(e.p)}"
            return power if e.p > 0 else f"1/{power}"
        return super()._print_Pow(expr, rational=rational)


for _cls in SPECIAL_FUNCTIONS:
    setattr(ScalarPrinter, f"_print_{_cls.__name__}", _special_printer("_f_"))
    setattr(VectorPrinter, f"_print_{_cls.__name__}", _special_printer("_v_"))


@dataclass(frozen=True)
class Kernel:
    """One generated function body.

    Attributes
    ----------
    temps : tuple of (str, str)
        CSE assignments ``name = code`` in evaluation order.
    outputs : tuple of (tuple of int, str)
        ``(index, code)`` for each non-trivial output entry.
    shape : tuple of int
        Shape of the output (without batch axes).
    """

    temps: tuple[tuple[str, str], ...]
    outputs: tuple[tuple[tuple[int, ...], str], ...]
    shape: tuple[int, ...]

    def entries(self) -> list[str]:
        """Codes of all entries in C order, ``0.0`` where there is no output (scalar lists)."""
        table = dict(self.outputs)
        out = []
        for flat in range(int(sp.prod(self.shape))):
            idx = tuple(int(i) for i in _unravel(flat, self.shape))
            out.append(table.get(idx, "0.0"))
        return out

    def rows(self) -> list[list[str]]:
        """Entries of a 2-D kernel as rows."""
        flat = self.entries()
        n, m = self.shape
        return [flat[i * m:(i + 1) * m] for i in range(n)]


def _unravel(flat: int, shape: tuple[int, ...]) -> tuple[int, ...]:
    idx = []
    for dim in reversed(shape):
        idx.append(flat % dim)
        flat //= dim
    return tuple(reversed(idx))


@dataclass(frozen=True)
class ModuleIR:
    """Everything the templates need, as plain data."""

    module_name: str
    system_name: str
    method: str
    description: str
    kind: str
    order: int
    traits: dict
    source: str
    constraints: tuple[str, ...]
    q_names: tuple[str, ...]
    p_names: tuple[str, ...]
    state_vars: tuple[str, ...]
    param_names: tuple[str, ...]
    param_vars: tuple[str, ...]
    param_defaults: tuple[str, ...]
    unknown_names: tuple[str, ...]
    invariant_names: tuple[str, ...]
    invariant_exprs: tuple[str, ...]
    scalar: dict
    vector: dict
    helpers: tuple[str, ...]
    signature: str
    resolution: str | None = None
    fixed_point: bool = False

    @property
    def dim(self) -> int:
        return len(self.q_names)

    @property
    def n_unknowns(self) -> int:
        return len(self.unknown_names)

    @property
    def n_constraints(self) -> int:
        return len(self.constraints)

    @property
    def unknown_vars(self) -> tuple[str, ...]:
        # Unknowns are internal symbols (leading underscore): already safe.
        return self.unknown_names


def _cse(exprs: tuple) -> tuple:
    """CSE of a tuple of expressions, memoised: the scalar and the vector flavour of a
    kernel print the same reduced expressions, so eliminate once."""
    key = exprs
    hit = _CSE_CACHE.get(key)
    if hit is None:
        hit = sp.cse(list(exprs), symbols=sp.numbered_symbols("_c"),
                     order="canonical")
        _CSE_CACHE.clear()  # keep only the latest kernel (they come in scalar/vector pairs)
        _CSE_CACHE[key] = hit
    return hit


_CSE_CACHE: dict = {}


def _kernel(exprs: list[sp.Expr], shape: tuple[int, ...], printer, rename: dict) -> Kernel:
    exprs = tuple(sp.sympify(e).xreplace(rename) for e in exprs)
    temps, reduced = _cse(exprs)
    tcode = tuple((str(s), printer.doprint(e)) for s, e in temps)
    outputs = []
    for flat, e in enumerate(reduced):
        if e == 0:
            continue
        outputs.append((_unravel(flat, shape), printer.doprint(e)))
    return Kernel(tcode, tuple(outputs), shape)


def _helpers(exprs) -> tuple[str, ...]:
    used = set()
    for e in exprs:
        for f in sp.sympify(e).atoms(sp.Function):
            if type(f) in SPECIAL_FUNCTIONS:
                used.add(SPECIAL_FUNCTIONS[type(f)][1:])
    # Close over the helpers a helper calls (e.g. expdd calls sinhc).
    todo = list(used)
    while todo:
        for dep in HELPER_DEPENDENCIES.get(todo.pop(), ()):
            if dep not in used:
                used.add(dep)
                todo.append(dep)
    return tuple(sorted(used))


def lower(scheme, signature: str, module_name: str) -> ModuleIR:
    """Lower ``scheme`` to a :class:`ModuleIR` (deterministic).

    Parameters
    ----------
    scheme : Scheme
    signature : str
        The signature hash to embed (see :func:`methodgen.emit.signature`).
    module_name : str
        Python module name of the generated file.
    """
    system = scheme.system
    user = [s.name for s in system.y] + list(system.param_names)
    names = sanitize_names(user)
    rename = {s: sp.Symbol(names[s.name], real=True) for s in list(system.y) + list(system.params)}
    sp_ = ScalarPrinter({"fully_qualified_modules": True})
    vp = VectorPrinter({"fully_qualified_modules": True})

    n = len(scheme.unknowns)
    d2 = 2 * system.dim
    res = list(scheme.residual)
    jac = list(scheme.jacobian) if n else []
    inc = list(scheme.increment)
    guess = list(scheme.guess)
    invs: tuple[Invariant, ...] = scheme.invariants
    inv_exprs = [inv.expr for inv in invs]

    scalar = {}
    vector = {}
    if n:
        scalar["guess"] = _kernel(guess, (n,), sp_, rename)
        vector["guess"] = _kernel(guess, (n,), vp, rename)
        scalar["resjac"] = _kernel(res + jac, (n + n * n,), sp_, rename)
        vector["resjac"] = _kernel(res + jac, (n + n * n,), vp, rename)
        scalar["res"] = _kernel(res, (n,), sp_, rename)
        vector["res"] = _kernel(res, (n,), vp, rename)
        if scheme.unknown_scale is not None:
            scalar["scale"] = _kernel([scheme.unknown_scale], (1,), sp_, rename)
            vector["scale"] = _kernel([scheme.unknown_scale], (1,), vp, rename)
    scalar["increment"] = _kernel(inc, (d2,), sp_, rename)
    vector["increment"] = _kernel(inc, (d2,), vp, rename)
    vector["hamiltonian"] = _kernel([system.H], (1,), vp, rename)
    vector["invariants"] = _kernel(inv_exprs, (len(inv_exprs),), vp, rename)
    n_cons = len(system.constraints)
    if n_cons:
        # Constraint machinery only where there are constraints: g, G = ∂g/∂q and M⁻¹
        # for checking and projecting initial values onto T*Q.
        from .derive import constraint_jacobian, separable_split
        G = constraint_jacobian(system)
        Minv = separable_split(system).Minv
        vector["constraints"] = _kernel(list(system.constraints) + list(G), (n_cons + n_cons * system.dim,),
                                        vp, rename)
        vector["minv"] = _kernel(list(Minv), (system.dim * system.dim,), vp, rename)

    all_exprs = res + jac + inc + guess + [system.H] + inv_exprs
    return ModuleIR(
        module_name=module_name,
        system_name=system.name or "system",
        method=scheme.method,
        description=scheme.description,
        kind=scheme.traits.solve,
        order=scheme.traits.order,
        traits=scheme.traits.as_dict(),
        source=system.source,
        constraints=tuple(system.constraint_sources),
        q_names=tuple(s.name for s in system.q),
        p_names=tuple(s.name for s in system.p),
        state_vars=tuple(names[s.name] for s in system.y),
        param_names=tuple(system.param_names),
        param_vars=tuple(names[k] for k in system.param_names),
        param_defaults=tuple(repr(system.param_values[k]) for k in system.param_names),
        unknown_names=tuple(s.name for s in scheme.unknowns),
        invariant_names=tuple(inv.name for inv in invs),
        invariant_exprs=tuple(str(inv.expr) for inv in invs),
        scalar=scalar,
        vector=vector,
        helpers=_helpers(all_exprs),
        signature=signature,
        resolution=scheme.resolution,
        fixed_point=scheme.fixed_point,
    )
