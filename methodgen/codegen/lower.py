"""Lowering: a symbolic :class:`~methodgen.symbolic.schemes.base.Scheme` → frozen IR.

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
import re
from dataclasses import dataclass, field, replace

import sympy as sp
from sympy.printing.numpy import NumPyPrinter
from sympy.printing.pycode import PythonCodePrinter

from .abi import PostLayout, float_config_sources, int_config_values, post_layout
from ..symbolic.compensate import compensate, compensation_symbols
from .lower_loops import (acc_symbol, force_plan, jacobian_row_scales, jacobian_via_sums, loop_prefix, potential_via_sums,
                          sum_pattern, table_names)
from ..symbolic.derive import Invariant, casimir_invariants, separable_split, vector_field
from ..symbolic.fsal import fsal_applies, fsal_plan, merged_stage
from ..symbolic.splittings import composition_stages, is_splitting
from ..problem.poisson import is_poisson
from ..errors import InputError
from ..symbolic.schemes.base import LOOP_MIN_INSTANCES, STEP, is_linear_field  # noqa: F401 (re-exported)
from ..problem.special import HELPER_DEPENDENCIES, SPECIAL_FUNCTIONS
from ..symbolic.timetransform import time_scale_guard
from .kir import Code, python
from .kir_build import MAX_PRODUCT_POWER, _power_by_squaring, _strip
from .kir_build import code as _code

__all__ = ["Kernel", "ModuleIR", "lower", "sanitize_names"]

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
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


def _squaring(base: str, n: int) -> str:
    """``base**n`` (n ≥ 2) as the products of exponentiation by squaring, parenthesised: the
    text of :func:`methodgen.codegen.kir_build._power_by_squaring`'s tree (one source of the
    order of the products)."""
    return f"({python(_strip(_power_by_squaring(('v', base), n)))})"


def _root_power(root: str, k: int) -> str:
    """A half-integer power's ``root**k`` as the compiled kernels round it."""
    return _squaring(root, k) if k <= MAX_PRODUCT_POWER else f"{root}**{k}"


def _product_power(printer, b, e):
    """An integer power ``b**e`` (2 ≤ |e| ≤ MAX_PRODUCT_POWER) as the products of
    exponentiation by squaring (:func:`methodgen.codegen.kir_build._power_by_squaring`: the
    compiled kernels' rounding), or None for any other power."""
    if not (e.is_Integer and 2 <= abs(e) <= MAX_PRODUCT_POWER):
        return None
    res = _squaring(printer.parenthesize(b, sp.printing.precedence.PRECEDENCE["Mul"]), abs(int(e)))
    return res if e > 0 else f"1/{res}"


class ScalarPrinter(PythonCodePrinter):
    """Python floats + :mod:`math`; half-integer powers through ``math.sqrt``."""

    #: the kernel IR's builder reproduces this printer's trees (methodgen.codegen.kir_build)
    kir_flavour = "scalar"

    def _print_Pow(self, expr, rational=False):
        b, e = expr.args
        product = _product_power(self, b, e)
        if product is not None:
            return product
        if e.is_Rational and e.q == 2 and abs(e.p) != 1:
            power = _root_power(f"math.sqrt({self._print(b)})", abs(e.p))
            return power if e.p > 0 else f"1/{power}"
        return super()._print_Pow(expr, rational=rational)


class CheckPrinter(ScalarPrinter):
    """ScalarPrinter for the per-step checks (no trajectory depends on their rounding):
    squares and cubes of a symbol as products and ``u**(3/2)`` as ``u*math.sqrt(u)``,
    which CPython evaluates faster than ``**``.  Squares to fourth powers of any other base
    are products too: a float ``**`` that overflows raises OverflowError where ``*`` gives
    inf, and a check (such as H at the step's end) must not fail where the state is finite."""

    kir_flavour = "check"

    def _print_Pow(self, expr, rational=False):
        b, e = expr.args
        if b.is_Symbol and e.is_Integer and 2 <= e <= 3:
            return "(" + "*".join([self._print(b)] * int(e)) + ")"
        if e.is_Integer and 2 <= e <= 4:
            base = self.parenthesize(b, sp.printing.precedence.PRECEDENCE["Mul"])
            return "(" + "*".join([base] * int(e)) + ")"
        if b.is_Symbol and e.is_Rational and e.q == 2 and abs(e.p) == 3:
            u = self._print(b)
            power = f"({u}*math.sqrt({u}))"
            return power if e.p > 0 else f"(1/{power})"
        return super()._print_Pow(expr, rational=rational)


class VectorPrinter(NumPyPrinter):
    """numpy arrays of any leading (batch) shape."""

    kir_flavour = "vector"

    def _print_Max(self, expr):
        args = [self._print(a) for a in expr.args]
        out = args[-1]
        for a in reversed(args[:-1]):
            out = f"numpy.maximum({a}, {out})"
        return out

    def _print_Pow(self, expr, rational=False):
        b, e = expr.args
        product = _product_power(self, b, e)
        if product is not None:
            return product
        if e == -1:
            return f"1/{self.parenthesize(b, sp.printing.precedence.PRECEDENCE['Pow'])}"
        if e.is_Rational and e.q == 2 and abs(e.p) != 1:
            power = _root_power(f"numpy.sqrt({self._print(b)})", abs(e.p))
            return power if e.p > 0 else f"1/{power}"
        return super()._print_Pow(expr, rational=rational)


for _cls in SPECIAL_FUNCTIONS:
    setattr(ScalarPrinter, f"_print_{_cls.__name__}", _special_printer("_f_"))
    setattr(VectorPrinter, f"_print_{_cls.__name__}", _special_printer("_v_"))


def _print_grouped(self, expr):
    # A compensated stage sum (methodgen.symbolic.compensate): its parentheses fix the association.
    return "(" + self._print(expr.args[0]) + ")"


