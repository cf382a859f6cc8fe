"""Safe parsing of expression text into SymPy.

Hamiltonians and constraints arrive as text (from Python calls or scene files).
Text is *data*: it is parsed with :func:`ast.parse` (which never executes
anything) and the resulting tree is walked with a whitelist.  Only numbers,
declared names, the arithmetic operators ``+ - * / **`` and calls of the
functions in :data:`FUNCTIONS` are accepted; everything else — attribute access,
subscripts, lambdas, comprehensions, keyword arguments, strings, dunder names —
is refused *before* any SymPy object is built.  ``sympify`` is never called on
user text.

Float literals are converted to exact rationals (``0.1`` becomes ``1/10``) so
that the symbolic proofs of :mod:`methodgen.symbolic.verify` stay exact.

Indexed sums.  ``Sum(body, i, lo, hi)`` is ``body`` summed over the integers
``lo ≤ i ≤ hi``, and ``q[e]`` inside it names the declared symbol ``q<e>`` (``q[i+1]``
with ``i = 3`` is ``q4``): a chain is one line, ``Sum(exp(q[i] - q[i+1]), i, 1, N-1)``
written with the number, and a periodic wrap is index arithmetic, ``q[i % 200 + 1]``.
Sums nest (``Sum(Sum(..., j, i + 1, 8), i, 1, 7)`` over pairs).  Index expressions are
integers, the bound indices and ``+ - * // %`` on them, evaluated here as Python
integers; anything else, an unbound index, or a subscript that names no declared
symbol is refused with one line.  The sum is expanded into its terms at parsing (at most
:data:`MAX_SUM_TERMS`); the derivations group the terms back into families of like
terms (:mod:`methodgen.problem.families`) and derive each family once.
"""

from __future__ import annotations

import ast
import keyword
import math
import re
from typing import Mapping

import sympy as sp

from ..errors import ParseError

#: Functions allowed in expression text, mapped to their SymPy constructors.
FUNCTIONS: dict[str, object] = {
    "sqrt": sp.sqrt,
    "exp": sp.exp,
    "log": sp.log,
    "sin": sp.sin,
    "cos": sp.cos,
    "tan": sp.tan,
    "sinh": sp.sinh,
    "cosh": sp.cosh,
    "tanh": sp.tanh,
    "atan": sp.atan,
}

#: Named constants of the grammar.
CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi}

#: SymPy function classes allowed in an expression (``sqrt`` and powers are ``Pow``).
SMOOTH_FUNCTIONS: tuple[type, ...] = (sp.exp, sp.log, sp.sin, sp.cos, sp.tan, sp.sinh, sp.cosh,
                                      sp.tanh, sp.atan)

#: Why a non-smooth SymPy function is refused, and what to write instead.
#: ``{a}`` is the (first) argument, ``{u}`` the same parenthesised if needed, ``{u2}`` its square.
_NONSMOOTH: dict[str, tuple[str, str]] = {
    "Abs": ("|x| has a kink at 0; for real symbols sqrt({u2}) is Abs({a}) and ({u2})**(3/2) "
            "is {u2}*Abs({a})",
            "write {u2} or sqrt({u2} + eps**2)"),
    "Max": ("max(a, b) has a kink where a = b",
            "use a smooth blend such as (a + b + sqrt((a - b)**2 + eps**2))/2"),
    "Min": ("min(a, b) has a kink where a = b",
            "use a smooth blend such as (a + b - sqrt((a - b)**2 + eps**2))/2"),
    "sign": ("sign(x) jumps at 0",
             "use tanh({u}/eps) or {u}/sqrt({u2} + eps**2)"),
    "Heaviside": ("the step function jumps at 0",
                  "use (1 + tanh({u}/eps))/2"),
    "Piecewise": ("the branches of a piecewise expression meet with a jump or a kink",
                  "write one smooth formula valid on the whole domain"),
    "floor": ("floor(x) jumps at every integer", "write a smooth formula"),
    "ceiling": ("ceiling(x) jumps at every integer", "write a smooth formula"),
    "frac": ("the fractional part jumps at every integer",
             "for a periodic potential use sin and cos"),
    "DiracDelta": ("the Dirac delta is a distribution, not a function",
                   "use a smooth bump such as exp(-{u2}/eps**2)"),
    "re": ("re(z) is not a smooth real function of real symbols (z is taken as complex)",
           "write H as a real expression of the real symbols"),
    "im": ("im(z) is not a smooth real function of real symbols (z is taken as complex)",
           "write H as a real expression of the real symbols"),
    "arg": ("arg(x) jumps from 0 to pi at x = 0 for real x",
            "write H as a real expression of the real symbols"),
    "conjugate": ("conjugate(z) is not a smooth real function of real symbols",
                  "write H as a real expression of the real symbols"),
}

