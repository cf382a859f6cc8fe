"""Lattice Hamiltonians of symbolic size: a family of systems, one for every N.

A semi-discretised Hamiltonian PDE (sine-Gordon, NLS, a wave equation) or a chain is a sum
of *site terms*, each the same expression at every site of a range:

    H = Sum(p[i]**2/2, i, 1, N) + Sum((q[i % N + 1] - q[i])**2 * N**2/(2*L**2), i, 1, N)
        + Sum(1 - cos(q[i]), i, 1, N)

with ``N`` a declared *size* (a positive integer symbol, usable in expressions too).  Unlike
:mod:`methodgen.problem.parse`, which expands a sum over numbers into its terms, a sum over a symbolic
range is kept as one template: its summand in *slot symbols* ``q_0, q_p1, p_m1, …`` (the field
at the site ``i``, ``i + 1``, ``i - 1``), and its range ``lo ≤ i ≤ hi`` with each bound an integer
or ``N + c``.  Everything derived from it -- gradients, discrete gradients, their Jacobians,
the certificates -- is a statement about the template, independent of N; the generated module
builds the index tables for the N of its input at run time.

Index grammar (exact, by construction -- nothing is sampled):

* ``q[i + c]`` -- the site ``i + c``, which must lie in ``1 … N`` for every ``i`` of the range
  and every admissible N (checked from the bounds; e.g. ``Sum(…q[i+1]…, i, 1, N - 1)``);
* ``q[(i + c) % N + 1]`` -- the periodic neighbour ``i + c + 1`` (mod N), always valid;
* outside any Sum, ``q[k]`` and ``q[N - k]`` -- a fixed site (a boundary term).

A site term may couple sites up to :data:`MAX_TERM_WIDTH` apart (its slots' offsets span at most
that, e.g. ``(q[(i + 1) % N + 1] - q[i])**2`` couples i and i + 2): the step's Newton matrix is
then banded with half-bandwidth w sites (cyclically for a periodic lattice), solved in O(N)
by grouping w sites into one block (:mod:`methodgen.runtime.lattice_stepper`).  Nested (pair)
sums over a symbolic range, and wider terms, are refused with a message saying so.

Two structures:

* *canonical* (the default): fields ``q``, ``p``, ``y' = J ∇H`` with J the canonical matrix;
* *skew* (``Lattice(H, fields=("u",), skew="(g[i+1] - g[i-1])/(2*dx**2)")``): one field per site
  and ``u' = S ∇H`` with S a constant periodic stencil applied to the gradient ``g = ∇H``,
  ``(S g)_i = Σ_k c_k g_{i+k}``, e.g. the centred difference of a KdV lattice.  The stencil is
  parsed by the same whitelist parser (``g[i + c]`` or ``g[(i + c) % N + 1]``: the site i + c,
  cyclically), must be linear in g with coefficients free of the field, of half-width at most
  :data:`MAX_STENCIL_HALF_WIDTH`, and *skew*: ``c_0 = 0`` and ``c_{-k} = -c_k``, checked exactly
  (refused otherwise, naming the coefficient that fails).  Skew lattices are periodic: every
  term is summed over all sites ``Sum(…, i, 1, N)`` with periodic neighbours; any N ≥
  :attr:`Lattice.nmin` (odd too).

The Newton matrix's half-bandwidth in sites is :attr:`Lattice.half_width`: the widest term's
width (canonical), plus the stencil's half-width (skew, ``I - h S ∂∇̄H``).  Every lattice needs
N ≥ 2 w + 1, so that the sites i - w … i + w are distinct.

A *2-D periodic* lattice names two sizes, ``Lattice(H, size=("N", "M"))`` (a :class:`Lattice2D`):
terms ``Sum(Sum(body, j, 1, M), i, 1, N)`` over the N × M torus with two-index fields
``q[i, j]``, ``q[i % N + 1, j]``, ``q[i, (j - 2) % M + 1]``, kept as templates in 2-D slots
``q_0_0, q_p1_0, q_0_m1, …`` (:func:`slot_symbol2`); nearest neighbours, periodic both ways
(boundaries and wider stencils refused with a message saying what is valid).

References
----------
.. [1] E. Celledoni, V. Grimm, R. I. McLachlan, D. I. McLaren, D. O'Neale, B. Owren,
   G. R. W. Quispel, "Preserving energy resp. dissipation in numerical PDEs using the
   'Average Vector Field' method", J. Comput. Phys. 231 (2012) 6770-6789.
.. [2] D. Furihata, T. Matsuo, *Discrete Variational Derivative Method*, CRC Press (2011).
"""

from __future__ import annotations

import ast
import keyword
from dataclasses import dataclass
from typing import Mapping

import sympy as sp

from ..errors import InputError, ParseError
from .parse import (CONSTANTS, FUNCTIONS, MAX_TEXT, RESERVED, SUM, _Builder, _check_double_range,
                    _NAME_RE, check_smooth)

__all__ = ["Bound", "SiteTerm", "Lattice", "slot_symbol", "STENCIL_GRADIENT", "STENCIL_INDEX", "Lattice2D",
           "SiteTerm2D", "slot_symbol2"]

#: smallest size any lattice admits: with N ≥ 3 the sites i - 1, i, i + 1 are distinct
MIN_SIZE = 3
#: the names a skew stencil's text uses: the gradient ``g`` at the row's site ``i``
STENCIL_GRADIENT, STENCIL_INDEX = "g", "i"
#: the widest site term: its slots' offsets span at most this many sites (the Newton matrix's
#: blocks grow with the width, w sites per block: 4 keeps them ≤ 8 × 8 for a canonical lattice)
MAX_TERM_WIDTH = 4
#: the widest skew stencil: g[i - 3] … g[i + 3] (a sixth-order first difference)
MAX_STENCIL_HALF_WIDTH = 3
_SKEW_EXAMPLE = "(g[i+1] - g[i-1])/(2*dx)"


def slot_symbol(field: str, offset: int) -> sp.Symbol:
    """The symbol of ``field`` at the site ``i + offset`` of a template (``q_0``, ``q_p1``, ``p_m2``)."""
    tag = "0" if offset == 0 else (f"p{offset}" if offset > 0 else f"m{-offset}")
    return sp.Symbol(f"{field}_{tag}", real=True)


