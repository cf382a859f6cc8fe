"""Particle systems of symbolic size: one family of N-body Hamiltonians, one for every N.

An N-body Hamiltonian is a sum of *one-body* terms and of *pair* terms, each the same
expression for every particle or every pair:

    H = Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N)
        - Sum(Sum(G*m[i]*m[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)

with position fields (``x, y[, z]``), momentum fields (``px, py[, pz]``), per-particle arrays
given at run time (the masses ``m``, length N), scalar parameters (``G``) and a size ``N``.
Unlike :mod:`methodgen.problem.parse`, which expands a sum over numbers into its terms, a sum
over the symbolic range is kept as a *template* in slot symbols: ``x_a, px_a, m_a`` (the
particle ``i``) and, in a pair sum, ``x_b, m_b`` (the particle ``j``).  Everything derived
from the family -- forces, discrete gradients, certificates -- is a statement about the two
templates, independent of N; the generated module builds the pair tables for the N of its
input at run time (:mod:`methodgen.codegen.particle_emit`).

Grammar (exact, by construction -- nothing is sampled):

* a one-body term ``Sum(body, i, 1, N)``: ``body`` in ``x[i]``, ``px[i]``, ``m[i]``, the
  parameters and numbers; it must split into a kinetic part, a homogeneous quadratic form in
  the momenta with coefficients in ``m[i]`` and the parameters, plus an external potential
  ``W(x[i], m[i])`` (the one-body term may not couple positions and momenta);
* a pair term ``Sum(Sum(body, j, i + 1, N), i, 1, N)`` (each pair once) or, the same pairs,
  ``Sum(Sum(body, j, 1, i - 1), i, 1, N)``: ``body`` in ``x[i]``, ``x[j]``, ``m[i]``, ``m[j]``,
  the parameters and numbers, depending on the positions of both particles and on no momentum;
* factors free of the fields in front of a sum, and constants.

Refused with a message saying what is valid: triple sums, a pair sum over all j (it includes
j = i), other ranges, a field outside a Sum or at another index, momenta in a pair term,
positions and momenta coupled in a one-body term, a kinetic energy that is not quadratic in
the momenta, products of sums.

References
----------
.. [1] R. A. LaBudde, D. Greenspan, "Discrete mechanics -- a general treatment", J. Comput.
   Phys. 15 (1974) 134-167 (the pair-wise energy-momentum scheme).
.. [2] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed., Springer
   (2006), I.2 and VIII (N-body problems, their invariants).
"""

from __future__ import annotations

import ast
import keyword
from dataclasses import dataclass
from typing import Mapping, Sequence

import sympy as sp

from ..errors import InputError, ParseError
from .lattice import _build_scalar
from .parse import MAX_TEXT, RESERVED, SUM, _Builder, _check_double_range, _NAME_RE, check_smooth

__all__ = ["Particles", "particle_symbol", "MIN_BODIES"]

#: the smallest size a particle family admits: two bodies make one pair
MIN_BODIES = 2
#: the slot tags of the particle ``i`` (a) and of its partner ``j`` (b) in a pair template
ROLES = ("a", "b")
_PAIR_EXAMPLE = "Sum(Sum(G*m[i]*m[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)"


def particle_symbol(name: str, role: str) -> sp.Symbol:
    """The slot symbol of the field or array ``name`` at the particle ``role`` (``"a"``: the
    index i; ``"b"``: the partner j of a pair): ``x_a``, ``px_a``, ``m_b``."""
    return sp.Symbol(f"{name}_{role}", real=True)