#: Names a user may type for a refused SymPy function (text input).
_NONSMOOTH_TEXT: dict[str, str] = {
    **{k: k for k in _NONSMOOTH},
    "abs": "Abs", "fabs": "Abs", "max": "Max", "min": "Min", "sgn": "sign", "heaviside": "Heaviside",
    "step": "Heaviside", "piecewise": "Piecewise", "where": "Piecewise", "ceil": "ceiling",
    "delta": "DiracDelta", "real": "re", "imag": "im", "angle": "arg", "conj": "conjugate",
}

_GRAMMAR = ("numbers, symbols, pi, E, + - * / **, sqrt and the functions "
            "exp, log, sin, cos, tan, sinh, cosh, tanh, atan")

#: Names a user symbol may not take (the grammar's own words).
RESERVED = frozenset(FUNCTIONS) | frozenset(CONSTANTS) | {"Sum"}

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

MAX_TEXT = 20_000
#: Largest number of terms the indexed sums of one expression may expand to.
MAX_SUM_TERMS = 100_000
#: Largest number of expression nodes the expansion of the indexed sums may build (the
#: summand's nodes once per term).  The term bound alone let a 20 kB text with a long summand
#: build ~10⁸ nodes (a parse of half an hour).  5·10⁶ lets the largest sums the term bound
#: admits through with their usual summands (99 235 pairs of a 3-D gravity summand, ~25
#: nodes a term: about a minute, SymPy's constructors dominating).
MAX_SUM_NODES = 5_000_000
#: The indexed-sum construct (a word of the grammar, not a user symbol).
SUM = "Sum"
MAX_DEPTH = 60
MAX_INT_EXPONENT = 64


def check_name(name: object, what: str = "symbol") -> str:
    """Validate a user symbol name and return it.

    A valid name starts with a letter, continues with letters, digits or
    underscores, is not a Python keyword and is not a word of the grammar
    (:data:`RESERVED`).  Leading underscores (and so dunder names) are refused.
    """
    if not isinstance(name, str):
        raise ParseError(f"{what} name must be a string, got {type(name).__name__} {name!r}")
    if not _NAME_RE.fullmatch(name):
        raise ParseError(
            f"invalid {what} name {name!r}: a name starts with a letter and contains only "
            "letters, digits and underscores (no leading underscore)"
        )
    if keyword.iskeyword(name) or keyword.issoftkeyword(name):
        raise ParseError(f"invalid {what} name {name!r}: it is a Python keyword; choose another name")
    if name in RESERVED:
        raise ParseError(
            f"invalid {what} name {name!r}: it is a function or constant of the expression "
            f"grammar ({', '.join(sorted(RESERVED))})"
        )
    return name


def parse_expr(text: str, symbols: Mapping[str, sp.Symbol], *, what: str = "expression") -> sp.Expr:
    """Parse ``text`` into a real scalar SymPy expression over ``symbols``.

    Parameters
    ----------
    text : str
        Expression in Python syntax restricted to the whitelist described in the
        module docstring, e.g. ``"(px**2 + py**2)/(2*m) - k/sqrt(x**2 + y**2)"``.
    symbols : mapping of str to sympy.Symbol
        The declared names (coordinates, momenta, parameters).
    what : str
        How to call the expression in error messages ("Hamiltonian", "constraint 1").

    Returns
    -------
    sympy.Expr

    Raises
    ------
    ParseError
        On syntax errors, undeclared names, disallowed constructs, or
        expressions that are not real scalars.
    """
    if not isinstance(text, str):
        raise ParseError(f"{what} must be a string, got {type(text).__name__}")
    if len(text) > MAX_TEXT:
        raise ParseError(f"{what} is longer than {MAX_TEXT} characters")
    if not text.strip():
        raise ParseError(f"{what} is empty")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        col = f" at column {exc.offset}" if exc.offset else ""
        raise ParseError(f"syntax error in {what}{col}: {exc.msg}: {text!r}") from None
    expr = _Builder(symbols, what).build(tree.body, 0)
    if not isinstance(expr, sp.Expr) or isinstance(expr, (sp.MatrixBase,)):
        raise ParseError(f"{what} must be a scalar expression")
    if expr.has(sp.I) or expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ParseError(f"{what} is not a finite real expression: {expr}")
    check_smooth(expr, what)
    _check_double_range(expr, what)
    return expr