@dataclass(frozen=True)
class Bound:
    """A range bound: ``c`` (``from_end`` False) or ``N + c`` (``from_end`` True), 1-based."""

    from_end: bool
    c: int

    def value(self, n: int) -> int:
        return n + self.c if self.from_end else self.c

    def __str__(self) -> str:
        if not self.from_end:
            return str(self.c)
        return "N" if self.c == 0 else f"N {'+' if self.c > 0 else '-'} {abs(self.c)}"


@dataclass(frozen=True)
class SiteTerm:
    """One template summed over a range of sites.

    Attributes
    ----------
    template : sympy.Expr
        The summand in slot symbols (:func:`slot_symbol`), parameters and the size symbol.
    slots : tuple of (str, int)
        The (field, offset) of each slot symbol the template uses, sorted.
    lo, hi : Bound
        The sites ``lo ≤ i ≤ hi`` (1-based) the template is summed over.
    source : str
        The text of the term.
    """

    template: sp.Expr
    slots: tuple[tuple[str, int], ...]
    lo: Bound
    hi: Bound
    source: str

    def symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(slot_symbol(f, o) for f, o in self.slots)

    def sites(self, n: int) -> tuple[int, int]:
        """The 0-based first and last site of the range at size ``n``."""
        return self.lo.value(n) - 1, self.hi.value(n) - 1

    def width(self) -> int:
        offs = [o for _, o in self.slots]
        return max(offs) - min(offs) if offs else 0


# --- index values: ("int", a) | ("size", c) = N + c | ("lin", c) = i + c | ("mod", c) = (i + c) % N
#     | ("per", c) = (i + c - 1) % N + 1, the periodic site i + c

_PERIODIC_HINT = "write a periodic neighbour as q[(i + c) % N + 1] (the site i + c + 1, mod N)"


class _LatticeBuilder(_Builder):
    """:class:`methodgen.problem.parse._Builder` with Sums over a symbolic size kept as templates."""

    def __init__(self, symbols, fields, size: sp.Symbol, what: str):
        super().__init__(symbols, what)
        self.fields = fields
        self.size = size
        self.index_name: str | None = None      # the index of the enclosing Sum
        self.sums: list[tuple[sp.Symbol, sp.Expr, Bound, Bound, str]] = []
        self.anchors: dict[sp.Symbol, tuple[str, Bound]] = {}

    # the symbolic index arithmetic
    def ivalue(self, node: ast.AST, where: str):
        if isinstance(node, ast.Constant) and isinstance(node.value, int) and not isinstance(node.value, bool):
            return ("int", node.value)
        if isinstance(node, ast.Name):
            if node.id == self.index_name:
                return ("lin", 0)
            if node.id == self.size.name:
                return ("size", 0)
            hint = (f"{node.id!r} is not the index of the enclosing Sum" if self.index_name else
                    f"{node.id!r} is not an index (outside a Sum, a site is a number k or N - k)")
            raise self.fail(node, f"{where}: {hint}")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            kind, v = self.ivalue(node.operand, where)
            if kind == "int":
                return ("int", -v)
        elif isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
            (ka, a), (kb, b) = self.ivalue(node.left, where), self.ivalue(node.right, where)
            sign = 1 if isinstance(node.op, ast.Add) else -1
            if kb == "int" and ka in ("int", "size", "lin"):
                return (ka, a + sign * b)
            if ka == "int" and kb in ("size", "lin") and sign == 1:
                return (kb, a + b)
            if ka == "mod" and kb == "int" and sign == 1 and b == 1:
                return ("per", a + 1)
            if ka == "mod" or kb == "mod":
                raise self.fail(node, f"{where}: {ast.unparse(node)!r} may leave 1 … N; {_PERIODIC_HINT}")
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mod):
            (ka, a), (kb, b) = self.ivalue(node.left, where), self.ivalue(node.right, where)
            if ka == "lin" and (kb, b) == ("size", 0):
                return ("mod", a)
            if ka == "int" and kb == "int" and b != 0:
                return ("int", a % b)
        raise self.fail(node, f"{where}: {ast.unparse(node)!r} is not a supported index; use i + c "
                              f"(a site of the range), (i + c) % N + 1 (periodic), or a fixed site k or N - k")

    def range_bound(self, node: ast.AST, where: str) -> Bound:
        kind, v = self.ivalue(node, where)
        if kind == "int":
            return Bound(False, v)
        if kind == "size":
            return Bound(True, v)
        raise self.fail(node, f"{where} must be an integer or N + c")

    def subscript(self, node: ast.Subscript) -> sp.Expr:
        if (not isinstance(node.value, ast.Name) or node.value.id not in self.fields
                or isinstance(node.slice, (ast.Slice, ast.Tuple))):
            raise self.fail(node, f"subscripting {ast.unparse(node)!r} is not allowed: write "
                                  f"{'[…] or '.join(self.fields)}[…] with one index")
        field = node.value.id
        kind, v = self.ivalue(node.slice, f"subscripting {ast.unparse(node)}")
        if self.index_name is not None:
            if kind == "lin":
                self.lin_offsets.append((node, v))
                return slot_symbol(field, v)
            if kind == "per":          # (i + c - 1) % N + 1: the site i + c, cyclically
                return slot_symbol(field, v)
            if kind == "mod":
                raise self.fail(node, f"{ast.unparse(node)}: (i + c) % N is 0 … N-1, not a site 1 … N; "
                                      f"{_PERIODIC_HINT}")
            raise self.fail(node, f"subscripting {ast.unparse(node)} inside a Sum names a fixed site; a site "
                                  f"term may use only sites relative to its index (i + c, or (i + c) % N + 1)")
        if kind == "int":
            b = Bound(False, v)
        elif kind == "size":
            b = Bound(True, v)
        else:
            raise self.fail(node, f"subscripting {ast.unparse(node)} outside a Sum needs a fixed site k or N - k")
        if (not b.from_end and b.c < 1) or (b.from_end and b.c > 0):
            raise self.fail(node, f"{ast.unparse(node)} is outside the sites 1 … N")
        sym = sp.Symbol(f"_anchor_{field}_{'e' if b.from_end else 's'}{b.c}".replace("-", "m"), real=True)
        self.anchors[sym] = (field, b)
        return sym

    def name(self, node: ast.Name) -> sp.Expr:
        if node.id == self.size.name:
            return self.size
        if node.id == self.index_name:
            raise self.fail(node, f"the Sum index {node.id!r} may appear only in subscripts")
        return super().name(node)

    def indexed_sum(self, node: ast.Call, depth: int) -> sp.Expr:
        usage = "Sum(body, i, lo, hi) takes the summand, an index name and its bounds"
        if node.keywords or len(node.args) != 4 or any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, f"{usage}, e.g. Sum(1 - cos(q[i]), i, 1, N)")
        if self.index_name is not None:
            raise self.fail(node, "nested Sums (pair interactions) over a symbolic size are not supported: "
                                  "a lattice term couples neighbouring sites")
        body, var, lo_node, hi_node = node.args
        if not isinstance(var, ast.Name):
            raise self.fail(var, f"{usage}: the second argument must be a name")
        name = var.id
        if (not _NAME_RE.fullmatch(name) or name in RESERVED or keyword.iskeyword(name)
                or name in self.symbols or name in self.fields or name == self.size.name):
            raise self.fail(var, f"Sum index {name!r} is not a free name (it is a field, the size, a parameter or "
                                 "a word of the grammar): choose another, e.g. j or k")
        lo = self.range_bound(lo_node, f"the lower bound of Sum over {name}")
        hi = self.range_bound(hi_node, f"the upper bound of Sum over {name}")
        # empty for every N, or for every N but finitely many: a typo, not a term
        if (lo.from_end == hi.from_end and hi.c < lo.c) or (lo.from_end and not hi.from_end):
            raise self.fail(node, f"Sum over {name} from {lo} to {hi} is empty (for all but a few N); the "
                                  "bounds are inclusive, lo ≤ hi, e.g. Sum(…, i, 1, N)")
        self.index_name, self.lin_offsets = name, []
        try:
            template = self.build(body, depth + 1)
        finally:
            self.index_name = None
        lins, self.lin_offsets = self.lin_offsets, []
        for sub, c in lins:    # q[i + c] must be a site 1 … N for every i of the range
            low_ok = (lo.c + c >= 1) if not lo.from_end else True
            high_ok = (hi.c + c <= 0) if hi.from_end else True
            if not (low_ok and high_ok):
                raise self.fail(sub, f"{ast.unparse(sub)} leaves the sites 1 … N for i = {lo} … {hi}; "
                                     f"narrow the range or {_PERIODIC_HINT}")
        placeholder = sp.Symbol(f"_sum{len(self.sums)}", real=True)
        self.sums.append((placeholder, template, lo, hi, ast.unparse(node)))
        return placeholder


