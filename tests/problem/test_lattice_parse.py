"""Lattices of symbolic size: the parser keeps site terms as templates, exactly, and refuses
what it cannot keep (with messages that say what is valid)."""

from __future__ import annotations

import re

import pytest
import sympy as sp

from methodgen.errors import InputError, ParseError
from methodgen.problem.lattice import Bound, Lattice, slot_symbol

SG = ("Sum(p[i]**2/2, i, 1, N) + Sum((q[i % N + 1] - q[i])**2*N**2/(2*L**2), i, 1, N) "
      "+ Sum(1 - cos(q[i]), i, 1, N)")
FPU = ("Sum(p[i]**2/2, i, 1, N) + Sum((q[i+1] - q[i])**2/2 + beta*(q[i+1] - q[i])**4/4, i, 1, N - 1)"
       " + q[1]**2/2 + q[N]**2/2")


def test_periodic_terms_are_templates_in_slot_symbols():
    lat = Lattice(SG, params={"L": 6.0})
    q0, q1, p0 = slot_symbol("q", 0), slot_symbol("q", 1), slot_symbol("p", 0)
    N, L = lat.size, sp.Symbol("L", real=True)
    assert [t.template for t in lat.terms] == [p0**2 / 2, (q1 - q0)**2 * N**2 / (2 * L**2), 1 - sp.cos(q0)]
    assert all((t.lo, t.hi) == (Bound(False, 1), Bound(True, 0)) for t in lat.terms)
    assert lat.terms[1].slots == (("q", 0), ("q", 1))


@pytest.mark.parametrize("n", [3, 4, 7])
def test_expansion_is_the_sum_written_out(n):
    """The templates summed over their ranges give the sum parsed with the number for N (the
    expanding parser of methodgen.parse): the same expression."""
    from methodgen.problem.parse import parse_expr

    lat = Lattice(FPU, params={"beta": 0.5})
    H, qs, ps = lat.expand(n)
    names = {s.name: s for s in qs + ps}
    names["beta"] = sp.Symbol("beta", real=True)
    text = FPU.replace("N", str(n))
    assert sp.expand(H - parse_expr(text, names)) == 0


def test_boundary_terms_are_single_sites():
    lat = Lattice(FPU, params={"beta": 1.0})
    ends = [(t.lo, t.hi) for t in lat.terms if t.lo == t.hi]
    assert sorted(ends, key=str) == sorted([(Bound(False, 1), Bound(False, 1)), (Bound(True, 0), Bound(True, 0))],
                                           key=str)


@pytest.mark.parametrize("index,offset", [("i % N + 1", 1), ("(i + 0) % N + 1", 1), ("(i - 2) % N + 1", -1),
                                          ("i", 0)])
def test_periodic_index_forms(index, offset):
    lat = Lattice(f"Sum(q[i]*q[{index}] + p[i]**2, i, 1, N)" if offset else "Sum(q[i]**2 + p[i]**2, i, 1, N)")
    offs = {o for f, o in lat.terms[0].slots if f == "q"}
    assert offs == ({0, offset})


@pytest.mark.parametrize("text,message", [
    ("Sum(q[i+1]**2 + p[i]**2, i, 1, N)", "leaves the sites 1 … N"),
    ("Sum(q[i-1]*q[i] + p[i]**2, i, 1, N)", "leaves the sites 1 … N"),
    ("Sum(q[i % N + 2] + p[i]**2, i, 1, N)", "(i + c) % N + 1"),
    ("Sum(q[2*i] + p[i]**2, i, 1, N)", "not a supported index"),
    ("Sum(Sum(q[i]*q[j], j, 1, N), i, 1, N)", "nested Sums"),
    ("Sum(q[i]*q[(i + 4) % N + 1] + p[i]**2, i, 1, N)", "couples sites 5 apart; lattice terms may couple sites "
                                                        "at most 4 apart"),
    ("Sum(q[i]**2, i, 1, N)*Sum(p[i]**2, i, 1, N)", "non-linearly"),
    ("Sum(q[i]**2 + p[i]**2, i, 1, N) + q[0]", "outside the sites"),
    ("Sum(q[i]**2 + x[i]**2, i, 1, N)", "not allowed"),
    ("Sum(q[i]**2 + i, i, 1, N)", "only in subscripts"),
    ("Sum(abs(q[i]) + p[i]**2, i, 1, N)", "Abs"),
    ("__import__('os')", "unknown function"),
    ("Sum(q[i]**2 + p[i]**2, i, 5, 2)", "is empty"),
    ("Sum(q[i]**2 + p[i]**2, i, N, 1)", "is empty"),
    ("Sum(q[i % N]**2 + p[i]**2, i, 1, N)", "not a site 1 … N"),
    ("Sum(1, i, 1, N) + 2", "no term in the fields"),
    ("Sum(p[i]**2, i, 1, N) + q[1]*q[N - 4]", "q[1]*q[N - 4] couples sites 5 apart"),
])
def test_refusals_name_what_is_valid(text, message):
    with pytest.raises(ParseError, match=re.escape(message)):
        Lattice(text)


def test_names_and_sizes_are_checked():
    with pytest.raises(InputError, match="q_"):
        Lattice("Sum(q[i]**2 + p[i]**2, i, 1, N)", params={"q_p1": 1.0})
    with pytest.raises(InputError, match="size"):
        Lattice("Sum(q[i]**2 + p[i]**2, i, 1, N)", params={"N": 4.0})
    lat = Lattice(FPU, params={"beta": 1.0})
    with pytest.raises(InputError, match="N ≥ 3"):
        lat.check_size(2)


def test_minimum_size_follows_the_ranges():
    lat = Lattice("Sum(q[i]**2 + p[i]**2, i, 1, N) + Sum(q[i+1]*q[i], i, 5, N - 1)")
    assert lat.nmin == 6      # the range 5 … N - 1 is empty below N = 6
