"""Lowering's half of the kernel IR: a SymPy expression -> the tree of its printed code.

:func:`from_sympy` builds, for one of the code printers of :mod:`methodgen.codegen.lower`, exactly
the tree Python makes of that printer's text for the expression -- the same decisions (SymPy's
order of terms and factors, its rational constants, its square roots, the check printer's
products for small powers), nodes instead of strings -- so the rounding of every generated
kernel is the one it always had.  :func:`code` gives the lowering its :class:`~methodgen.codegen.kir.Code`.
Kept apart from :mod:`methodgen.codegen.kir` so that the runtime, which reads trees, never
imports SymPy.

References
----------
SymPy's ``CodePrinter._print_Mul``, ``StrPrinter._print_Add``,
``AbstractPythonCodePrinter._hprint_Pow`` (``sympy.printing``), whose trees this reproduces.
"""

from __future__ import annotations

import sympy as sp
from sympy.core.mul import _keep_coeff
from sympy.printing.precedence import PRECEDENCE, precedence

from .kir import FUNCTIONS, Code, Unsupported, python

__all__ = ["from_sympy", "code"]

#: a transient marker of the builder: the subtree SymPy's printer wrapped in parentheses
_PAREN = "()"


def from_sympy(expr: sp.Expr, printer) -> tuple:
    """The tree of ``expr`` as ``printer`` writes it (one of the code printers of
    :mod:`methodgen.codegen.lower`: its order of terms and factors, its rational constants, its
    powers; the ``check`` printer's products for small powers).

    Parameters
    ----------
    expr : sympy.Expr
        A CSE'd expression in (sanitised) symbols.
    printer : sympy.printing.pycode.PythonCodePrinter
        Decides the order of terms and factors and the digits of floats, as it would when
        printing; its text is never produced.

    Returns
    -------
    tuple
        The tree (see the module docstring).

    Raises
    ------
    Unsupported
        For a node the IR does not have.
    """
    # one builder per printer (a lowering's printer lives for that lowering): its memo builds
    # each distinct subexpression's tree once across the lowering's expressions
    builder = getattr(printer, "_kir_builder", None)
    if builder is None or builder.p is not printer:
        builder = _Builder(printer)
        try:
            printer._kir_builder = builder
        except AttributeError:     # (a printer that takes no attributes: a builder per call)
            pass
    return _strip(builder.build(expr))


def _strip(node):
    if node[0] == _PAREN:
        return _strip(node[1])
    if node[0] in ("n", "v"):
        return node
    if node[0] == "call":
        return ("call", node[1], tuple(_strip(a) for a in node[2]))
    return (node[0],) + tuple(_strip(a) for a in node[1:])


def _fold(op: str, items: list) -> tuple:
    out = items[0]
    for x in items[1:]:
        out = (op, out, x)
    return out


def _neg_leftmost(node):
    """The tree of ``"-" + text``: Python's unary minus takes the leftmost operand of a
    product or quotient (``-a*b/c`` is ``((-a)*b)/c``), a power or call whole, and a
    parenthesised group whole."""
    if node[0] in ("*", "/"):
        return (node[0], _neg_leftmost(node[1]), node[2])
    return ("neg", node)


def _number(value) -> tuple:
    return ("neg", ("n", -value)) if value < 0 else ("n", value)