def _check_double_range(expr: sp.Expr, what: str) -> None:
    """Every number of ``expr`` (and its numerator and denominator, printed apart in the generated
    code) must be a double: ``1e200*1e200`` folds to an exact integer no float can hold, which the
    generated module would meet only at run time as an ``OverflowError``."""
    for n in expr.atoms(sp.Rational):
        parts = [(n, "")] if n.q == 1 else [(n, ""), (sp.Integer(n.p), "the numerator of "),
                                            (sp.Integer(n.q), "the denominator of ")]
        for part, role in parts:
            try:
                ok = math.isfinite(float(part))
            except OverflowError:
                ok = False
            if not ok:
                of = f" ({role}{sp.Float(n, 4)})" if role else ""
                raise ParseError(f"{what}: the number {sp.Float(part, 4)}{of} is beyond the range of a double "
                                 "(about ±1.8e308)")
    # Every other number-valued subexpression (exp(1000), cosh(800), pi**700) is evaluated by
    # SymPy's evalf (mpmath, arbitrary precision; the user's text is never evaluated): the
    # generated code computes it in doubles, where it would overflow to inf (or, for a nonzero
    # value, underflow to 0) at run time and be blamed on the initial state.
    for node in sp.preorder_traversal(expr):
        if not isinstance(node, sp.Expr) or node.is_Rational or node.is_Float or node.free_symbols \
                or isinstance(node, sp.NumberSymbol) or node is sp.E:
            continue
        try:
            value = node.evalf(30)
            re_, im_ = value.as_real_imag()
            parts = [float(abs(re_)), float(abs(im_))]
            exact_zero = [re_ == 0, im_ == 0]
        except (TypeError, ValueError, OverflowError, AttributeError):
            continue   # not a number (e.g. unevaluated): the other checks of the expression decide
        for v, zero in zip(parts, exact_zero):
            if not math.isfinite(v) or (v == 0 and not zero):
                raise ParseError(f"{what}: {node} = {sp.Float(value, 4) if value.is_real else value} is beyond "
                                 "the range of a double (magnitudes up to about 1.8e308, nonzero ones above about 5e-324): "
                                 "the generated code would compute it in doubles; rescale the problem")


def _needs(what: str) -> str:
    if what.startswith("constraint"):
        return "RATTLE/SHAKE need smooth constraints g(q) (their Jacobian G(q))"
    return "a discrete gradient needs a smooth H"


def _refusal(what: str, shown: str, cls_name: str, arg: str | None) -> str:
    """One line: what is refused, why, and what to write instead."""
    reason, remedy = _NONSMOOTH[cls_name]
    if arg is None:
        arg = "x"
    u = arg if _NAME_RE.fullmatch(arg) else f"({arg})"
    fmt = {"a": arg, "u": u, "u2": f"{u}**2"}
    return f"{what}: {shown} is not smooth ({reason.format(**fmt)}); {_needs(what)} — {remedy.format(**fmt)}"


def check_smooth(expr: sp.Expr, what: str = "expression") -> sp.Expr:
    """Refuse every node of ``expr`` that is not in the smooth grammar; return ``expr``.

    Allowed node classes: symbols, rational numbers, floats, the constants ``pi``
    and ``E``, ``Add``, ``Mul``, ``Pow`` (which includes ``sqrt`` and rational
    powers, smooth on their real domain) and the functions of
    :data:`SMOOTH_FUNCTIONS`.  Everything else — ``Abs`` (SymPy's form of
    ``sqrt(q**2)`` for real ``q``), ``Max``/``Min``, ``sign``, ``Heaviside``,
    ``Piecewise``, ``floor`` …, and any other function — raises a one-line
    :class:`ParseError` naming the node and why it is refused: a discrete
    gradient (and the exact proofs of :mod:`methodgen.symbolic.verify`) need a smooth H.

    The same check is applied to parsed text and to SymPy input
    (:class:`methodgen.Hamiltonian`), to the Hamiltonian and to constraints.
    """
    from .special import sinc_u   # sin(u)/u as folded by the Hamiltonian (smooth)

    for node in sp.preorder_traversal(expr):
        if isinstance(node, (sp.Symbol, sp.Rational, sp.Add, sp.Mul, sp.Pow, sinc_u) + SMOOTH_FUNCTIONS):
            continue
        if isinstance(node, sp.Float) and node.is_finite:
            continue
        if node is sp.pi or node is sp.E:
            continue
        name = type(node).__name__
        if name in _NONSMOOTH:
            arg = str(node.args[0]) if node.args and not isinstance(node, sp.Piecewise) else None
            raise ParseError(_refusal(what, str(node), name, arg))
        if isinstance(node, sp.Function) or isinstance(getattr(node, "func", None), sp.FunctionClass):
            fname = getattr(node.func, "__name__", name)
            raise ParseError(f"{what}: function {fname} (in {node}) is not in the grammar: allowed are "
                             f"{_GRAMMAR}; {_needs(what)}")
        shown = str(node) if str(node) == name else f"{node} ({name})"
        raise ParseError(f"{what}: {shown} is not in the grammar: allowed are {_GRAMMAR}")
    return expr