ScalarPrinter._print_grouped = _print_grouped
VectorPrinter._print_grouped = _print_grouped


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
    loops, accs : tuple
        Loops over families of like terms that run before ``temps`` and the accumulator
        arrays they fill (empty for straight-line kernels; see :mod:`methodgen.codegen.lower_loops`).
    """

    temps: tuple[tuple[str, str], ...]
    outputs: tuple[tuple[tuple[int, ...], str], ...]
    shape: tuple[int, ...]
    #: Loops over families of like terms ahead of ``temps``
    #: (:class:`methodgen.codegen.lower_loops.Loop`) and the accumulators they fill.
    loops: tuple = ()
    accs: tuple = ()
    #: A Newton kernel whose outputs after the residual are row scales s: the Jacobian
    #: is ``I + diag(s) _sB`` (:func:`methodgen.codegen.lower_loops.jacobian_row_scales`).
    jac_rows: bool = False
    #: Straight-line assignments ahead of the loops, and the names of the first outputs they
    #: give (Δq of a looped Störmer–Verlet step), which the loops read as slot increments
    #: (load source ``"d"``) and the kernel returns first.
    pre: tuple = ()
    pre_out: tuple = ()
    _names: frozenset | None = field(default=None, repr=False, compare=False)

    def reads(self, name: str) -> bool:
        """Whether the kernel's straight-line code reads the variable ``name`` (a compiled
        kernel then loads only what it reads: its loops load their slots themselves)."""
        if self._names is None:
            found = set()
            for code in [c for _, c in self.pre + self.temps] + [c for _, c in self.outputs]:
                found.update(_IDENT.findall(code))
            object.__setattr__(self, "_names", frozenset(found))
        return name in self._names

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
    #: Names of the state's compensations in the step kernels (``_c_<state var>``): the
    #: kernels evaluate the step at the exact numerical state y + c (methodgen.symbolic.compensate).
    comp_vars: tuple[str, ...]
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
    #: Local error estimate of every step (see :func:`local_error_plan`): ``"carry"`` (E from
    #: the field at both ends of the step, its start value carried over from the previous
    #: step), ``"direct"`` (E computed by the ``post`` kernel) or None (linear field: exempt).
    local_error: str | None = None
    #: State components the estimate E lives in, and those of Δy it is measured against.
    lerr_index: tuple[int, ...] = ()
    lerr_norm: tuple[int, ...] = ()
    #: E = lerr_scale * (Δy - T) (Kahan: 0.5, see local_error_plan), as Python source.
    lerr_scale: str = "1.0"
    #: The embedded partner of the method, for the module documentation.
    lerr_partner: str = ""
    #: Real-domain conditions of H and the constraints that a trajectory can violate:
    #: ``(kind, expression)``, kind ``"positive"`` (log, negative fractional power) or
    #: ``"nonnegative"`` (positive fractional power such as sqrt).
    domain: tuple[tuple[str, str], ...] = ()
    #: The energy-jump test is made (see energy_jump): the post kernel also gives H and
    #: Σ|terms of H| at y1, unless ``energy_jump_step``.
    energy_jump: bool = False
    #: A composition's energy-jump test: once per composed step, H and its size at the step's
    #: end from the ``hs`` kernel (the post kernel does not give them).
    energy_jump_step: bool = False
    #: Symmetric composition of the base step: family, order, stages, source (None: the base
    #: method), and its coefficients γ_i as float64 reprs (``stages`` of them).
    composition: dict | None = None
    gammas: tuple[str, ...] = ("1.0",)
    #: For a Poincaré time-transformed system: ``g``, the names of the physical time
    #: coordinate and its momentum, the original H (text) and the index of its monitor
    #: among the invariants.  None otherwise.
    time_transform: dict | None = None
    #: For a Poisson system y' = S(y)∇H: its state names, S as text (``matrix``: rows of
    #: entries; ``matrix_text``: one line), the Casimirs' names and the Jacobi-identity
    #: verdict.  None for a canonical system (``q_names``, ``p_names``).
    poisson: dict | None = None
    #: Index tables of the loops over families of like terms: ``(name, rows)``, rows of
    #: ints (coordinates' positions in q, or parameters' positions); empty without loops.
    loop_tables: tuple = ()
    #: Lower and upper bandwidth ``(kl, ku)`` of the Newton matrix (its structural nonzeros:
    #: ``J[i, j] ≡ 0`` for ``i - j > kl`` or ``j - i > ku``); ``(n - 1, n - 1)`` when dense.
    #: Gaussian elimination with partial pivoting then touches only the band (the pivot
    #: rows' fill stays within ``kl + ku``): a chain costs O(n), not O(n³), per solve
    #: (:func:`jacobian_band`).
    band: tuple[int, int] = (0, 0)
    #: First-same-as-last Störmer–Verlet (:mod:`methodgen.symbolic.fsal`): the names of the start
    #: force ∇U(q0) that the post kernel takes as input ``_g`` and returns, as the end
    #: force, right after Δy; empty for every other method.
    fsal_vars: tuple[str, ...] = ()
    #: For first-same-as-last modules: each stage's step fractions (kick with the carried
    #: force, drift, kick with the new force), as reprs; (γ_k/2, γ_k, γ_k/2) for a
    #: composition, the splitting's stages for a splitting (:mod:`methodgen.symbolic.splittings`).
    stage_kick_a: tuple[str, ...] = ("0.5",)
    stage_drift: tuple[str, ...] = ("1.0",)
    stage_kick_b: tuple[str, ...] = ("0.5",)
    #: True for a splitting family (stages that are not Störmer–Verlet steps).
    splitting: bool = False
    #: A composed first-same-as-last Störmer–Verlet step run with merged kicks (every runtime:
    #: :func:`methodgen.runtime.stepper.stepper`): the state (q0, p0) stays fixed through the
    #: composed step, its increment so far D (starting from the compensation) is what the stages
    #: add to, each stage's post kernel is called at (q0, p0) + D with the kick ``_ha`` the merged
    #: b_{k-1} + a_k and ``_hb`` 0 (the stage's own last kick is the next stage's first), and
    #: (q0, p0) + D is summed once per composed step (Kahan).  Only where each stage's values read
    #: the state through y + c (no domain condition, time transformation, stage H, projection,
    #: carried estimate), the state is (q, p), T is quadratic (the estimate reads Δq and the
    #: forces, not Δp) and the stages are Störmer–Verlet steps (not a splitting's).
    merged_kicks: bool = False
    #: An s-stage implicit method lowered by structure (:func:`stage_tables`): the tables
    #: its residual and Newton-matrix loops read (float reprs); None where the residual and
    #: the Newton matrix are straight-line kernels.
    stage: dict | None = None
    #: Symmetric projection (:mod:`methodgen.symbolic.projection`): the projected invariants' names,
    #: H first (kernel ``proj``: their values, their gradients row by row, then the metric
    #: w of the direction diag(w) Gᵀ); empty without projection.
    projection: tuple[str, ...] = ()
    #: False for the standard projection (Φ_h once per step; not symmetric).
    projection_symmetric: bool = True

    @property
    def stages(self) -> int:
        return len(self.gammas)

    @property
    def gamma_ratios(self) -> tuple[str, ...]:
        """γ_i / γ_{i-1} (γ_0 / γ_{s-1} = 1 for i = 0: the sequence is palindromic), as reprs.

        A processor's sequence (:mod:`methodgen.symbolic.processing`) is not palindromic: its modules
        are run one step at a time, where the first stage starts from (γ_0 h / 2) f (ratio 1)."""
        g = [float(x) for x in self.gammas]
        return tuple(repr(g[i] / g[i - 1]) if i else "1.0" for i in range(len(g)))

    @property
    def dim(self) -> int:
        """Degrees of freedom d of a canonical system (0 for a Poisson system: see n_state)."""
        return len(self.q_names)

    @property
    def n_state(self) -> int:
        """Length of the state vector: 2d for a canonical system, n for a Poisson system."""
        return len(self.state_vars)

    @property
    def state_names(self) -> tuple[str, ...]:
        """The state's names, in state-vector order (q then p for a canonical system)."""
        return tuple(self.poisson["state"]) if self.poisson else self.q_names + self.p_names

    @property
    def n_unknowns(self) -> int:
        return len(self.unknown_names)

    @property
    def n_constraints(self) -> int:
        return len(self.constraints)

    @property
    def post(self) -> PostLayout:
        """Where each value sits in the output of the post kernel (:mod:`methodgen.codegen.abi`)."""
        return post_layout(self)

    @property
    def int_config(self) -> dict:
        """The compiled runtime's int configuration, by name (:func:`methodgen.codegen.abi.int_config_values`)."""
        return int_config_values(self)

    @property
    def float_config(self) -> dict:
        """The compiled runtime's float configuration, by name, as the Python source of the
        module's constants (:func:`methodgen.codegen.abi.float_config_sources`)."""
        return float_config_sources(self)

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


def _is_product_power(e) -> bool:
    # printed as products (kir_build): u**n, 2 <= |n| <= MAX_PRODUCT_POWER, or u**(k/2), |k| >= 3
    if not e.is_Pow or not e.exp.is_Rational:
        return False
    x = e.exp
    if x.is_Integer:
        return 2 <= abs(x) <= MAX_PRODUCT_POWER and not e.base.is_Atom
    return x.q == 2 and 3 <= abs(x.p) <= MAX_PRODUCT_POWER