class _ParticleBuilder(_Builder):
    """:class:`methodgen.problem.parse._Builder` with sums over the symbolic size kept as one-body
    and pair templates (``self.sums``: placeholder, template, kind "one" or "pair", source)."""

    def __init__(self, symbols, qf, pf, arrays, size: str, what: str):
        super().__init__(symbols, what)
        self.qf, self.pf, self.arrays, self.size = tuple(qf), tuple(pf), tuple(arrays), size
        self.roles: dict[str, str] = {}        # enclosing Sum indices -> their role (a, b)
        self.pair_body = False                 # building the inner Sum of a pair term
        self.sums: list[tuple[sp.Symbol, sp.Expr, str, str]] = []

    def subscript(self, node: ast.Subscript) -> sp.Expr:
        names = self.qf + self.pf + self.arrays
        where = f"subscripting {ast.unparse(node)}"
        if not isinstance(node.value, ast.Name) or node.value.id not in names:
            raise self.fail(node, f"{where} is not allowed: the subscripted names are the fields and arrays "
                                  f"{', '.join(names)}")
        if not self.roles:
            raise self.fail(node, f"{where} outside a Sum: every term in the particles is a one-body sum "
                                  f"Sum(…, i, 1, {self.size}) or a pair sum {_PAIR_EXAMPLE}")
        idx = node.slice
        if not (isinstance(idx, ast.Name) and idx.id in self.roles):
            raise self.fail(node, f"{where}: a particle is named by the index of its Sum alone "
                                  f"({' or '.join(self.roles)}), e.g. {node.value.id}[{next(iter(self.roles))}]")
        name = node.value.id
        if name in self.pf and len(self.roles) == 2:
            raise self.fail(node, f"{where}: a momentum in a pair term; a pair term is a potential "
                                  "V(q_i, q_j) of the positions (and arrays) of the two particles")
        return particle_symbol(name, self.roles[idx.id])

    def name(self, node: ast.Name) -> sp.Expr:
        if node.id == self.size:
            raise self.fail(node, f"the size {self.size!r} may appear only as a Sum bound")
        if node.id in self.roles:
            raise self.fail(node, f"the Sum index {node.id!r} may appear only in subscripts")
        if node.id in self.qf + self.pf + self.arrays:
            raise self.fail(node, f"{node.id!r} is a field or an array: subscript it with the Sum's index, "
                                  f"{node.id}[i]")
        return super().name(node)

    def _is(self, node, form: str, index: str | None = None) -> bool:
        """``node`` is the bound ``form``: "1", "N", "i + 1" or "i - 1" (i: ``index``)."""
        if form == "1":
            return isinstance(node, ast.Constant) and type(node.value) is int and node.value == 1
        if form == "N":
            return isinstance(node, ast.Name) and node.id == self.size
        op = ast.Add if form == "i + 1" else ast.Sub
        return (isinstance(node, ast.BinOp) and isinstance(node.op, op) and isinstance(node.left, ast.Name)
                and node.left.id == index and isinstance(node.right, ast.Constant)
                and type(node.right.value) is int and node.right.value == 1)

    def indexed_sum(self, node: ast.Call, depth: int) -> sp.Expr:
        N = self.size
        usage = (f"a one-body term is Sum(body, i, 1, {N}); a pair term Sum(Sum(body, j, i + 1, {N}), i, 1, {N}) "
                 f"(or j from 1 to i - 1: the same pairs)")
        if node.keywords or len(node.args) != 4 or any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, f"Sum(body, i, lo, hi) takes the summand, an index name and its bounds; {usage}")
        body, var, lo, hi = node.args
        if not isinstance(var, ast.Name):
            raise self.fail(var, "Sum(body, i, lo, hi): the second argument must be a name")
        name = var.id
        if (not _NAME_RE.fullmatch(name) or name in RESERVED or keyword.iskeyword(name) or name in self.symbols
                or name in self.qf + self.pf + self.arrays or name == N or name in self.roles):
            raise self.fail(var, f"Sum index {name!r} is not a free name (a field, an array, the size, a parameter, "
                                 "an enclosing Sum's index or a word of the grammar): choose another, e.g. i or j")
        if len(self.roles) == 2:
            raise self.fail(node, f"three nested Sums: only one-body and pair terms are supported; {usage}")
        if not self.roles:          # the outer Sum: over every particle
            if not (self._is(lo, "1") and self._is(hi, "N")):
                raise self.fail(node, f"Sum over {name} from {ast.unparse(lo)} to {ast.unparse(hi)}: the outer "
                                      f"Sum runs over every particle, {name} = 1 … {N}; {usage}")
            pair = isinstance(body, ast.Call) and isinstance(body.func, ast.Name) and body.func.id == SUM
            self.roles[name] = "a"
            self.inner_ok = pair
            try:
                template = self.build(body, depth + 1)
            finally:
                del self.roles[name]
            placeholder = sp.Symbol(f"_sum{len(self.sums)}", real=True)
            self.sums.append((placeholder, template, "pair" if pair else "one", ast.unparse(node)))
            return placeholder
        # the inner Sum of a pair term: it must be the outer Sum's whole summand
        outer = next(iter(self.roles))
        if self.pair_body:
            raise self.fail(node, f"three nested Sums: only one-body and pair terms are supported; {usage}")
        if not getattr(self, "inner_ok", False):
            raise self.fail(node, f"a Sum inside the Sum over {outer} must be its whole summand: {usage}")
        self.inner_ok = False
        upper = self._is(lo, "i + 1", outer) and self._is(hi, "N")
        lower = self._is(lo, "1") and self._is(hi, "i - 1", outer)
        if self._is(lo, "1") and self._is(hi, "N"):
            raise self.fail(node, f"Sum over {name} = 1 … {N} inside the Sum over {outer} includes {name} = {outer} "
                                  f"(a particle with itself); sum each pair once, Sum(Sum(body, {name}, {outer} + 1, "
                                  f"{N}), {outer}, 1, {N}) (a symmetric sum over {name} ≠ {outer} is twice that)")
        if not (upper or lower):
            raise self.fail(node, f"Sum over {name} from {ast.unparse(lo)} to {ast.unparse(hi)} inside the Sum over "
                                  f"{outer}: a pair term sums {name} = {outer} + 1 … {N} (or {name} = 1 … {outer} - 1), "
                                  "each pair once; other ranges are not supported")
        self.roles[name] = "b"
        self.pair_body = True
        try:
            template = self.build(body, depth + 1)
        finally:
            del self.roles[name]
            self.pair_body = False
        if lower:     # Σ_i Σ_{j<i} V(q_i, q_j) = Σ_{a<b} V(q_b, q_a): the roles swapped
            swap = {}
            for nm in self.qf + self.arrays:
                a, b = particle_symbol(nm, "a"), particle_symbol(nm, "b")
                swap[a], swap[b] = b, a
            template = template.xreplace(swap)
        return template