class _Builder:
    """The trees of SymPy's ``CodePrinter`` / ``PythonCodePrinter`` / the lowering's subclasses,
    method for method (the same decisions, nodes instead of strings)."""

    def __init__(self, printer):
        from ..problem.special import SPECIAL_FUNCTIONS
        from ..symbolic.compensate import grouped

        self.p = printer
        # the check printer writes small powers as products (lower.CheckPrinter: kir_flavour "check");
        # the vector printer (numpy arrays) has numpy's functions and its own powers
        flavour = getattr(printer, "kir_flavour", None)
        self.check = flavour == "check"
        self.vector = flavour == "vector"
        self.sqrt = "numpy.sqrt" if self.vector else "math.sqrt"
        self.prefix = "_v_" if self.vector else "_f_"
        self.special = SPECIAL_FUNCTIONS
        self.grouped = grouped
        self.memo: dict = {}

    def paren(self, item, level) -> tuple:
        # CodePrinter.parenthesize(item, level, strict=False)
        node = self.build(item)
        return (_PAREN, node) if precedence(item) <= level else node

    def build(self, e) -> tuple:
        # a subexpression's tree does not depend on where it stands (its parent decides the
        # parentheses): built once (trees are tuples, shared safely)
        got = self.memo.get(e)
        if got is None:
            got = self.memo[e] = self._build(e)
        return got

    def _build(self, e) -> tuple:
        if isinstance(e, self.grouped):
            return (_PAREN, self.build(e.args[0]))
        if e.is_Symbol:
            return ("v", self.p._print(e))
        if e.is_Integer:
            return _number(int(e.p))
        if e.is_Rational:
            return ("/", _number(int(e.p)), ("n", int(e.q)))
        if e.is_Float:
            text = self.p._print(e)
            neg = text.startswith("-")
            try:
                v = float(text[1:] if neg else text)
            except ValueError:
                raise Unsupported(f"the float {text}") from None
            return ("neg", ("n", v)) if neg else ("n", v)
        if e.is_NumberSymbol:
            # pi, E: the printer's module constants (math.pi, math.e)
            name = self.p._print(e)
            if name not in ("math.pi", "math.e", "numpy.pi", "numpy.e"):
                raise Unsupported(f"the constant {name}")
            return ("v", name)
        if e.is_Add:
            return self.add(e)
        if e.is_Mul:
            return self.mul(e)
        if e.is_Pow:
            return self.pow(e)
        if type(e) in self.special:
            name = self.prefix + self.special[type(e)][1:]
            return ("call", name, tuple(self.build(a) for a in e.args))
        if self.vector and isinstance(e, sp.Max):
            # VectorPrinter._print_Max: numpy.maximum(a, numpy.maximum(b, …))
            args = [self.build(a) for a in e.args]
            out = args[-1]
            for a in reversed(args[:-1]):
                out = ("call", "numpy.maximum", (a, out))
            return out
        known = self.p.known_functions.get(type(e).__name__)
        if known is not None and e.args:
            name = self.p._module_format(known)
            if name not in FUNCTIONS:
                raise Unsupported(f"the function {name}")
            return ("call", name, tuple(self.build(a) for a in e.args))
        raise Unsupported(f"{type(e).__name__} ({e})")

    @staticmethod
    def _starts_minus(term) -> bool:
        # whether the printer's text of an Add's term starts with "-" (StrPrinter._print_Add
        # then writes it as a subtraction)
        if term.is_Number:
            return bool(term < 0)
        if term.is_Mul:
            return bool(term.as_coeff_Mul()[0] < 0)
        return False

    def add(self, e) -> tuple:
        # StrPrinter._print_Add
        terms = self.p._as_ordered_terms(e, order=None)
        prec = precedence(e)
        out = None
        for term in terms:
            minus = self._starts_minus(term) and not term.is_Add
            node = self.positive(term) if minus else self.build(term)
            if precedence(term) < prec or term.is_Add:
                node = (_PAREN, node)
            if out is None:
                out = _neg_leftmost(node) if minus else node
            else:
                out = ("-" if minus else "+", out, node)
        return out

    def positive(self, term) -> tuple:
        """The tree of a negative term's text without its leading ``-``."""
        if term.is_Number:
            return self.build(-term)
        return self.mul(term, signed=False)

    def mul(self, e, signed=True) -> tuple:
        # CodePrinter._print_Mul
        prec = precedence(e)
        c, rest = e.as_coeff_Mul()
        sign = False
        if c < 0:
            e = _keep_coeff(-c, rest)
            sign = True
        args = e.as_ordered_factors() if self.p.order not in ("old", "none") else sp.Mul.make_args(e)
        a, b = [], []
        for item in args:
            if item.is_commutative and item.is_Pow and item.exp.is_Rational and item.exp.is_negative:
                b.append(sp.Pow(item.base, -item.exp, evaluate=False) if item.exp != -1
                         else sp.Pow(item.base, -item.exp))
            else:
                a.append(item)
        a = a or [sp.S.One]
        if len(a) == 1 and sign:
            anodes = [self.paren(a[0], 0.5 * (PRECEDENCE["Pow"] + PRECEDENCE["Mul"]))]
        else:
            anodes = [self.paren(x, prec) for x in a]
        node = _fold("*", anodes)
        if b:
            bnodes = [self.paren(x, prec) for x in b]
            node = ("/", node, bnodes[0] if len(bnodes) == 1 else (_PAREN, _fold("*", bnodes)))
        if sign and signed:
            node = _neg_leftmost(node)
        return node

    def pow(self, e) -> tuple:
        b, x = e.args
        if self.check:
            # CheckPrinter._print_Pow
            if b.is_Symbol and x.is_Integer and 2 <= x <= 3:
                return (_PAREN, _fold("*", [self.build(b)] * int(x)))
            if x.is_Integer and 2 <= x <= 4:
                return (_PAREN, _fold("*", [self.paren(b, PRECEDENCE["Mul"])] * int(x)))
            if b.is_Symbol and x.is_Rational and x.q == 2 and abs(x.p) == 3:
                u = self.build(b)
                power = (_PAREN, ("*", u, ("call", "math.sqrt", (u,))))
                return power if x.p > 0 else (_PAREN, ("/", ("n", 1), power))
        if x.is_Integer and 2 <= abs(x) <= MAX_PRODUCT_POWER:
            # ScalarPrinter._print_Pow, VectorPrinter._print_Pow: an integer power as the
            # compiled kernels compute it (exponentiation by squaring), so every flavour
            # rounds alike; libm's pow (CPython's float **, numpy's power) rounds otherwise
            node = _power_by_squaring(self.paren(b, PRECEDENCE["Mul"]), abs(int(x)))
            return node if x > 0 else ("/", ("n", 1), node)
        if self.vector and x == -1:
            # VectorPrinter._print_Pow
            return ("/", ("n", 1), self.paren(b, PRECEDENCE["Pow"]))
        # ScalarPrinter._print_Pow, VectorPrinter._print_Pow
        if x.is_Rational and x.q == 2 and abs(x.p) != 1:
            root = ("call", self.sqrt, (self.build(b),))
            k = abs(int(x.p))
            power = _power_by_squaring(root, k) if k <= MAX_PRODUCT_POWER else ("**", root, ("n", k))
            return power if x.p > 0 else ("/", ("n", 1), power)
        if self.vector and x.is_integer and x.is_negative:
            # NumPyPrinter._print_Pow: a negative integer power with a float exponent
            e = sp.Pow(b, x.evalf(), evaluate=False)
            x = e.exp
        # AbstractPythonCodePrinter._hprint_Pow (rational=False)
        prec = precedence(e)
        if x == sp.S.Half:
            return ("call", self.sqrt, (self.build(b),))
        if e.is_commutative:
            if -x is sp.S.Half:
                return ("/", ("n", 1), ("call", self.sqrt, (self.build(b),)))
            if x is sp.S.NegativeOne:
                return ("/", ("n", 1), self.paren(b, prec))
        return ("**", self.paren(b, prec), self.paren(x, prec))


#: The largest |n| of an integer power printed as products (``x**n`` beyond it: libm's pow
#: in Python, exponentiation by squaring in the compiled kernels).
MAX_PRODUCT_POWER = 16


def _power_by_squaring(base: tuple, n: int) -> tuple:
    """``base**n`` (n ≥ 2) as the products of exponentiation by squaring, in the order of
    :meth:`methodgen.codegen.llvmkernels` ``power`` (numba's ``static_power_impl``): the
    same rounding as the compiled kernels' ``**``."""
    res, val = None, base
    while n:
        if n & 1:
            res = val if res is None else (_PAREN, ("*", res, val))
        n >>= 1
        if n:
            val = (_PAREN, ("*", val, val))
    return res


def code(printer, expr: sp.Expr):
    """The printed code of ``expr``: a :class:`Code` (its tree's Python) for the scalar, check and
    vector printers of :mod:`methodgen.codegen.lower`, whose trees :func:`from_sympy` builds;
    SymPy's text for any other printer or an expression the IR has no node for."""
    if getattr(printer, "kir_flavour", None) in ("scalar", "check", "vector"):
        try:
            return Code(from_sympy(expr, printer))
        except Unsupported:
            pass
    return printer.doprint(expr)