def _bind_powers(temps: list, outs: list, tag: str = "") -> tuple[list, list]:
    """Bind what a power printed as products repeats: the base of ``u**n`` (u not a
    symbol) and the square root of ``u**(k/2)`` (|k| ≥ 3), each to a temporary placed before
    its first use (``_pwN = u``, ``_sqN = sqrt(u)``, or a temporary that already holds it).
    The compiled kernels evaluate the base or the root once and square it; so does the
    printed Python then, with the same products and bits, instead of repeating the base in
    every factor.

    Parameters
    ----------
    temps : list of (Symbol, Expr)
        CSE assignments in order.
    outs : list of Expr
        The reduced outputs.
    tag : str
        Part of the temporaries' names (``_pw<tag>N``): a second CSE pass of one kernel
        (:func:`_chained_kernel`) binds its own.

    Returns
    -------
    (temps, outs) with the bases and roots bound.
    """
    pw, sq = sp.numbered_symbols(f"_pw{tag}"), sp.numbered_symbols(f"_sq{tag}")
    bound: dict = {}
    fresh: list = []

    def bind(expr, names):
        r = bound.get(expr)
        if r is None:
            r = bound[expr] = next(names)
            fresh.append((r, expr))
        return r

    def power(x):
        if x.exp.is_Integer:
            return sp.Pow(bind(x.base, pw), x.exp)
        return sp.Pow(bind(sp.sqrt(x.base), sq), x.exp.p)

    def rewrite(e):
        if not isinstance(e, sp.Basic) or not e.has(sp.Pow):
            return e
        return e.replace(_is_product_power, power)

    new_temps = []
    for sym, e in temps:
        e = rewrite(e)
        new_temps += fresh
        fresh.clear()
        new_temps.append((sym, e))
        bound.setdefault(e, sym)          # a later power of the same base or root uses it
    outs = [rewrite(e) for e in outs]
    new_temps += fresh
    return new_temps, outs


def _kernel(exprs: list[sp.Expr], shape: tuple[int, ...], printer, rename: dict) -> Kernel:
    exprs = tuple(sp.sympify(e).xreplace(rename) for e in exprs)
    temps, reduced = _bind_powers(*_cse(exprs))
    tcode = tuple((str(s), _code(printer, e)) for s, e in temps)
    outputs = []
    for flat, e in enumerate(reduced):
        if e == 0:
            continue
        outputs.append((_unravel(flat, shape), _code(printer, e)))
    return Kernel(tcode, tuple(outputs), shape)


def _chained_kernel(first: list, later: list, links: tuple, printer, rename: dict,
                    later_printer=None, shared=()) -> Kernel:
    """Kernel of ``first`` followed by ``later``, which is written in the symbols ``links``
    that stand for the outputs of ``first``.  Two CSE passes: the code of ``first`` is
    exactly that of a kernel of ``first`` alone; ``later`` reuses its outputs (and is
    printed with ``later_printer``, default ``printer``).  ``shared`` subexpressions of
    ``later`` are computed once (CSE sees them as outputs too)."""
    lp = later_printer or printer
    first = tuple(sp.sympify(e).xreplace(rename) for e in first)
    later = tuple(sp.sympify(e).xreplace(rename) for e in later)
    shared = tuple(sp.sympify(e).xreplace(rename) for e in shared)
    t1, r1 = _bind_powers(*_cse(first))
    t2, r2 = (sp.cse(list(later + shared), symbols=sp.numbered_symbols("_e"), order="canonical")
              if later else ([], []))
    t2, r2 = _bind_powers(t2, r2[:len(later)], "e")
    temps = [(str(s), _code(printer, e)) for s, e in t1]
    # (a link whose expression is itself -- Δq computed ahead of the loops -- is not reassigned)
    temps += [(str(s), _code(printer, e)) for s, e in zip(links, r1) if e != s]
    temps += [(str(s), _code(lp, e)) for s, e in t2]
    outputs = [((i,), Code(("v", str(s)))) for i, s in enumerate(links)]
    outputs += [((len(links) + j,), _code(lp, e)) for j, e in enumerate(r2) if e != 0]
    return Kernel(tuple(temps), tuple(outputs), (len(links) + len(later),))


def _program_kernel(dag, printer, rename) -> Kernel:
    """Kernel of a straight-line program already reduced (:class:`methodgen.symbolic.stages.FieldDerivative`:
    f and the nonzeros of f'), printed as it is -- no second CSE over the derivative."""
    temps = tuple((str(s), _code(printer, sp.sympify(e).xreplace(rename))) for s, e in dag.assignments)
    outs = list(dag.field) + list(dag.jacobian)
    outputs = tuple(((i,), _code(printer, sp.sympify(e).xreplace(rename))) for i, e in enumerate(outs) if e != 0)
    return Kernel(temps, outputs, (len(outs),))


_HELPER_CALL = re.compile(r"\b_[fv]_([A-Za-z0-9_]+)\(")


def _helpers_called(*flavours) -> tuple[str, ...]:
    """The removable-singularity helpers the kernels' code calls (``_f_<name>(`` or
    ``_v_<name>(``, as the printers print them), with the helpers those call: read off the
    printed code, so exactly what the module needs (a scan of the expressions' function
    atoms cost seconds on an unrolled N-body step)."""
    known = {v[1:] for v in SPECIAL_FUNCTIONS.values()}
    used = set()
    for flavour in flavours:
        for k in flavour.values():
            codes = [c for _, c in k.pre + k.temps + k.outputs]
            for L in k.loops:
                codes += [c for _, c in L.temps] + [c for *_, c in L.adds]
            for code in codes:
                used.update(m for m in _HELPER_CALL.findall(code) if m in known)
    return _helper_closure(used)


def _helper_closure(used: set) -> tuple[str, ...]:
    # Close over the helpers a helper calls (e.g. expdd calls sinhc).
    todo = list(used)
    while todo:
        for dep in HELPER_DEPENDENCIES.get(todo.pop(), ()):
            if dep not in used:
                used.add(dep)
                todo.append(dep)
    return tuple(sorted(used))


@dataclass(frozen=True)
class LocalErrorPlan:
    """How a generated stepper estimates the local error of a step (:func:`local_error_plan`)."""

    kind: str                       # "carry" or "direct"
    index: tuple[int, ...]          # components of E
    norm: tuple[int, ...]           # components of Δy that E is measured against
    extra: tuple                    # what the post kernel adds after Δy (see local_error_plan)
    scale: sp.Rational              # E = scale * (Δy - T)
    partner: str
    shared: tuple = ()              # subexpressions to compute once (the components of E)


#: What E is measured against in a first-same-as-last stage (E = Δq minus it for a Störmer–Verlet
#: stage; for a splitting's stage the same formula in its kick and drift steps).
_FSAL_PARTNER = "the trapezoidal rule of the positions (the momenta already are one)"
_SPLIT_PARTNER = ("the trapezoidal rule of the positions, for a stage kick a·h, drift d·h, kick b·h written "
                  "as E = d(a + b)h²/4 M⁻¹(∇U(q1) - ∇U(q0)), its value at a = b = d/2")