class _StencilBuilder(_LatticeBuilder):
    """One row ``(S g)_i`` of a skew stencil: ``g[i + c]`` (or ``g[(i + c) % N + 1]``) is the
    gradient at the site i + c, cyclically -- the row's index is fixed, there is no Sum."""

    def __init__(self, symbols, size: sp.Symbol, what: str):
        super().__init__(symbols, (STENCIL_GRADIENT,), size, what)
        self.index_name = STENCIL_INDEX
        self.lin_offsets = []

    def subscript(self, node: ast.Subscript) -> sp.Expr:
        if (isinstance(node.value, ast.Name) and node.value.id == STENCIL_GRADIENT
                and not isinstance(node.slice, (ast.Slice, ast.Tuple))):
            kind, _ = self.ivalue(node.slice, f"subscripting {ast.unparse(node)}")
            if kind in ("int", "size"):
                raise self.fail(node, f"{ast.unparse(node)} names a fixed site; a stencil row uses the sites "
                                      f"relative to its own, g[i + c], e.g. {_SKEW_EXAMPLE}")
        return super().subscript(node)

    def indexed_sum(self, node: ast.Call, depth: int) -> sp.Expr:
        raise self.fail(node, f"the skew stencil is one row (S g)_i, a combination of g[i + c] with no Sum; "
                              f"e.g. {_SKEW_EXAMPLE}")