@dataclass(frozen=True)
class _Parts:
    kinetic: sp.Expr
    external: sp.Expr
    pair: sp.Expr
    constant: sp.Expr


class Particles:
    """A family of particle systems of symbolic size N (module docstring).

    Parameters
    ----------
    H : str
        The Hamiltonian as text: one-body sums ``Sum(…, i, 1, N)`` and pair sums
        ``Sum(Sum(…, j, i + 1, N), i, 1, N)`` (times factors free of the fields), constants.
    q, p : sequence of str
        The position fields (1 to 3, e.g. ``["x", "y"]``) and their momenta, in the same order.
    size : str
        The name of the size (default ``"N"``).
    arrays : sequence of str
        Per-particle parameters given at run time as arrays of length N (e.g. ``["m"]``).
    params : mapping of str to float
        Scalar parameters and their default values.
    name : str

    Attributes
    ----------
    kinetic : sympy.Expr
        T(p_a; m_a, params), a homogeneous quadratic form in the momenta slots.
    external : sympy.Expr
        W(q_a; m_a, params), the external potential of one particle (0 if none).
    pair : sympy.Expr
        V(q_a, q_b; m_a, m_b, params), the pair potential (0 if none).
    q_slots, p_slots : tuple of tuple of sympy.Symbol
        ``(x_a, y_a), (x_b, y_b)`` and ``(px_a, py_a),``: the slot symbols per role.
    array_slots : tuple of tuple of sympy.Symbol
        ``(m_a, …), (m_b, …)``.
    dim : int
        The number of position fields.

    Examples
    --------
    >>> fam = Particles("Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N) - Sum(Sum(G*m[i]*m[j]/"
    ...                 "sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)",
    ...                 q=["x", "y"], p=["px", "py"], arrays=["m"], params={"G": 1.0})
    >>> fam.dim, fam.pair.free_symbols >= {fam.q_slots[0][0], fam.q_slots[1][0]}
    (2, True)
    """

    def __init__(self, H: str, q: Sequence[str] = ("x", "y", "z"), p: Sequence[str] = ("px", "py", "pz"), *,
                 size: str = "N", arrays: Sequence[str] = ("m",), params: Mapping[str, float] | None = None,
                 name: str = "particles"):
        if not isinstance(H, str):
            raise InputError(f"the particles' Hamiltonian must be text, got {type(H).__name__}")
        if len(H) > MAX_TEXT:
            raise ParseError(f"Hamiltonian is longer than {MAX_TEXT} characters")
        for label, v in (("q", q), ("p", p), ("arrays", arrays)):
            if isinstance(v, str) or not isinstance(v, (list, tuple)):
                raise InputError(f"{label}= is a list of names, e.g. q=['x', 'y'], got {v!r}")
        q, p, arrays = tuple(q), tuple(p), tuple(arrays)
        if not 1 <= len(q) <= 3 or len(p) != len(q):
            raise InputError(f"particles move in 1 to 3 dimensions: q= names 1 to 3 position fields and p= as many "
                             f"momenta, got q={list(q)}, p={list(p)}")
        params = dict(params or {})
        if not isinstance(size, str):
            raise InputError(f"size is a name, e.g. 'N', got {size!r}")
        names = (*q, *p, *arrays, size, *params)
        for nm in names:
            if not isinstance(nm, str) or not _NAME_RE.fullmatch(nm) or nm in RESERVED or keyword.iskeyword(nm):
                raise InputError(f"{nm!r} is not a valid name (a letter, then letters, digits, _)")
        if len(set(names)) != len(names):
            raise InputError("the names of the position and momentum fields, the arrays, the size and the "
                             "parameters must differ")
        prefixes = tuple(f"{f}_" for f in (*q, *p, *arrays))
        clash = [k for k in params if k.startswith(prefixes)]
        if clash:
            raise InputError(f"parameter names may not start with a field's or array's name and '_' (the slot "
                             f"symbols' names): {', '.join(clash)}")
        for k, v in params.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise InputError(f"parameter {k!r} must be a real number, got {v!r}")
        self.name, self.text = name, H
        self.q_names, self.p_names, self.array_names = q, p, arrays
        self.size = sp.Symbol(size, integer=True, positive=True)
        self.params = {k: float(v) for k, v in params.items()}
        self.param_symbols = tuple(sp.Symbol(k, real=True) for k in params)
        self.dim = len(q)
        self.q_slots = tuple(tuple(particle_symbol(f, r) for f in q) for r in ROLES)
        self.p_slots = (tuple(particle_symbol(f, "a") for f in p),)
        self.array_slots = tuple(tuple(particle_symbol(f, r) for f in arrays) for r in ROLES)
        parts = self._parse(H, "Hamiltonian")
        self.kinetic, self.external, self.pair, self.constant = (parts.kinetic, parts.external, parts.pair,
                                                                 parts.constant)
        self.nmin = MIN_BODIES

    def _parse(self, text: str, what: str) -> _Parts:
        b = _ParticleBuilder({s.name: s for s in self.param_symbols}, self.q_names, self.p_names, self.array_names,
                             self.size.name, what)
        top = _build_scalar(b, text, what)
        placeholders = [ph for ph, *_ in b.sums]
        one, pair = sp.S.Zero, sp.S.Zero
        for ph, template, kind, src in b.sums:
            coeff = sp.diff(top, ph)
            if coeff.free_symbols & set(placeholders):
                raise ParseError(f"{what}: {src} enters non-linearly (times another sum); H must be a sum of "
                                 "one-body and pair terms")
            if kind == "one":
                one += coeff * template
            else:
                pair += coeff * template
        rest = sp.sympify(top.xreplace({ph: sp.S.Zero for ph in placeholders}))
        qa, qb = self.q_slots
        pa = self.p_slots[0]
        for part, label in ((one, "one-body"), (pair, "pair"), (rest, "constant")):
            check_smooth(part, what)
            _check_double_range(part, what)
            if part.has(sp.I, sp.zoo, sp.oo, -sp.oo, sp.nan):
                raise ParseError(f"{what}: the {label} term {part} is not a finite real expression")
        if pair != 0:
            if not pair.free_symbols & set(qa) or not pair.free_symbols & set(qb):
                raise ParseError(f"{what}: the pair term {pair} does not depend on the positions of both particles "
                                 f"i and j; a pair term is an interaction V(q_i, q_j), e.g. {_PAIR_EXAMPLE}")
        one = sp.expand(one) if one.is_polynomial(*pa) else one
        external, kinetic = one.as_independent(*pa, as_Add=True)
        if kinetic == 0:
            raise ParseError(f"{what} has no kinetic term: write Sum((px[i]**2 + …)/(2*m[i]), i, 1, N)")
        if kinetic.free_symbols & set(qa):
            raise ParseError(f"{what}: the one-body term couples positions and momenta ({kinetic}); the kinetic "
                             "energy must depend on the momenta (and the arrays, the parameters) only, the "
                             "positions entering through an external potential W(q_i) apart")
        try:
            poly = sp.Poly(kinetic, *pa)
            quad = (all(sum(mon) == 2 for mon in poly.monoms())
                    and not (poly.free_symbols_in_domain & set(pa)))
        except sp.PolynomialError:
            quad = False
        if not quad:
            raise ParseError(f"{what}: the kinetic energy {kinetic} is not a quadratic form in the momenta "
                             f"{', '.join(self.p_names)} (e.g. (px[i]**2 + py[i]**2)/(2*m[i])); other kinetic "
                             "energies are not supported")
        if pair == 0 and external.free_symbols.isdisjoint(qa):
            raise ParseError(f"{what} has no potential in the positions")
        return _Parts(sp.factor_terms(kinetic), external, pair, rest)

    # --- what the derivations, modules and tests use --------------------------------------------

    @property
    def fields(self) -> tuple[str, ...]:
        return (*self.q_names, *self.p_names)

    def check_size(self, n) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or n < self.nmin:
            raise InputError(f"the particles {self.name!r} need N ≥ {self.nmin} bodies, got {n!r}")

    def expand(self, n: int):
        """H at size ``n`` written out: ``(H, q, p, arrays)`` with q, p the symbol lists in the
        state's order (particle-major: ``x1, y1, x2, y2, …``) and ``arrays`` ``{name: [m1, …]}``
        (for tests and checks at small n; the size of the result grows as n²)."""
        self.check_size(n)
        qs = [[sp.Symbol(f"{f}{k}", real=True) for f in self.q_names] for k in range(1, n + 1)]
        ps = [[sp.Symbol(f"{f}{k}", real=True) for f in self.p_names] for k in range(1, n + 1)]
        ar = {a: [sp.Symbol(f"{a}{k}", real=True) for k in range(1, n + 1)] for a in self.array_names}

        def at(role, k):
            sub = dict(zip(self.q_slots[ROLES.index(role)], qs[k]))
            sub.update({particle_symbol(a, role): ar[a][k] for a in self.array_names})
            if role == "a":
                sub.update(dict(zip(self.p_slots[0], ps[k])))
            return sub

        one = self.kinetic + self.external
        terms = [one.xreplace(at("a", k)) for k in range(n)]
        terms += [self.pair.xreplace({**at("a", a), **at("b", b)}) for a in range(n) for b in range(a + 1, n)]
        return sp.Add(*terms, self.constant), [s for row in qs for s in row], [s for row in ps for s in row], ar