def local_error_plan(scheme, dy=None, field_at_end=None, fsal=None) -> LocalErrorPlan | None:
    """The embedded error estimate ``E`` of one step ``y0 → y1 = y0 + Δy`` of ``scheme``.

    The classical embedded pair for second-order one-step methods is the
    trapezoidal rule ``T = (h/2)(f(y0) + f(y1))`` and the midpoint rule
    ``M = h f((y0 + y1)/2)`` applied to the chord of the step itself: both agree
    with the exact flow to O(h³) and their gap ``T - M = (h/8) f''(Δy, Δy) + …``
    has the size of the local error (for the exact flow, Euler–Maclaurin gives
    ``Δy - T = -(h³/12) y⁽³⁾ + O(h⁵)``).  Each method supplies the partner from
    its own stage data, so E costs at most one evaluation of f per step:

    * midpoint rule and the discrete gradients (energy-momentum, AVF, Gonzalez,
      Itoh–Abe): ``Δy/h`` is f at (or a discrete gradient near) the midpoint,
      so ``E = Δy - T``; f(y1) is evaluated together with the increment and
      carried over as f(y0) of the next step (``"carry"``);
    * Kahan: ``Δy = 2M - T``, so ``E = (Δy - T)/2 = M - T`` (scale 1/2);
    * trapezoidal rule: ``Δy = T``, so ``E = Δy - M``, with one evaluation of f
      at the midpoint of the chord (``"direct"``);
    * Störmer–Verlet, RATTLE, SHAKE: ``Δp`` is already the trapezoidal rule of
      the forces (constraint forces included), and
      ``E_q = Δq - (h/2)(∂H/∂p(y0) + ∂H/∂p(y1)) = (h²/4) M⁻¹(F(q0) - F(q1))``
      needs no evaluation of U at all (``"direct"``).  E has no momentum part
      and is measured against Δq (mass-weighted, ``|M E_q|/|M Δq|``, when the
      kinetic energy is ½pᵀM⁻¹p): the chord average of ``(hω)²/4``, ω² the
      curvature of U along the step.

    When the momenta are eliminated (separable H, Newton on Δq) the position
    part of ``Δy - T`` is the Newton residual: only the momenta are formed.
    Because E uses the field at *both ends* of the step, a step that straddles
    a fast region (a pericentre jumped over, its midpoint far from the
    singularity) has a large E where the Jacobian at the midpoint and the
    explicit predictor see nothing.

    ``dy`` are symbols standing for the components of Δy (default: the
    increment expressions themselves).  What the ``post`` kernel returns after
    Δy, so that the per-step test costs a few operations: for ``"direct"``
    ``|E|²`` and ``|Δy|²``; for ``"carry"`` ``|Δy|²``, ``a = Δy - (h/2) f(y1)``
    and ``b = (h/2) f(y1)`` on the components of E, so that ``E = a - b`` of
    the step before (or of the initial state).  The test is
    ``|E|² > (MAX_LOCAL_ERROR / scale)² |Δy|²``.

    Returns None for a linear vector field without constraints: the methods
    are then exact up to a phase error and E vanishes identically (Figure 1
    uses h·ω ≈ 5 on purpose).  Constraint forces make a linear field nonlinear.

    ``field_at_end``: the field written so that ``y → y + Δy`` gives f(y1) (a module that
    loops over sums of like terms passes its force at the step's end as the sum ``_sK``);
    default the system's vector field.

    ``fsal``: ``(G0, G1, (ha, hd, hb))`` for a first-same-as-last stage kick ha - drift hd -
    kick hb (:mod:`methodgen.symbolic.fsal`; G0, G1 the symbols of ∇U at its start and end).  The
    trapezoidal form above holds for ha = hb = hd/2 only; a splitting's stage (say
    (0, a, b)) is not a consistent step on its own, so E is written as what it is for
    Störmer–Verlet, ``(h²/4) M⁻¹ (∇U(q1) - ∇U(q0))``, with ``h²/4 → hd (ha + hb)/4``: the
    curvature of U along the stage's drift, measured against Δq as before (same value for
    Störmer–Verlet in exact arithmetic).
    """
    system = scheme.system
    if is_linear_field(system) and not system.constraints:
        return None
    h = STEP
    f = list(vector_field(system)) if field_at_end is None else list(field_at_end)
    inc = list(scheme.increment) if dy is None else list(dy)
    at1 = {s: s + dv for s, dv in zip(system.y, inc)}
    n = len(system.y)
    full = tuple(range(n))
    # "reduced": momenta eliminated (canonical systems only), E lives in the momenta p = y[d:]
    index = tuple(range(n // 2, n)) if scheme.resolution == "reduced" else full

    def squares(exprs):
        return sp.Add(*[e**2 for e in exprs])

    if system.constraints or scheme.traits.solve in ("explicit", "projection"):
        d = system.dim
        q = tuple(range(d))
        sep = separable_split(system)
        if fsal is not None:
            G0, G1, (ha, hd, hb) = fsal
            # a Störmer–Verlet stage (a composition's: kicks hd/2, exactly so in binary) reads
            # the drift alone, so that a stage called with merged kicks (ModuleIR.merged_kicks)
            # has the same estimate; a splitting's stage its own kicks
            w = hd * (ha + hb) / 4 if is_splitting(scheme.composition) else hd * hd / 4
            if sep.Minv is not None:
                M = sep.Minv.inv()
                E = [w * (G1[i] - G0[i]) for i in q]
                if sep.isotropic:
                    return LocalErrorPlan("direct", q, q, (squares(E), M[0, 0] ** 2 * squares(inc[:d])),
                                          sp.Integer(1), _FSAL_PARTNER, tuple(E))
                D = list(M * sp.Matrix(inc[:d]))
            elif not is_splitting(scheme.composition):
                # A Störmer–Verlet stage (ha = hb = hd/2) with a T that is not quadratic (e.g. the
                # logarithmic Hamiltonian): the trapezoidal defect of the positions itself, in the
                # stage's step hd, as without first-same-as-last.
                E = [inc[i] - hd / 2 * (f[i] + f[i].xreplace(at1)) for i in q]
                D = inc[:d]
            else:
                Tpp = sp.hessian(sep.T, system.p)
                E = list(w * Tpp * sp.Matrix([G1[i] - G0[i] for i in q]))
                D = inc[:d]
            return LocalErrorPlan("direct", q, q, (squares(E), squares(D)), sp.Integer(1), _FSAL_PARTNER,
                                  tuple(E) + tuple(D))
        if sep is not None and sep.Minv is not None:
            # ∂H/∂p = M⁻¹p is linear, so M E = M Δq - (h/2)(2 p0 + Δp): measured in the
            # mass-weighted norm |M·| (the same ratio for a multiple of the identity),
            # no division per step.
            M = sep.Minv.inv()
            MD = M * sp.Matrix(inc[:d])
            E = [MD[i] - h / 2 * (2 * system.p[i] + inc[d + i]) for i in q]
            D = list(MD)
            if sep.isotropic:  # |M Δq|² = m² |Δq|²: one multiplication
                D2 = M[0, 0] ** 2 * squares(inc[:d])
                return LocalErrorPlan("direct", q, q, (squares(E), D2), sp.Integer(1),
                                      "the trapezoidal rule of the positions (the momenta already are one)",
                                      tuple(E))
        else:
            E = [inc[i] - h / 2 * (f[i] + f[i].xreplace(at1)) for i in q]
            D = inc[:d]
        return LocalErrorPlan("direct", q, q, (squares(E), squares(D)), sp.Integer(1),
                              "the trapezoidal rule of the positions (the momenta already are one)",
                              tuple(E) + tuple(D))
    if scheme.method == "trapezoidal":
        mid = {s: s + dv / 2 for s, dv in zip(system.y, inc)}
        E = [inc[i] - h * f[i].xreplace(mid) for i in index]
        return LocalErrorPlan("direct", index, full, (squares(E), squares(inc)), sp.Integer(1),
                              "the midpoint rule on the chord of the step", tuple(E))
    scale = sp.Rational(1, 2) if scheme.method == "kahan" else sp.Integer(1)
    b = [h / 2 * f[i].xreplace(at1) for i in index]
    a = [inc[i] - bi for i, bi in zip(index, b)]
    return LocalErrorPlan("carry", index, full, (squares(inc), *a, *b), scale,
                          "the trapezoidal rule on the chord of the step")


def domain_conditions(system) -> tuple[tuple[str, sp.Expr], ...]:
    """Conditions for H (and the constraints) to be real that a trajectory can violate.

    ``log(u)`` needs u > 0, a fractional power ``u**e`` needs u ≥ 0 (u > 0 for
    e < 0).  Conditions SymPy proves for real states are dropped (for
    ``(x**2 + y**2)**(-1/2)`` only the singular point u = 0 is left, where the
    value is infinite and is caught as such), and so are conditions on the
    parameters alone (the initial check evaluates H there): most systems check
    nothing per step.
    """
    state = set(system.y)
    seen: dict[tuple[str, str], tuple[str, sp.Expr]] = {}
    for expr in (system.H, *system.constraints):
        for node in sp.preorder_traversal(expr):
            if isinstance(node, sp.log):
                u, kind = node.args[0], "positive"
            elif isinstance(node, sp.Pow) and node.exp.is_integer is not True:
                u = node.base
                kind = "nonnegative" if (node.exp.is_Rational and node.exp > 0) else "positive"
            else:
                continue
            if not (u.free_symbols & state) or u.is_nonnegative or u.is_positive:
                continue
            seen.setdefault((kind, sp.srepr(u)), (kind, u))
    return tuple(seen[k] for k in sorted(seen))


def energy_jump(scheme, lplan, tguard) -> tuple[sp.Expr, ...]:
    """``(H, S)``: what the energy-jump test needs, or ``()`` where it does not apply.

    A step whose end lands inside a feature thinner than the step (a barrier) changes H by
    more than H's own size, ``S = Σ|terms of H|``, and the next step may leave it again:
    the local error estimate, built from the field at the two ends, can see nothing (the
    force vanishes at the barrier's centre).  The runtimes refuse a step with
    ``|H(y1) - H(y0)| > MAX_ENERGY_JUMP · S(y0)`` (``S = |T| + |U|`` for a separable H), the values at y1 carried over as those at
    y0 of the next step (one evaluation of H per step, sharing the force's subexpressions).  Not for methods that keep H exactly
    (their H does not jump), linear fields (exempt from the resolution guards, no lplan)
    and time-transformed systems (K = 0: their own level-set guard, see
    :func:`methodgen.symbolic.timetransform.time_scale_guard`).  The caller leaves it out where H has
    domain conditions: H(y1) is evaluated in the kernel that gives the domain conditions, and a
    state outside the domain must be reported as such, not as a failure evaluating H there.
    """
    system = scheme.system
    if lplan is None or tguard or scheme.traits.energy_preserving:
        return ()
    return energy_jump_form(system)


def energy_jump_form(system) -> tuple[sp.Expr, sp.Expr]:
    """``(H, S)`` of :func:`energy_jump` for ``system``: ``S = |T| + |U|`` for a separable H
    (the same scale where U's terms share a sign, as gravity's do, and two abs() instead of
    one per term on an N-body H), else ``Σ|terms of H|``."""
    H = system.H
    sep = separable_split(system)
    if sep is not None and sep.T != 0 and sep.U != 0:
        return (H, sp.Abs(sep.T) + sp.Abs(sep.U))
    return (H, sp.Add(*(sp.Abs(t) for t in sp.Add.make_args(H))))


def uses_loops(scheme, loops: bool | None = None) -> bool:
    """Whether the module of ``scheme`` loops over families of like terms.

    ``loops=None`` (default): where the scheme has a :class:`~methodgen.symbolic.schemes.base.LoopPlan`
    with a family of at least :data:`LOOP_MIN_INSTANCES` instances.  ``True`` forces loops
    where there is a plan (a ValueError where there is none), ``False`` unrolls.  Forcing
    is for tests and benchmarks: :func:`methodgen.verify` certifies the loops of the
    default choice (``LoopPlan.looped``), not of a module forced to loop below it.
    """
    plan = getattr(scheme, "loops", None)
    if loops is None:
        return plan is not None and plan.looped
    if loops and plan is None:
        raise ValueError(f"loops=True: {scheme.method} has no sums of like terms to loop over for this "
                         "system (loops are built for energy-momentum, midpoint and AVF, with a separable H and a quadratic "
                         "kinetic energy); use loops=None or False")
    return bool(loops)


def lower(scheme, signature: str, module_name: str, loops: bool | None = None, *,
          expanded: bool = False, backend: str | None = None) -> ModuleIR:
    """Lower ``scheme`` to a :class:`ModuleIR` (deterministic).

    Parameters
    ----------
    scheme : Scheme
    signature : str
        The signature hash to embed (see :func:`methodgen.codegen.emit.signature`).
    module_name : str
        Python module name of the generated file.
    loops : bool or None
        Loop over families of like terms instead of unrolling every term
        (:func:`uses_loops`; default: where a family has ≥ 3 instances).  For Störmer–Verlet
        (first-same-as-last, compensated) the families of U are those of
        :func:`methodgen.codegen.lower_loops.force_plan`: the post kernel's end force and H at y1,
        and H in the initial-state kernels, are loops; Δq stays straight-line code.
    expanded : bool
        Internal (tests and benchmarks): emit the residual and the Newton matrix of an
        s-stage method (``scheme.stage_system``) as the expanded straight-line kernels of
        ``scheme.residual`` and its ``(s·n)²`` symbolic Jacobian, instead of the loops over
        the stages (:mod:`methodgen.symbolic.stages`, the default).
    backend : str or None
        ``"numba"``: leave out the batch (numpy) flavour of the kernels the numba templates
        do not render (guess, residual, Newton matrix, scale, increment, post, hs) -- their
        lowering is a large part of a cold build's time.  None: lower everything (any
        backend can render the IR).
    """
    system = scheme.system
    batch = backend != "numba"
    user = [s.name for s in system.y] + list(system.param_names)
    names = sanitize_names(user)
    rename = {s: sp.Symbol(names[s.name], real=True) for s in list(system.y) + list(system.params)}
    comp = compensation_symbols(system.y)
    rename.update({c: sp.Symbol("_c_" + names[s.name], real=True) for s, c in comp.items()})
    sp_ = ScalarPrinter({"fully_qualified_modules": True})
    vp = VectorPrinter({"fully_qualified_modules": True})

    n = len(scheme.unknowns)
    d2 = len(system.y)
    # The step's equations at the exact numerical state y + c (compensated stage sums:
    # the round-off of long runs then follows Brouwer's law, see methodgen.symbolic.compensate).
    # Only where the unknowns are named increments (``_d_*``).  Gauss collocation (stage
    # increments ``_z*``) is left out: measured on harmonic ensembles (200 phases), its
    # energy drift is the same with and without (h = 0.01, 20000 steps: -8.3e-17 vs
    # -8.7e-17 for s = 2; h = 0.7: -6.6e-14 both) -- it comes from the float64 rounding
    # of A and d, not from the stage sums.
    cmp_ = ((lambda exprs, c: list(exprs)) if any(not u.name.startswith("_d_") for u in scheme.unknowns)
            else compensate)
    # An explicit first-same-as-last Störmer–Verlet step loops over U's families for its end
    # force (and H at both ends) where U has a family of at least LOOP_MIN_INSTANCES terms.
    fsal = n == 0 and cmp_ is compensate and fsal_applies(scheme)
    splan = force_plan(system) if fsal and loops is not False else None
    if splan is not None and (not (splan.looped or loops) or potential_via_sums(system, splan) is None):
        splan = None
    # with the end force in loops only Δq of the plan is used: the unrolled ∇U(q0 + Δq) is not built
    fplan = fsal_plan(scheme, full=splan is None) if fsal else None
    if fplan is None:
        splan = None
    looped = splan is None and uses_loops(scheme, loops) and n > 0
    plan = scheme.loops if looped else splan
    # An s-stage method: f and f' derived once, the stage system assembled by loops in the
    # module (methodgen.symbolic.stages) -- neither the residual's s copies of f per stage nor the
    # (s·n)² Jacobian are lowered.
    stage = getattr(scheme, "stage_system", None) if (n and not looped and not expanded) else None
    if looped:
        # The sums stay sums: the kernels below get loops over the families ahead of their
        # straight-line code (methodgen.codegen.lower_loops), and the Newton matrix comes from the
        # chain rule through the sums, never from the expanded residual.
        res = cmp_(list(plan.residual), comp)
        rows = jacobian_row_scales(plan.residual, scheme.unknowns, plan)
        if rows is None:
            jac_acc, _ = jacobian_via_sums(plan.residual, scheme.unknowns, plan)
        jac = cmp_(rows if rows is not None else jac_acc, comp)
        inc = cmp_(list(plan.increment), comp)
        guess = list(plan.guess)
    elif stage is not None:
        if cmp_ is compensate:   # pragma: no cover - stage increments are never compensated
            raise ValueError("a stage system's unknowns are stage increments (uncompensated)")
        field = list(stage.field)
        dag = stage.derivative
        fjac = list(dag.jacobian)
        res, jac = field, [e for _, e in dag.assignments] + fjac   # (helpers are found in them)
        inc = list(scheme.increment)
        guess = list(scheme.guess)
    else:
        res = cmp_(list(scheme.residual), comp)
        jac = cmp_(list(scheme.jacobian), comp) if n else []
        # (a numba module of a first-same-as-last step needs no increment kernel: its post
        # kernel gives Δy, and the compensated expansion is a large part of the lowering)
        inc = cmp_(list(scheme.increment), comp) if batch or fplan is None else []
        guess = list(scheme.guess)
    invs: tuple[Invariant, ...] = scheme.invariants
    inv_exprs = [inv.expr for inv in invs]
    dim = system.dim if not is_poisson(system) else 0
    compensated = cmp_ is compensate

    def kern(exprs, shape, printer, jac_rows=False):
        k = _kernel(exprs, shape, printer, rename)
        k = _with_loops(k, exprs, plan, printer, dim, compensated, ("_sB",) if jac_rows else ())
        return replace(k, jac_rows=True) if jac_rows else k

    scalar = {}
    vector = {}
    if n:
        scalar["guess"] = kern(guess, (n,), sp_)
        if batch:
            vector["guess"] = kern(guess, (n,), vp)
        # with row scales (looped modules): R then s, and J = I + diag(s) _sB in the module
        scaled = looped and rows is not None
        nj = n if scaled else n * n
        if stage is not None:
            # f at a point (the kernel's state), and f with the nonzeros of f'; the residual
            # and Newton-matrix kernels are the templates' loops over the stages
            m = len(field)
            for flavour, printer in ((scalar, sp_), (vector, vp)):
                flavour["field"] = kern(field, (m,), printer)
                flavour["fieldjac"] = _program_kernel(dag, printer, rename)
                flavour["res"] = Kernel((), (), (n,))
                flavour["resjac"] = Kernel((), (), (n + nj,))
            band = jacobian_band(n, stage.newton_pattern())
        else:
            scalar["resjac"] = kern(res + jac, (n + nj,), sp_, scaled)
            if batch:
                vector["resjac"] = kern(res + jac, (n + nj,), vp, scaled)
            band = _newton_band(n, scalar["resjac"], plan, scaled)
            scalar["res"] = kern(res, (n,), sp_)
            if batch:
                vector["res"] = kern(res, (n,), vp)
        if scheme.unknown_scale is not None:
            scalar["scale"] = _kernel([scheme.unknown_scale], (1,), sp_, rename)
            if batch:
                vector["scale"] = _kernel([scheme.unknown_scale], (1,), vp, rename)
    # (no scalar flavour: every runtime adds the increment through the post kernel)
    if batch:
        vector["increment"] = kern(inc, (d2,), vp)
    # After each solve one kernel gives the increment together with what the checks
    # need at the new state y1 = y0 + Δy, sharing common subexpressions: the error
    # estimate's field values or E itself, and the domain conditions.
    # The checks are written in symbols _dy0, _dy1, ... bound to the increment, so the
    # increment's code is exactly that of the increment kernel (same trajectories).
    links = tuple(sp.Symbol(f"_dy{i}", real=True) for i in range(d2))
    # First-same-as-last Störmer–Verlet: the post kernel takes the start force and returns
    # the end force after Δy (one ∇U per stage); Δy's code then differs from the increment
    # kernel's only in reading the start force (see methodgen.symbolic.fsal).
    first, first_links = inc, links
    if fplan is None and is_splitting(scheme.composition):
        raise InputError(f"the {scheme.composition.family} splitting runs as first-same-as-last "
                         "kick-drift-kick stages, which this module does not have (it needs a "
                         "separable H written without loops, compensated=True); use a composition "
                         "family (triple-jump, suzuki, kahan-li, sofroniou-spaletta)")
    if splan is not None:   # the end force is looped (below): only Δq is straight-line code
        first = cmp_(fplan.increment[:dim], comp)
        first_links = links + tuple(sp.Symbol(f"_gy{i}", real=True) for i in range(len(fplan.symbols)))
    elif fplan is not None:
        first = cmp_(fplan.increment + fplan.end_force, comp)
        first_links = links + tuple(sp.Symbol(f"_gy{i}", real=True) for i in range(len(fplan.symbols)))
    # With loops, the force at the step's end is the sum _sK (Σ ∇U_t(q0 + Δq), Δq = z).
    field1 = None
    if looped:
        sep = separable_split(system)
        field1 = list(sep.Minv * sp.Matrix(system.p)) + [-sp.Symbol(f"_sK{i}", real=True) for i in range(dim)]
    lplan = local_error_plan(scheme, links, field_at_end=field1,
                             fsal=None if fplan is None else
                             (fplan.symbols, first_links[d2:], fplan.steps))
    if lplan is not None and is_splitting(scheme.composition):
        lplan = replace(lplan, partner=_SPLIT_PARTNER)
    conds = domain_conditions(system)
    # A time transformation's guard values (g, the level-set defect and its scale) at y1.
    tguard = time_scale_guard(system) if not is_poisson(system) else ()
    at1 = {s: s + dv for s, dv in zip(system.y, links)}
    # The energy-jump test (methods that do not keep H): H and its size Σ|terms| at y1, carried
    # over as the values at y0 of the next step (a kernel gives them at the initial state).
    ejump = energy_jump(scheme, lplan, tguard) if not conds else ()
    ejump_form = energy_jump_form(system) if ejump and plan is not None else None
    # A composition tests the energy jump once per composed step, with the hs kernel at its
    # end: H at every stage's end was 15 % of a Störmer–Verlet o10 stage (Hénon–Heiles), and a
    # composition's stages are not steps the user chose (their energies are the composed
    # step's intermediate values, the composed step the unit the guard is about).
    composition = getattr(scheme, "composition", None)
    ejump_step = bool(ejump) and composition is not None and composition.stages > 1
    ejump1 = None
    if splan is not None:
        # Δq first (straight-line, ahead of the loops: its values are the loops' slot
        # increments), then the end force Σ_t ∇U_t(q0 + c + Δq) as the sum _sG, and H at
        # y1 through _sV = Σ_t U_t(q0 + Δq).
        pre = first[:dim]
        G1 = [acc_symbol("_sG", i) for i in range(dim)]
        ha, hb = fplan.steps[0], fplan.steps[2]
        first = list(links[:dim]) + [-ha * g0 - hb * g1 for g0, g1 in zip(fplan.symbols, G1)] + G1
        if ejump and tuple(ejump) == ejump_form:
            T, _ = potential_via_sums(system, splan)
            T1 = T.xreplace(at1)
            U1 = sp.Add(*[t for t in sp.Add.make_args(separable_split(system).U)
                          if not t.free_symbols & set(system.q)]) + acc_symbol("_sV", 0)
            ejump1 = [T1 + U1, sp.Abs(T1) + sp.Abs(U1)]
    if ejump1 is None:
        ejump1 = [u.xreplace(at1) for u in ejump]
    if ejump_step:
        ejump1 = []
    later = (list(lplan.extra if lplan else ()) + [u.xreplace(at1) for _, u in conds]
             + [u.xreplace(at1) for u in tguard] + ejump1)
    shared = lplan.shared if lplan else ()
    vsource = "d" if splan is not None else "z"
    merged = _merged_kicks(scheme, fplan, lplan, conds, tguard, ejump, ejump_step)
    if merged and splan is None:
        # a composed step with merged kicks: the stage at y + D (D the step's increment so far)
        # written for a short chain of dependent operations (methodgen.symbolic.fsal.merged_stage)
        first = merged_stage(fplan, system, comp)
    for flavour, printer, lp in ((scalar, sp_, CheckPrinter({"fully_qualified_modules": True})),
                                 (vector, vp, None))[:2 if batch else 1]:
        k = _with_loops(_chained_kernel(first, later, first_links, printer, rename, lp, shared),
                        first + later, plan, printer, dim, compensated, vsource=vsource)
        if splan is not None:
            head = _kernel(pre, (dim,), printer, rename)
            dq = tuple(str(s) for s in links[:dim])
            k = replace(k, pre=head.temps + tuple(zip(dq, head.entries())), pre_out=dq)
        flavour["post"] = k
    if fplan is not None:
        # The start force of a run: ∇U at the exact numerical state y + c, with the stage
        # sums of the step without first-same-as-last.
        force = cmp_(fplan.start_force, comp)
        scalar["force"] = _kernel(force, (len(force),), sp_, rename)
        vector["force"] = _kernel(force, (len(force),), vp, rename)
    # At the initial state: H and the whole vector field (the carried field values
    # of the first step are components of it), then the domain conditions.
    # With loops, H and the field at one state through the sums over the families (the
    # potential _sU, the force _sF): code that grows like the families, not like U.
    pot = potential_via_sums(system, plan) if plan is not None else None
    if pot is not None:
        T, U = pot
        check = [T + U] + [sp.diff(T, s) for s in system.p] + [-acc_symbol("_sF", i) for i in range(dim)]
    else:
        check = [system.H] + list(vector_field(system))
    scalar["check"] = kern(check, (len(check),), sp_)
    vector["check"] = kern(check, (len(check),), vp)
    if conds:
        scalar["domain"] = _kernel([u for _, u in conds], (len(conds),), sp_, rename)
        vector["domain"] = _kernel([u for _, u in conds], (len(conds),), vp, rename)
    if tguard:
        vector["tguard"] = _kernel(list(tguard), (len(tguard),), vp, rename)
    if ejump and pot is not None and tuple(ejump) == ejump_form:
        ejump = (T + U, sp.Abs(T) + sp.Abs(U))
    if ejump:
        scalar["hs"] = kern(list(ejump), (2,), CheckPrinter({"fully_qualified_modules": True}))
        if batch:
            vector["hs"] = kern(list(ejump), (2,), vp)
    vector["hamiltonian"] = kern([T + U] if pot is not None else [system.H], (1,), vp)
    vector["invariants"] = _kernel(inv_exprs, (len(inv_exprs),), vp, rename)
    n_cons = len(system.constraints)
    if n_cons:
        # Constraint machinery only where there are constraints: g, G = ∂g/∂q and M⁻¹
        # for checking and projecting initial values onto T*Q.
        from ..symbolic.derive import constraint_jacobian
        G = constraint_jacobian(system)
        Minv = separable_split(system).Minv
        vector["constraints"] = _kernel(list(system.constraints) + list(G), (n_cons + n_cons * system.dim,),
                                        vp, rename)
        vector["minv"] = _kernel(list(Minv), (system.dim * system.dim,), vp, rename)
    if scheme.projection:
        # Symmetric projection (methodgen.symbolic.projection): the projected invariants g and their
        # gradients G (row by row), at one state.
        from ..symbolic.projection import gradients
        g, G, w = gradients(scheme)
        scalar["proj"] = _kernel(g + G + w, (len(g) + len(G) + len(w),), sp_, rename)
        vector["proj"] = _kernel(g + G + w, (len(g) + len(G) + len(w),), vp, rename)

    return ModuleIR(
        module_name=module_name,
        system_name=system.name or "system",
        method=scheme.method,
        description=scheme.description,
        # a projected method runs its base explicit step (the projection is its own loop)
        kind="explicit" if scheme.projection else scheme.traits.solve,
        order=scheme.traits.order,
        traits=scheme.traits.as_dict(),
        source=system.source,
        constraints=tuple(system.constraint_sources),
        q_names=() if is_poisson(system) else tuple(s.name for s in system.q),
        p_names=() if is_poisson(system) else tuple(s.name for s in system.p),
        state_vars=tuple(names[s.name] for s in system.y),
        comp_vars=tuple(str(rename[comp[s]]) for s in system.y),
        param_names=tuple(system.param_names),
        param_vars=tuple(names[k] for k in system.param_names),
        param_defaults=tuple(repr(system.param_values[k]) for k in system.param_names),
        unknown_names=tuple(s.name for s in scheme.unknowns),
        invariant_names=tuple(inv.name for inv in invs),
        invariant_exprs=tuple(str(inv.expr) for inv in invs),
        scalar=scalar,
        vector=vector,
        helpers=_helpers_called(scalar, vector),
        signature=signature,
        resolution=scheme.resolution,
        fixed_point=scheme.fixed_point,
        local_error=lplan.kind if lplan else None,
        lerr_index=lplan.index if lplan else (),
        lerr_norm=lplan.norm if lplan else (),
        lerr_scale=repr(float(lplan.scale)) if lplan else "1.0",
        lerr_partner=lplan.partner if lplan else "",
        domain=tuple((kind, str(u)) for kind, u in conds),
        energy_jump=bool(ejump),
        energy_jump_step=ejump_step,
        **_composition_fields(scheme),
        time_transform=_time_transform_fields(system, invs),
        poisson=_poisson_fields(system),
        loop_tables=_loop_tables(plan),
        band=band if n else (0, 0),
        fsal_vars=tuple(str(g) for g in fplan.symbols) if fplan is not None else (),
        merged_kicks=merged,
        **(_stage_fields(scheme) if fplan is not None else {}),
        stage=stage_tables(stage) if stage is not None else None,
        projection=tuple(scheme.projection),
        projection_symmetric=bool(getattr(scheme, "projection_symmetric", True)),
    )


def _merged_kicks(scheme, fplan, lplan, conds, tguard, ejump, ejump_step) -> bool:
    """:attr:`ModuleIR.merged_kicks` for a lowered scheme."""
    comp = getattr(scheme, "composition", None)
    system = scheme.system
    if fplan is None or comp is None or comp.stages < 2 or is_splitting(comp) or is_poisson(system):
        return False
    sep = separable_split(system)
    return (getattr(comp, "role", "method") in ("method", "kernel") and not conds and not tguard
            and (ejump_step or not ejump) and not system.constraints and not scheme.projection
            and (lplan is None or lplan.kind == "direct") and sep is not None and sep.Minv is not None
            and len(system.y) == 2 * len(fplan.symbols))


def stage_tables(stage) -> dict:
    """The constants of a stage system's loops (:class:`methodgen.symbolic.stages.StageSystem`),
    floats as their reprs: ``s``, ``m``, ``nnz``; ``Q`` (s × m), ``P`` (m × s, None for
    ``u_k = y + Z_k``), ``sigma`` (s); ``rows``, ``cols``: f''s nonzeros in the order the
    ``fieldjac`` kernel returns them.  (The Newton matrix's weights ``Q_jk P_ki`` are
    multiplied in the loops, not tabled: a table of them would grow like s²m.)"""
    s, m = stage.stages, stage.m
    return {"s": s, "m": m, "nnz": len(stage.pattern), **_stage_sums(s, m),
            "Q": tuple(tuple(repr(float(x)) for x in row) for row in stage.weights),
            "P": None if stage.points is None else tuple(tuple(repr(float(x)) for x in row)
                                                           for row in stage.points),
            "sigma": tuple(repr(float(x)) for x in stage.scale),
            "rows": tuple(a for a, _ in stage.pattern), "cols": tuple(b for _, b in stage.pattern)}


def _stage_sums(s: int, m: int) -> dict:
    """The sums the numpy scalar kernels spell out (Python source, added left to right, as
    the loops of the other flavours add them): ``qsum`` Σ_k Q_jk f_k over mirror pairs of
    points ``(k, m−1−k)`` from the outside in, then the middle point; ``psum`` Σ_i P_ki Z_i;
    ``gsum`` Σ_k c_k f'_k; with the comprehension targets ``fvars``, ``xvars``, ``gvars``."""
    def chain(terms):
        return " + ".join(terms)

    pairs = [f"(_q[{k}] * _f{k} + _q[{m - 1 - k}] * _f{m - 1 - k})" for k in range(m // 2)]
    mid = [f"_q[{m // 2}] * _f{m // 2}"] if m % 2 else []

    def targets(prefix, count):
        names = ", ".join(f"{prefix}{k}" for k in range(count))
        return names + ("," if count == 1 else "")

    return {"qsum": chain(pairs + mid), "fvars": targets("_f", m),
            "psum": chain([f"_w[{i}] * _x{i}" for i in range(s)]), "xvars": targets("_x", s),
            "gsum": chain([f"_c[{k}] * _g{k}" for k in range(m)]), "gvars": targets("_g", m)}


def jacobian_band(n: int, entries) -> tuple[int, int]:
    """``(kl, ku)``: the largest distance below and above the diagonal of the structurally
    nonzero entries ``(i, j)`` of an ``n × n`` Newton matrix (the diagonal counts; ``(0, 0)``
    for ``n = 0``).  Entries outside are zero for every input (exact zeros of the
    derivation), so for a finite matrix elimination restricted to the band is Gaussian
    elimination itself: every pivot it chooses and every value it computes is the dense
    routine's (a non-finite entry spreads NaN further in the dense routine; both fail)."""
    kl = ku = 0
    for i, j in entries:
        kl, ku = max(kl, i - j), max(ku, j - i)
    return (min(kl, max(n - 1, 0)), min(ku, max(n - 1, 0)))


def _newton_band(n: int, resjac: Kernel, plan, scaled: bool) -> tuple[int, int]:
    if scaled:   # J = I + diag(s) _sB: the pattern of the accumulated _sB
        return jacobian_band(n, sum_pattern(plan))
    entries = [divmod(idx[0] - n, n) for idx, code in resjac.outputs if idx[0] >= n]
    return jacobian_band(n, entries)


def _with_loops(k: Kernel, exprs, plan, printer, dim: int, compensated: bool, whole=(), vsource="z") -> Kernel:
    if plan is None:
        return k
    loops, accs = loop_prefix(exprs, plan, printer, dim, compensated, whole, vsource)
    return Kernel(k.temps, k.outputs, k.shape, loops, accs)


def _loop_tables(plan) -> tuple:
    if plan is None:
        return ()
    out = []
    for f, lf in enumerate(plan.families):
        table, ptable = table_names(f)
        out.append((table, lf.family.index))
        if lf.family.pslots:
            out.append((ptable, lf.family.pindex))
    return tuple(out)


def _poisson_fields(system) -> dict | None:
    if not is_poisson(system):
        return None
    rows = tuple(tuple(" ".join(e.split()) for e in row) for row in system.S_sources)
    casimirs = tuple(inv.name for inv in casimir_invariants(system))
    return {"state": system.state_names, "matrix": rows,
            "matrix_text": "[" + ", ".join("[" + ", ".join(r) + "]" for r in rows) + "]",
            "casimirs": casimirs, "jacobi": system.jacobi().status}


def _time_transform_fields(system, invs) -> dict | None:
    tt = system.time_transform
    if tt is None:
        return None
    from ..symbolic.derive import PHYSICAL_ENERGY

    return {"g": " ".join(tt.g_source.split()), "time": tt.time.name, "energy": tt.energy.name,
            "hamiltonian": " ".join(tt.original.source.split()),
            # per-step guard of g > 0 and of the level set (timetransform.time_scale_guard)
            "guard": bool(time_scale_guard(system)),
            "h_index": [inv.name for inv in invs].index(PHYSICAL_ENERGY),
            # the log form: Λ = log(T + e) − log(−U) on the exchanged state (p…, e, q…, t)
            "form": tt.form, "exchanged": tt.exchanged}


def _stage_fields(scheme) -> dict:
    """KICK_A, DRIFT, KICK_B of a first-same-as-last module's stages (reprs)."""
    comp = getattr(scheme, "composition", None)
    if comp is None:
        return {}
    if is_splitting(comp):
        ka, dr, kb = comp.stage_fractions()
    else:
        ka, dr, kb = composition_stages(comp.floats())
    return {"stage_kick_a": tuple(map(repr, ka)), "stage_drift": tuple(map(repr, dr)),
            "stage_kick_b": tuple(map(repr, kb)), "splitting": is_splitting(comp)}


def _composition_fields(scheme) -> dict:
    comp = getattr(scheme, "composition", None)
    if comp is None:
        return {}
    return {"composition": {"family": comp.family, "order": comp.order, "stages": comp.stages,
                            "source": comp.source, "role": getattr(comp, "role", "method")},
            "gammas": tuple(repr(g) for g in comp.floats())}