class Lattice:
    """A Hamiltonian lattice of symbolic size N: canonical fields ``q[1..N]``, ``p[1..N]``, or one
    field ``u[1..N]`` with a constant skew stencil (``u' = S ∇H``, module docstring).

    Parameters
    ----------
    H : str
        The Hamiltonian as text: a sum of site terms ``Sum(body, i, lo, hi)`` (times factors free
        of the fields) and boundary terms at fixed sites (module docstring).
    q, p : str
        The field names (default ``"q"``, ``"p"``).
    size : str
        The name of the size (default ``"N"``).
    params : mapping of str to float
        Parameter values (names declared for H); the size is not one of them.
    name : str
    invariants : mapping of str to str, optional
        Quantities to monitor, each a sum of site terms in the same grammar (e.g. the mass
        ``"Sum(q[i]**2 + p[i]**2, i, 1, N)"`` of a Schrödinger lattice).  ``"H"`` is always one.
    fields : tuple of one str, optional
        The field of a skew lattice (default ``("u",)`` when ``skew`` is given); canonical
        lattices name theirs with ``q`` and ``p``.
    skew : str, optional
        The skew structure: one row ``(S g)_i`` of a periodic stencil in ``g[i + c]`` (the
        gradient ∇H at the site i + c, cyclically), e.g. ``"(g[i+1] - g[i-1])/(2*dx**2)"``;
        coefficients in the parameters, numbers and N.  Checked exactly to be skew.

    Attributes
    ----------
    terms : tuple of SiteTerm
    invariants : dict of str to tuple of SiteTerm
    nmin : int
        The smallest N at which every term's range and site is valid.
    structure : {"canonical", "skew"}
    stencil : dict of int to sympy.Expr
        A skew lattice's coefficients ``c_k`` (offset k → coefficient, the nonzero ones); empty
        for a canonical lattice.

    Examples
    --------
    >>> kdv = Lattice("Sum(dx*(-u[i]**3 + (u[i % N + 1] - u[i])**2/(2*dx**2)), i, 1, N)",
    ...               fields=("u",), skew="(g[i+1] - g[i-1])/(2*dx**2)", params={"dx": 0.1})
    >>> kdv.structure, sorted(kdv.stencil)
    ('skew', [-1, 1])
    """

    def __new__(cls, H=None, *args, size="N", **kw):
        # two sizes: a 2-D periodic lattice (Lattice2D, which is not a Lattice: __init__ below is
        # not run on it)
        if cls is Lattice and isinstance(size, (tuple, list)):
            return Lattice2D(H, *args, size=tuple(size), **kw)
        return super().__new__(cls)

    def __init__(self, H: str, q: str = "q", p: str = "p", *, size: str = "N",
                 params: Mapping[str, float] | None = None, name: str = "lattice",
                 invariants: Mapping[str, str] | None = None, fields=None, skew: str | None = None):
        if not isinstance(H, str):
            raise InputError(f"the lattice Hamiltonian must be text, got {type(H).__name__}")
        if len(H) > MAX_TEXT:
            raise ParseError(f"Hamiltonian is longer than {MAX_TEXT} characters")
        params = dict(params or {})
        if skew is None and fields is not None:
            raise InputError("fields=(…) names the one field of a skew lattice and needs its structure, "
                             f"skew=\"{_SKEW_EXAMPLE}\"; a canonical lattice names its fields with q= and p=")
        if skew is not None:
            if (q, p) != ("q", "p"):
                raise InputError("a skew lattice has one field, named by fields=(\"u\",); q= and p= name the "
                                 "fields of a canonical lattice")
            fields = ("u",) if fields is None else fields
            if isinstance(fields, str) or not isinstance(fields, (tuple, list)) or len(fields) != 1:
                raise InputError(f"a skew lattice has one field per site: fields=(\"u\",), got {fields!r} "
                                 "(several fields with a skew stencil are not supported yet)")
            if not isinstance(skew, str):
                raise InputError(f"skew must be text, one row of the stencil, e.g. {_SKEW_EXAMPLE!r}; got "
                                 f"{type(skew).__name__}")
            names = (fields[0], size, *params)
        else:
            names = (q, p, size, *params)
        for nm in names:
            if not isinstance(nm, str) or not _NAME_RE.fullmatch(nm) or nm in RESERVED or keyword.iskeyword(nm):
                raise InputError(f"{nm!r} is not a valid name (a letter, then letters, digits, _)")
        if len(set(names)) != len(names):
            raise InputError(f"the names of the fields ({', '.join(names[:len(names) - 1 - len(params)])}), "
                             f"the size ({size!r}) and the parameters must differ")
        prefixes = tuple(f"{f}_" for f in names[:len(names) - 1 - len(params)])
        clash = [k for k in params if k.startswith(prefixes)]
        if clash:
            raise InputError(f"parameter names may not start with {' or '.join(map(repr, prefixes))} (the site "
                             f"symbols' names): {', '.join(clash)}")
        if skew is not None and STENCIL_GRADIENT in names:
            raise InputError(f"{STENCIL_GRADIENT!r} is the gradient in the skew stencil's text; give the field or "
                             "parameter another name")
        if size in params:
            raise InputError(f"{size!r} is the size; give it as the state's length, not a parameter")
        for k, v in params.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise InputError(f"parameter {k!r} must be a real number, got {v!r}")
        self.name, self.text = name, H
        self.structure = "canonical" if skew is None else "skew"
        self.q_name, self.p_name = (q, p) if skew is None else (fields[0], None)
        self.size = sp.Symbol(size, integer=True, positive=True)
        self.params = {k: float(v) for k, v in params.items()}
        self.param_symbols = tuple(sp.Symbol(k, real=True) for k in params)
        self.skew_text = skew
        self.stencil = {} if skew is None else self._stencil(skew)
        self.terms = self._parse(H, "Hamiltonian")
        self.invariant_texts = dict(invariants or {})
        self.invariants = _parsed_invariants(self.invariant_texts, self._parse)
        self.nmin = self._nmin()
        if skew is not None:
            self._check_periodic()

    def _stencil(self, text: str) -> dict:
        """The coefficients ``c_k`` of one row ``(S g)_i = Σ_k c_k g[i + k]``, checked exactly: linear
        in g, coefficients free of the field, half-width ≤ 1, skew (c_0 = 0, c_{-k} = -c_k)."""
        what = "skew stencil"
        if len(text) > MAX_TEXT:
            raise ParseError(f"{what} is longer than {MAX_TEXT} characters")
        b = _StencilBuilder({s.name: s for s in self.param_symbols}, self.size, what)
        row = _build_scalar(b, text, what)
        if b.anchors:
            raise ParseError(f"{what}: a fixed site; write the row with g[i + c] (the site i + c, cyclically)")
        gs = sorted((k for k in map(_parse_slot, row.free_symbols) if k and k[0] == STENCIL_GRADIENT),
                    key=lambda k: k[1])
        syms = [slot_symbol(STENCIL_GRADIENT, o) for _, o in gs]
        coeffs = {o: sp.diff(row, s) for (_, o), s in zip(gs, syms)}
        rest = sp.expand(row - sp.Add(*[c * s for (o, c), s in zip(coeffs.items(), syms)]))
        if any(c.free_symbols & set(syms) for c in coeffs.values()) or rest != 0:
            raise ParseError(f"{what} {text!r} is not linear in g: a stencil is Σ_k c_k g[i + k] with "
                             f"coefficients free of g, e.g. {_SKEW_EXAMPLE}")
        coeffs = {o: sp.factor(sp.cancel(c)) for o, c in coeffs.items()}
        coeffs = {o: c for o, c in coeffs.items() if c != 0}
        if not coeffs:
            raise ParseError(f"{what} {text!r} is zero: u' = S ∇H would not move")
        wide = [o for o in coeffs if abs(o) > MAX_STENCIL_HALF_WIDTH]
        if wide:
            w = MAX_STENCIL_HALF_WIDTH
            raise ParseError(f"{what} {text!r} reaches g[i {'+' if wide[0] > 0 else '-'} {abs(wide[0])}]: stencils "
                             f"of half-width at most {w} only (g[i - {w}] … g[i + {w}])")
        # exactly skew: each pair cancels, c_0 = 0 (reduced by cancel: rational in params and N)
        bad = []
        for o in sorted({abs(o) for o in coeffs}):
            pair = sp.cancel(coeffs.get(o, sp.S.Zero) + coeffs.get(-o, sp.S.Zero))
            if pair != 0:
                bad.append(f"c_0 = {coeffs[0]} (must be 0)" if o == 0 else
                           f"c_{o} = {coeffs.get(o, 0)} and c_-{o} = {coeffs.get(-o, 0)} (must be opposite)")
        if bad:
            raise ParseError(f"{what} {text!r} is not skew: {'; '.join(bad)}; a skew stencil has c_0 = 0 and "
                             f"c_(-k) = -c_k, e.g. {_SKEW_EXAMPLE}")
        for c in coeffs.values():
            check_smooth(c, what)
            if c.free_symbols - set(self.param_symbols) - {self.size} or c.has(sp.I, sp.zoo, sp.oo, sp.nan):
                raise ParseError(f"{what}: the coefficient {c} is not a finite real expression in the parameters "
                                 "and N")
        return dict(sorted(coeffs.items()))

    def _check_periodic(self) -> None:
        """A skew lattice is periodic: every term summed over all sites 1 … N (no boundary)."""
        for what, terms in (("Hamiltonian", self.terms), *((f"invariant {k}", v) for k, v in self.invariants.items())):
            for t in terms:
                if t.slots and (t.lo, t.hi) != (Bound(False, 1), Bound(True, 0)):
                    where = (f"is a boundary term at a fixed site" if t.lo == t.hi and "Sum" not in t.source else
                             f"is summed over i = {t.lo} … {t.hi}")
                    raise ParseError(f"{what}: {t.source} {where}; skew lattices are periodic only (for now): "
                                     f"write every term as Sum(…, i, 1, N) with periodic neighbours "
                                     f"{self.q_name}[i % N + 1], {self.q_name}[(i - 2) % N + 1]")

    def _parse(self, text: str, what: str) -> tuple[SiteTerm, ...]:
        symbols = {s.name: s for s in self.param_symbols}
        b = _LatticeBuilder(symbols, self.fields, self.size, what)
        top = _build_scalar(b, text, what)
        terms = []
        placeholders = [s for s, *_ in b.sums]
        for ph, template, lo, hi, src in b.sums:
            coeff = sp.diff(top, ph)
            if coeff.free_symbols & (set(placeholders) | set(b.anchors)):
                raise ParseError(f"{what}: {src} enters non-linearly (times another sum or a field); "
                                 "it must be a sum of site terms")
            terms.append(self._term(coeff * template, lo, hi, src))
        rest = sp.sympify(top.xreplace({ph: sp.S.Zero for ph in placeholders}))
        for t in sp.Add.make_args(rest):
            used = [s for s in t.free_symbols if s in b.anchors]
            if not used:
                if t != 0:    # a constant: no dynamics, but part of the value
                    terms.append(SiteTerm(t, (), Bound(False, 1), Bound(False, 1), str(t)))
                continue
            terms.append(self._anchored(t, used, b.anchors))
        if not any(t.slots for t in terms):
            raise ParseError(f"{what} has no term in the fields")
        for t in terms:
            _check_term(t, what)
            if t.width() > MAX_TERM_WIDTH:
                raise ParseError(f"{what} term {t.source} couples sites {t.width()} apart; lattice terms may "
                                 f"couple sites at most {MAX_TERM_WIDTH} apart (their offsets spanning at most "
                                 f"{MAX_TERM_WIDTH}, e.g. q[i] and q[(i + {MAX_TERM_WIDTH - 1}) % N + 1])")
        return tuple(terms)

    def _term(self, template, lo: Bound, hi: Bound, src: str) -> SiteTerm:
        slots = sorted({k for k in map(_parse_slot, template.free_symbols) if k and k[0] in self.fields})
        return SiteTerm(template, tuple(slots), lo, hi, src)

    def _anchored(self, t: sp.Expr, used, anchors) -> SiteTerm:
        # Positions 0-based with N taken as 0 (site N is -1): differences are the cyclic offsets
        pos = {s: (anchors[s][1].c - 1) for s in used}
        ref = min(used, key=lambda s: (anchors[s][1].from_end, anchors[s][1].c))
        base = anchors[ref][1]
        sub = {s: slot_symbol(anchors[s][0], pos[s] - pos[ref]) for s in used}
        shown = {s: sp.Symbol(f"{anchors[s][0]}[{anchors[s][1]}]") for s in used}
        return self._term(t.xreplace(sub), base, base, str(t.xreplace(shown)))

    def _nmin(self) -> int:
        n = MIN_SIZE
        for t in self.terms + tuple(x for ts in self.invariants.values() for x in ts):
            for (f, o) in t.slots:
                for bnd in (t.lo, t.hi):
                    # a fixed-count bound c and its slots must fit: c + o ≤ N
                    if not bnd.from_end:
                        n = max(n, bnd.c + max(o, 0))
                    else:
                        n = max(n, 1 - bnd.c - min(o, 0))
            if not t.lo.from_end and t.hi.from_end:
                n = max(n, t.lo.c - t.hi.c)
        # the sites i - w … i + w of the Newton matrix's band distinct (no entry wraps onto another)
        return max(n, 2 * self.half_width + 1)

    @property
    def jacobian_half_width(self) -> int:
        """The half-bandwidth in sites of ∂∇H: the widest term of H (a term's pieces at the site
        j depend on the slots of every site the term couples to j)."""
        return max((t.width() for t in self.terms), default=0)

    @property
    def half_width(self) -> int:
        """The Newton matrix's half-bandwidth w in sites: ``I - h J ∂∇̄H`` couples sites at most
        :attr:`jacobian_half_width` apart; ``I - h S ∂∇̄H`` that plus the stencil's half-width."""
        return self.jacobian_half_width + max((abs(k) for k in self.stencil), default=0)

    # --- the pieces the derivations and the module need -------------------------------------

    @property
    def fields(self) -> tuple[str, ...]:
        """The field names: ``(q, p)``, or ``(u,)`` for a skew lattice."""
        return (self.q_name, self.p_name) if self.structure == "canonical" else (self.q_name,)

    def check_size(self, n: int) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or n < self.nmin:
            raise InputError(f"the lattice {self.name!r} needs N ≥ {self.nmin} sites, got {n!r}")

    def stencil_matrix(self, n: int) -> sp.Matrix:
        """S at size ``n`` as an n × n matrix, ``S[i, (i + k) % n] += c_k`` (for tests at small n)."""
        self.check_size(n)
        S = sp.zeros(n, n)
        for k, c in self.stencil.items():
            for i in range(n):
                S[i, (i + k) % n] += c.xreplace({self.size: sp.Integer(n)})
        return S

    def expand(self, n: int) -> tuple[sp.Expr, list[sp.Symbol], list[sp.Symbol]]:
        """H at size ``n`` as an expression in ``q1..qn, p1..pn`` (for tests and checks at small n);
        a skew lattice's in ``u1..un`` (the third item then empty)."""
        self.check_size(n)
        qs = [sp.Symbol(f"{self.q_name}{k}", real=True) for k in range(1, n + 1)]
        ps = ([sp.Symbol(f"{self.p_name}{k}", real=True) for k in range(1, n + 1)]
              if self.structure == "canonical" else [])
        arrays = {self.q_name: qs, self.p_name: ps}
        out = []
        for t in self.terms:
            a, b = t.sites(n)
            for i in range(a, b + 1):
                sub = {slot_symbol(f, o): arrays[f][(i + o) % n] for f, o in t.slots}
                sub[self.size] = sp.Integer(n)
                out.append(t.template.xreplace(sub))
        return sp.Add(*out), qs, ps