def _expr_nodes(node: ast.AST) -> int:
    """Number of expression nodes under ``node`` (operators and load contexts not counted)."""
    return sum(1 for n in ast.walk(node) if isinstance(n, ast.expr))


class _Builder:
    """Walk an :mod:`ast` tree with a whitelist and build SymPy objects."""

    _BINOPS = {
        ast.Add: lambda a, b: a + b,
        ast.Sub: lambda a, b: a - b,
        ast.Mult: lambda a, b: a * b,
        ast.Div: lambda a, b: a / b,
    }

    def __init__(self, symbols: Mapping[str, sp.Symbol], what: str):
        self.symbols = symbols
        self.what = what
        self.bound: dict[str, int] = {}     # the indices of the enclosing Sums, and their values
        self.sum_terms = 0
        self.sum_nodes = 0                  # nodes built inside Sums (bounded by MAX_SUM_NODES)

    def fail(self, node: ast.AST, msg: str) -> ParseError:
        col = getattr(node, "col_offset", None)
        where = f" (column {col + 1})" if col is not None else ""
        return ParseError(f"{self.what}{where}: {msg}")

    def build(self, node: ast.AST, depth: int) -> sp.Expr:
        if depth > MAX_DEPTH:
            raise self.fail(node, f"expression nested deeper than {MAX_DEPTH} levels")
        if self.bound:
            # the running count: nested sums whose ranges depend on an outer index are
            # bounded here (a flat sum is refused before expanding, in indexed_sum)
            self.sum_nodes += 1
            if self.sum_nodes > MAX_SUM_NODES:
                raise self.fail(node, self._too_large())
        if isinstance(node, ast.Constant):
            return self.constant(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            arg = self.build(node.operand, depth + 1)
            return -arg if isinstance(node.op, ast.USub) else arg
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult)):
            # A sum a + b - c + ... (or a product) is one level, not one per term: Python
            # parses it as a left-leaning chain, which would make a chain of 64 particles
            # (130 terms) "deeper than MAX_DEPTH".  Walk the chain iteratively.
            product = isinstance(node.op, ast.Mult)
            ops = (ast.Mult,) if product else (ast.Add, ast.Sub)
            links = []
            cur = node
            while isinstance(cur, ast.BinOp) and isinstance(cur.op, ops):
                links.append((cur.op, cur.right))
                cur = cur.left
            parts = [self.build(cur, depth + 1)]
            for op, right in reversed(links):
                term = self.build(right, depth + 1)
                parts.append(-term if isinstance(op, ast.Sub) else term)
            if not product:
                return sp.Add(*parts)
            # a product folded left to right, as the nested evaluation did: SymPy
            # distributes a number over a sum only in a two-factor product, so Mul(*parts)
            # would give 2*x*(y + 1) where the text 2*(y+1)*x has always given x*(2*y + 2)
            out = parts[0]
            for factor in parts[1:]:
                out = out * factor
            return out
        if isinstance(node, ast.BinOp):
            if isinstance(node.op, ast.Pow):
                return self.power(node, depth)
            op = self._BINOPS.get(type(node.op))
            if op is None:
                raise self.fail(node, f"operator {type(node.op).__name__} is not allowed; use + - * / **")
            left = self.build(node.left, depth + 1)
            right = self.build(node.right, depth + 1)
            if isinstance(node.op, ast.Div) and right == 0:
                raise self.fail(node, "division by zero")
            return op(left, right)
        if isinstance(node, ast.Call):
            if isinstance(node.func, ast.Name) and node.func.id == SUM:
                return self.indexed_sum(node, depth)
            return self.call(node, depth)
        if isinstance(node, ast.Subscript):
            return self.subscript(node)
        raise self.fail(node, self.describe(node) + " is not allowed in an expression; allowed are "
                        "numbers, declared names, + - * / ** and the functions "
                        + ", ".join(sorted(FUNCTIONS)))

    @staticmethod
    def describe(node: ast.AST) -> str:
        kinds = {
            ast.Attribute: "attribute access",
            ast.Subscript: "subscripting",
            ast.Lambda: "lambda",
            ast.Tuple: "a tuple (expressions must be scalar)",
            ast.List: "a list (expressions must be scalar)",
            ast.Compare: "a comparison",
            ast.BoolOp: "a boolean operator",
            ast.IfExp: "a conditional expression",
            ast.NamedExpr: "an assignment expression",
        }
        return kinds.get(type(node), f"syntax element {type(node).__name__}")

    def constant(self, node: ast.Constant) -> sp.Expr:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(node, f"literal {value!r} is not a real number")
        if isinstance(value, int):
            return sp.Integer(value)
        if value != value or value in (float("inf"), float("-inf")):
            raise self.fail(node, "non-finite number")
        # repr gives the shortest decimal that round-trips: 0.1 -> 1/10 exactly.
        return sp.Rational(repr(value))

    # --- indexed sums ------------------------------------------------------------------------

    _INDEX_OPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b,
                  ast.Mult: lambda a, b: a * b, ast.FloorDiv: lambda a, b: a // b,
                  ast.Mod: lambda a, b: a % b}
    _INDEX_GRAMMAR = "integers, the indices of the enclosing Sums and + - * // % on them"

    def index_value(self, node: ast.AST, where: str) -> int:
        """An index expression (a bound or subscript) as a Python int."""
        if isinstance(node, ast.Constant) and isinstance(node.value, int) and not isinstance(node.value, bool):
            return node.value
        if isinstance(node, ast.Name):
            if node.id in self.bound:
                return self.bound[node.id]
            hint = (f"{node.id!r} is a declared symbol, not an index" if node.id in self.symbols
                    else f"{node.id!r} is not the index of an enclosing Sum")
            raise self.fail(node, f"{where}: {hint}; an index expression uses {self._INDEX_GRAMMAR}")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            v = self.index_value(node.operand, where)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.BinOp) and type(node.op) in self._INDEX_OPS:
            a, b = self.index_value(node.left, where), self.index_value(node.right, where)
            if isinstance(node.op, (ast.FloorDiv, ast.Mod)) and b == 0:
                raise self.fail(node, f"{where}: integer division by zero")
            if max(abs(a), abs(b)) > 10**9:
                raise self.fail(node, f"{where}: index beyond ±10⁹")
            return self._INDEX_OPS[type(node.op)](a, b)
        raise self.fail(node, f"{where}: {ast.unparse(node)!r} is not an index expression; "
                              f"allowed are {self._INDEX_GRAMMAR}")

    def subscript(self, node: ast.Subscript) -> sp.Expr:
        """``q[e]``: the declared symbol ``q<e>``."""
        if not isinstance(node.value, ast.Name) or isinstance(node.slice, (ast.Slice, ast.Tuple)):
            raise self.fail(node, f"subscripting {ast.unparse(node)!r} is not allowed: write name[index] with one "
                                  f"index expression ({self._INDEX_GRAMMAR}), e.g. q[i + 1] for q<i+1>")
        base = node.value.id
        k = self.index_value(node.slice, f"subscripting {ast.unparse(node)}")
        ident = f"{base}{k}"
        if k < 0 or ident not in self.symbols:
            known = sorted((n for n in self.symbols if n.startswith(base) and n[len(base):].isdigit()),
                           key=lambda n: int(n[len(base):]))
            have = (f"declared are {known[0]} … {known[-1]}" if len(known) > 1 else
                    f"declared is {known[0]}" if known else f"no declared symbol is {base}<integer>")
            raise self.fail(node, f"subscripting {ast.unparse(node)} gives {ident!r}, which is not a declared "
                                  f"symbol ({have})")
        return self.symbols[ident]

    def indexed_sum(self, node: ast.Call, depth: int) -> sp.Expr:
        """``Sum(body, i, lo, hi)``: body for i = lo, …, hi, expanded into terms."""
        usage = "Sum(body, i, lo, hi) takes the summand, an index name and its integer bounds"
        if node.keywords or len(node.args) != 4 or any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, f"{usage}, e.g. Sum(exp(q[i] - q[i+1]), i, 1, 7)")
        body, var, lo_node, hi_node = node.args
        if not isinstance(var, ast.Name):
            raise self.fail(var, f"{usage}: the second argument must be a name, got {ast.unparse(var)!r}")
        name = var.id
        if not _NAME_RE.fullmatch(name) or name in RESERVED or keyword.iskeyword(name):
            raise self.fail(var, f"Sum index {name!r} is not a valid name (a letter, then letters, digits, _)")
        if name in self.symbols:
            raise self.fail(var, f"Sum index {name!r} is a declared symbol; choose another index name")
        if name in self.bound:
            raise self.fail(var, f"Sum index {name!r} is already the index of an enclosing Sum")
        lo = self.index_value(lo_node, f"the lower bound of Sum over {name}")
        hi = self.index_value(hi_node, f"the upper bound of Sum over {name}")
        if hi < lo:
            raise self.fail(node, f"Sum over {name} from {lo} to {hi} is empty (the bounds are inclusive, lo ≤ hi)")
        if self.sum_terms + (hi - lo + 1) > MAX_SUM_TERMS:
            raise self.fail(node, f"the indexed sums expand to more than {MAX_SUM_TERMS} terms")
        self.sum_terms += hi - lo + 1
        # the summand's syntax nodes once per term, known before expanding (a nested Sum in
        # the summand counted by its own syntax only; the running count in build bounds it)
        if self.sum_nodes + (hi - lo + 1) * _expr_nodes(body) > MAX_SUM_NODES:
            raise self.fail(node, self._too_large())
        terms = []
        try:
            for v in range(lo, hi + 1):
                self.bound[name] = v
                terms.append(self.build(body, depth + 1))
        finally:
            self.bound.pop(name, None)
        return sp.Add(*terms)

    @staticmethod
    def _too_large() -> str:
        return (f"the indexed sums expand to more than {MAX_SUM_NODES:,} syntax nodes (summand size "
                "times number of terms); shorten the summand or the ranges")

    def name(self, node: ast.Name) -> sp.Expr:
        ident = node.id
        if ident in self.bound:
            return sp.Integer(self.bound[ident])
        if ident.startswith("_"):
            raise self.fail(node, f"name {ident!r} is not allowed (names may not start with '_')")
        if ident in self.symbols:
            return self.symbols[ident]
        if ident in CONSTANTS:
            return CONSTANTS[ident]
        if ident in FUNCTIONS:
            raise self.fail(node, f"function {ident!r} must be called, e.g. {ident}(x)")
        declared = ", ".join(sorted(self.symbols)) or "(none)"
        raise self.fail(node, f"unknown symbol {ident!r}; declared symbols are: {declared}")

    def power(self, node: ast.BinOp, depth: int) -> sp.Expr:
        base = self.build(node.left, depth + 1)
        exponent = self.build(node.right, depth + 1)
        # Guard against exponent towers such as 9**9**9 that would make SymPy
        # compute astronomically large integers.
        if exponent.is_number and (abs(exponent) > MAX_INT_EXPONENT):
            raise self.fail(node, f"exponent {exponent} is larger than {MAX_INT_EXPONENT} in magnitude")
        if base.is_number and exponent.is_number and base == 0 and exponent.is_negative:
            raise self.fail(node, "zero to a negative power")
        return base**exponent

    def call(self, node: ast.Call, depth: int) -> sp.Expr:
        if not isinstance(node.func, ast.Name):
            raise self.fail(node, "only direct calls of " + ", ".join(sorted(FUNCTIONS)) + " are allowed")
        fname = node.func.id
        if fname in _NONSMOOTH_TEXT:
            cls_name = _NONSMOOTH_TEXT[fname]
            arg = ast.unparse(node.args[0]) if len(node.args) == 1 and cls_name not in (
                "Max", "Min", "Piecewise") else None
            col = getattr(node, "col_offset", None)
            where = f" (column {col + 1})" if col is not None else ""
            raise ParseError(_refusal(f"{self.what}{where}", ast.unparse(node), cls_name, arg))
        if fname not in FUNCTIONS:
            raise self.fail(node, f"unknown function {fname!r}; allowed functions are "
                            + ", ".join(sorted(FUNCTIONS)))
        if node.keywords or len(node.args) != 1 or any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, f"{fname} takes exactly one positional argument")
        arg = self.build(node.args[0], depth + 1)
        return FUNCTIONS[fname](arg)