def _check_term(t, what: str) -> None:
    """ParseError unless a site term's template (1-D or 2-D) is smooth, has no nested range over
    the size, and is a finite real expression."""
    check_smooth(t.template, what)
    _check_double_range(t.template, what)
    if t.template.has(sp.I) or t.template.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        raise ParseError(f"{what} term {t.source} is not a finite real expression")


def _parsed_invariants(texts: Mapping, parse) -> dict:
    """``{name: site terms}`` of a lattice's monitored invariants, each text parsed by ``parse``
    (a lattice's own ``_parse``); InputError for a name that is not an identifier (or is H) or
    a value that is not text."""
    out = {}
    for k, text in texts.items():
        if not isinstance(k, str) or not _NAME_RE.fullmatch(k) or k == "H":
            raise InputError(f"invariant name {k!r} is not a valid name other than H")
        if not isinstance(text, str):
            raise InputError(f"invariant {k!r} must be text, got {type(text).__name__}")
        out[k] = parse(text, f"invariant {k}")
    return out


def _build_scalar(builder, text: str, what: str) -> sp.Expr:
    """``text`` parsed (:mod:`ast`, never evaluated) and built by the whitelist ``builder``: a
    scalar expression, or ParseError naming ``what``."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ParseError(f"syntax error in {what}: {exc.msg}: {text!r}") from None
    out = builder.build(tree.body, 0)
    if not isinstance(out, sp.Expr):
        raise ParseError(f"{what} must be a scalar expression")
    return out


def _parse_slot(s: sp.Symbol):
    name = s.name
    if "_" not in name or name.startswith("_"):
        return None
    field, tag = name.rsplit("_", 1)
    if tag == "0":
        return (field, 0)
    if tag[:1] in "pm" and tag[1:].isdigit():
        return (field, int(tag[1:]) * (1 if tag[0] == "p" else -1))
    return None


# --- 2-D periodic lattices -------------------------------------------------------------------
#
# ``Lattice(H, size=("N", "M"))`` (dispatched by :meth:`Lattice.__new__`): the sites (i, j) of an
# N × M torus, a term ``Sum(Sum(body, j, 1, M), i, 1, N)`` with ``q[i, j]``, ``q[i % N + 1, j]``,
# ``q[i, (j - 2) % M + 1]`` … (the field at the site i + a, j + b, cyclically).  Periodic both ways
# and nearest neighbours only: the step's linear part is then a periodic stencil that the 2-D
# FFT diagonalises (methodgen.symbolic.lattice_scheme.linear_stencil).

_EXAMPLE_2D = "Sum(Sum(p[i, j]**2/2 + (q[i % N + 1, j] - q[i, j])**2/2 + (q[i, j % M + 1] - q[i, j])**2/2, j, 1, M), i, 1, N)"
_PERIODIC_HINT_2D = ("2-D lattices are periodic both ways: write a neighbour as q[i % N + 1, j], q[(i - 2) % N + 1, j], "
                     "q[i, j % M + 1], q[i, (j - 2) % M + 1]")


def _otag2(o: int) -> str:
    return "0" if o == 0 else (f"p{o}" if o > 0 else f"m{-o}")


def slot_symbol2(field: str, offset: tuple[int, int]) -> sp.Symbol:
    """The symbol of ``field`` at the site ``(i + a, j + b)`` of a 2-D template (``q_0_0``, ``q_p1_0``,
    ``p_0_m1``)."""
    return sp.Symbol(f"{field}_{_otag2(offset[0])}_{_otag2(offset[1])}", real=True)


def _parse_slot2(s: sp.Symbol):
    """(field, (a, b)) of a 2-D slot symbol, or None."""
    parts = s.name.rsplit("_", 2)
    if len(parts) != 3 or not parts[0] or s.name.startswith("_"):
        return None
    offs = []
    for tag in parts[1:]:
        if tag == "0":
            offs.append(0)
        elif tag[:1] in "pm" and tag[1:].isdigit():
            offs.append(int(tag[1:]) * (1 if tag[0] == "p" else -1))
        else:
            return None
    return parts[0], tuple(offs)


@dataclass(frozen=True)
class SiteTerm2D:
    """One template summed over every site (i, j) of the N × M torus.

    Attributes
    ----------
    template : sympy.Expr
        The summand in slot symbols (:func:`slot_symbol2`), parameters and the sizes.
    slots : tuple of (str, (int, int))
        The (field, (a, b)) of each slot symbol, sorted.
    source : str
    """

    template: sp.Expr
    slots: tuple
    source: str

    def symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(slot_symbol2(f, o) for f, o in self.slots)

    def width(self) -> tuple[int, int]:
        """The span of the offsets in each direction (0 or 1 for nearest neighbours)."""
        if not self.slots:
            return (0, 0)
        return tuple(max(o[k] for _, o in self.slots) - min(o[k] for _, o in self.slots) for k in (0, 1))


class _Lattice2DBuilder(_Builder):
    """:class:`methodgen.problem.parse._Builder` for a 2-D periodic lattice: a term is two nested
    Sums, one over each size, kept as a template in 2-D slots."""

    def __init__(self, symbols, fields, sizes, what: str):
        super().__init__(symbols, what)
        self.fields, self.sizes = fields, sizes
        self.axis_of: dict[str, int] = {}      # the enclosing Sums' indices → their axis (0: N, 1: M)
        self.sums: list[tuple[sp.Symbol, sp.Expr, str]] = []

    def _offset(self, node: ast.AST, axis: int, where: str) -> int:
        """The periodic offset c of ``index`` along ``axis``: ``i`` (0), ``i % N + 1`` (1),
        ``(i + c) % N + 1`` (c + 1); anything else refused naming the valid forms."""
        size = self.sizes[axis].name
        index = next((k for k, a in self.axis_of.items() if a == axis), None)

        def lin(n):          # i + c → c, or None
            if isinstance(n, ast.Name) and n.id == index:
                return 0
            if (isinstance(n, ast.BinOp) and isinstance(n.op, (ast.Add, ast.Sub))
                    and isinstance(n.left, ast.Name) and n.left.id == index
                    and isinstance(n.right, ast.Constant) and type(n.right.value) is int):
                return n.right.value if isinstance(n.op, ast.Add) else -n.right.value
            return None

        c = lin(node)
        if c == 0:
            return 0
        if c is not None:
            raise self.fail(node, f"{where}: {ast.unparse(node)!r} is a site near the edge, not a periodic "
                                  f"neighbour (2-D lattices have no boundaries); {_PERIODIC_HINT_2D}")
        if (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add) and isinstance(node.right, ast.Constant)
                and node.right.value == 1 and type(node.right.value) is int
                and isinstance(node.left, ast.BinOp) and isinstance(node.left.op, ast.Mod)
                and isinstance(node.left.right, ast.Name) and node.left.right.id == size):
            c = lin(node.left.left)
            if c is not None:
                return c + 1
        other = next((k for k, a in self.axis_of.items() if a != axis), None)
        if isinstance(node, ast.Name) and node.id == other or other in {n.id for n in ast.walk(node)
                                                                         if isinstance(n, ast.Name)}:
            raise self.fail(node, f"{where}: the {'first' if axis == 0 else 'second'} index runs over "
                                  f"{index} = 1 … {size} (the Sum over {size}), but {ast.unparse(node)!r} uses "
                                  f"{other!r}")
        raise self.fail(node, f"{where}: {ast.unparse(node)!r} is not a supported index; {_PERIODIC_HINT_2D}")

    def subscript(self, node: ast.Subscript) -> sp.Expr:
        where = f"subscripting {ast.unparse(node)}"
        if not isinstance(node.value, ast.Name) or node.value.id not in self.fields:
            raise self.fail(node, f"{where} is not allowed: write {'[…, …] or '.join(self.fields)}[…, …]")
        if len(self.axis_of) != 2:
            raise self.fail(node, f"{where} outside Sum(Sum(…, j, 1, {self.sizes[1]}), i, 1, {self.sizes[0]}): "
                                  "2-D lattices have no boundary terms at fixed sites; every term is summed over "
                                  "all sites")
        if not isinstance(node.slice, ast.Tuple) or len(node.slice.elts) != 2:
            raise self.fail(node, f"{where}: a field of a 2-D lattice takes two indices, "
                                  f"{node.value.id}[i, j] (i over {self.sizes[0]}, j over {self.sizes[1]})")
        a = self._offset(node.slice.elts[0], 0, where)
        b = self._offset(node.slice.elts[1], 1, where)
        return slot_symbol2(node.value.id, (a, b))

    def name(self, node: ast.Name) -> sp.Expr:
        for s in self.sizes:
            if node.id == s.name:
                return s
        if node.id in self.axis_of:
            raise self.fail(node, f"the Sum index {node.id!r} may appear only in subscripts")
        return super().name(node)

    def indexed_sum(self, node: ast.Call, depth: int) -> sp.Expr:
        N, M = (s.name for s in self.sizes)
        usage = f"a 2-D site term is Sum(Sum(body, j, 1, {M}), i, 1, {N})"
        if node.keywords or len(node.args) != 4 or any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, f"Sum(body, i, lo, hi) takes the summand, an index name and its bounds; {usage}")
        body, var, lo_node, hi_node = node.args
        if not isinstance(var, ast.Name):
            raise self.fail(var, "Sum(body, i, lo, hi): the second argument must be a name")
        name = var.id
        if (not _NAME_RE.fullmatch(name) or name in RESERVED or keyword.iskeyword(name) or name in self.symbols
                or name in self.fields or name in (N, M) or name in self.axis_of):
            raise self.fail(var, f"Sum index {name!r} is not a free name (a field, a size, a parameter, an "
                                 "enclosing Sum's index or a word of the grammar): choose another, e.g. i or j")
        if len(self.axis_of) == 2:
            raise self.fail(node, f"three nested Sums: {usage}")
        if not (isinstance(hi_node, ast.Name) and hi_node.id in (N, M)
                and isinstance(lo_node, ast.Constant) and lo_node.value == 1 and type(lo_node.value) is int):
            raise self.fail(node, f"Sum over {name} from {ast.unparse(lo_node)} to {ast.unparse(hi_node)}: 2-D "
                                  f"lattices are periodic, every term summed over all sites ({usage}); boundaries "
                                  f"and partial ranges are not supported")
        axis = 0 if hi_node.id == N else 1
        if axis in self.axis_of.values():
            raise self.fail(node, f"two nested Sums over {hi_node.id}: {usage}")
        if not self.axis_of and not (isinstance(body, ast.Call) and isinstance(body.func, ast.Name)
                                     and body.func.id == SUM):
            raise self.fail(node, f"Sum over {name} alone: {usage} (one Sum over each size, the inner one the "
                                  "whole summand of the outer)")
        self.axis_of[name] = axis
        try:
            inner = self.build(body, depth + 1)
        finally:
            del self.axis_of[name]
        if self.axis_of:               # the inner Sum: the template itself
            return inner
        placeholder = sp.Symbol(f"_sum{len(self.sums)}", real=True)
        self.sums.append((placeholder, inner, ast.unparse(node)))
        return placeholder


class Lattice2D:
    """A periodic 2-D lattice Hamiltonian of symbolic sizes N × M (``Lattice(H, size=("N", "M"))``).

    ``H`` is a sum of terms ``Sum(Sum(body, j, 1, M), i, 1, N)`` (or the Sums the other way
    round) over the sites (i, j) of the torus, with the fields at ``q[i, j]`` and at periodic
    neighbours ``q[(i + c) % N + 1, j]``, ``q[i, (j + c) % M + 1]``, nearest neighbours only (the
    offsets of a term span at most 1 in each direction); canonical fields q, p.  Refused with a
    message: boundaries (``q[i + 1, j]``, partial ranges, fixed sites), wider stencils, one-index
    fields, a skew structure.  The state is ``(q[1..N, 1..M], p[1..N, 1..M])`` as an array
    (2, N, M).

    Examples
    --------
    >>> w = Lattice("Sum(Sum(p[i, j]**2/2 + (q[i % N + 1, j] - q[i, j])**2/2 + (q[i, j % M + 1] - q[i, j])**2/2"
    ...             " + 1 - cos(q[i, j]), j, 1, M), i, 1, N)", size=("N", "M"))
    >>> type(w).__name__, [s.name for s in w.sizes]
    ('Lattice2D', ['N', 'M'])
    """

    dims = 2
    structure = "canonical"
    stencil: dict = {}
    skew_text = None

    def __init__(self, H: str, q: str = "q", p: str = "p", *, size=("N", "M"),
                 params: Mapping[str, float] | None = None, name: str = "lattice",
                 invariants: Mapping[str, str] | None = None, fields=None, skew: str | None = None):
        if skew is not None or fields is not None:
            raise InputError("2-D lattices are canonical (fields q and p, named by q= and p=); a skew structure "
                             "(fields=, skew=) is supported on 1-D lattices only")
        if not isinstance(H, str):
            raise InputError(f"the lattice Hamiltonian must be text, got {type(H).__name__}")
        if len(H) > MAX_TEXT:
            raise ParseError(f"Hamiltonian is longer than {MAX_TEXT} characters")
        params = dict(params or {})
        if not isinstance(size, (tuple, list)) or len(size) != 2:
            raise InputError(f"size of a 2-D lattice is two names, e.g. ('N', 'M'); got {size!r}")
        names = (q, p, *size, *params)
        for nm in names:
            if not isinstance(nm, str) or not _NAME_RE.fullmatch(nm) or nm in RESERVED or keyword.iskeyword(nm):
                raise InputError(f"{nm!r} is not a valid name (a letter, then letters, digits, _)")
        if len(set(names)) != len(names):
            raise InputError(f"the names of the fields ({q}, {p}), the sizes ({', '.join(size)}) and the parameters "
                             "must differ")
        clash = [k for k in params if k.startswith((f"{q}_", f"{p}_"))]
        if clash:
            raise InputError(f"parameter names may not start with {q + '_'!r} or {p + '_'!r} (the site symbols' "
                             f"names): {', '.join(clash)}")
        for k, v in params.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise InputError(f"parameter {k!r} must be a real number, got {v!r}")
        self.name, self.text = name, H
        self.q_name, self.p_name = q, p
        self.sizes = tuple(sp.Symbol(s, integer=True, positive=True) for s in size)
        self.size = self.sizes[0]      # (the first size: what 1-D code that names "the size" reads)
        self.params = {k: float(v) for k, v in params.items()}
        self.param_symbols = tuple(sp.Symbol(k, real=True) for k in params)
        self.terms = self._parse(H, "Hamiltonian")
        self.invariant_texts = dict(invariants or {})
        self.invariants = _parsed_invariants(self.invariant_texts, self._parse)
        self.nmin = MIN_SIZE

    @property
    def fields(self) -> tuple[str, str]:
        return (self.q_name, self.p_name)

    def _parse(self, text: str, what: str) -> tuple[SiteTerm2D, ...]:
        b = _Lattice2DBuilder({s.name: s for s in self.param_symbols}, self.fields, self.sizes, what)
        top = _build_scalar(b, text, what)
        placeholders = [s for s, *_ in b.sums]
        terms = []
        for ph, template, src in b.sums:
            coeff = sp.diff(top, ph)
            if coeff.free_symbols & set(placeholders):
                raise ParseError(f"{what}: {src} enters non-linearly (times another sum); it must be a sum of "
                                 "site terms")
            template = coeff * template
            slots = sorted({k for k in map(_parse_slot2, template.free_symbols) if k and k[0] in self.fields})
            terms.append(SiteTerm2D(template, tuple(slots), src))
        rest = sp.sympify(top.xreplace({ph: sp.S.Zero for ph in placeholders}))
        if rest != 0:
            terms.append(SiteTerm2D(rest, (), str(rest)))     # a constant: part of the value only
        if not any(t.slots for t in terms):
            raise ParseError(f"{what} has no term in the fields")
        for t in terms:
            _check_term(t, what)
            wide = [(ax, w) for ax, w in zip(self.sizes, t.width()) if w > 1]
            if wide:
                raise ParseError(f"{what} term {t.source} couples sites {wide[0][1]} apart along {wide[0][0]}; "
                                 "2-D lattice terms may couple nearest neighbours only (offsets spanning at most "
                                 "1 in each direction, e.g. q[i, j] and q[i % N + 1, j]; wider stencils are not "
                                 "supported)")
        return tuple(terms)

    def check_size(self, n, m=None) -> None:
        """Refuse sizes below :data:`MIN_SIZE` (``check_size((n, m))`` or ``check_size(n, m)``)."""
        if m is None and isinstance(n, (tuple, list)) and len(n) == 2:
            n, m = n
        for s, v in zip(self.sizes, (n, m)):
            if isinstance(v, bool) or not isinstance(v, int) or v < self.nmin:
                raise InputError(f"the 2-D lattice {self.name!r} needs {s} ≥ {self.nmin} sites, got {v!r}")

    def expand(self, n: int, m: int):
        """H at size n × m in ``q_a_b, p_a_b`` (a = 1 … n, b = 1 … m; lists in row-major order, for
        tests and checks at small sizes)."""
        self.check_size(n, m)
        qs = [sp.Symbol(f"{self.q_name}{a}_{b}", real=True) for a in range(1, n + 1) for b in range(1, m + 1)]
        ps = [sp.Symbol(f"{self.p_name}{a}_{b}", real=True) for a in range(1, n + 1) for b in range(1, m + 1)]
        arrays = {self.q_name: qs, self.p_name: ps}
        sizes = {self.sizes[0]: sp.Integer(n), self.sizes[1]: sp.Integer(m)}
        out = []
        for t in self.terms:
            for a in range(n):
                for b in range(m):
                    sub = {slot_symbol2(f, o): arrays[f][((a + o[0]) % n) * m + (b + o[1]) % m] for f, o in t.slots}
                    out.append(t.template.xreplace({**sub, **sizes}))
        return sp.Add(*out), qs, ps
