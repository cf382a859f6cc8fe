"""2-D periodic lattices: the grammar (two nested Sums, two-index fields, periodic neighbours),
its templates in 2-D slots, the expansion at small sizes, and the refusals, each naming what is
wrong and what is valid."""

from __future__ import annotations

import pytest
import sympy as sp

from methodgen.errors import InputError, ParseError
from methodgen.problem.lattice import Lattice, Lattice2D, slot_symbol2

KG = ("Sum(Sum(p[i, j]**2/2 + (q[i % N + 1, j] - q[i, j])**2*N**2/(2*L**2)"
      " + (q[i, j % M + 1] - q[i, j])**2*M**2/(2*L**2) + q[i, j]**4/4, j, 1, M), i, 1, N)")


def test_two_sizes_make_a_2d_lattice_and_one_keeps_the_1d_one():
    lat = Lattice(KG, size=("N", "M"), params={"L": 1.0})
    assert isinstance(lat, Lattice2D) and [s.name for s in lat.sizes] == ["N", "M"]
    (t,) = lat.terms
    assert t.slots == (("p", (0, 0)), ("q", (0, 0)), ("q", (0, 1)), ("q", (1, 0)))
    q00, q10 = slot_symbol2("q", (0, 0)), slot_symbol2("q", (1, 0))
    assert sp.diff(t.template, q10, 2) == lat.sizes[0] ** 2 / sp.Symbol("L", real=True) ** 2
    assert sp.diff(t.template, q00, 4) == 6
    one = Lattice("Sum(p[i]**2/2 + q[i]**4, i, 1, N)")
    assert type(one) is Lattice and one.size.name == "N"


@pytest.mark.parametrize("index,offset", [
    ("q[i, j]", (0, 0)), ("q[i % N + 1, j]", (1, 0)), ("q[(i - 2) % N + 1, j]", (-1, 0)),
    ("q[i, j % M + 1]", (0, 1)), ("q[i, (j - 2) % M + 1]", (0, -1)), ("q[(i + 0) % N + 1, (j - 2) % M + 1]", (1, -1)),
])
def test_periodic_index_forms(index, offset):
    lat = Lattice(f"Sum(Sum(p[i, j]**2/2 + {index}**2, j, 1, M), i, 1, N)", size=("N", "M"))
    assert ("q", offset) in lat.terms[0].slots


def test_the_sums_may_come_in_either_order_and_separately():
    a = Lattice("Sum(Sum(p[i, j]**2/2 + cos(q[i, j % M + 1]), i, 1, N), j, 1, M)", size=("N", "M"))
    b = Lattice("Sum(Sum(p[i, j]**2/2, j, 1, M), i, 1, N) + 3*Sum(Sum(cos(q[i, j % M + 1]), j, 1, M), i, 1, N)",
                size=("N", "M"))
    assert a.terms[0].slots == (("p", (0, 0)), ("q", (0, 1)))
    assert len(b.terms) == 2 and b.terms[1].template == 3 * sp.cos(slot_symbol2("q", (0, 1)))


@pytest.mark.parametrize("n,m", [(3, 3), (3, 4), (5, 3)])
def test_expansion_is_the_sum_written_out(n, m):
    lat = Lattice("Sum(Sum(p[i, j]**2/2 + q[i, j]*q[i % N + 1, j] + N*q[i, j]*q[i, j % M + 1], j, 1, M), i, 1, N)",
                  size=("N", "M"))
    H, qs, ps = lat.expand(n, m)
    Q = [[sp.Symbol(f"q{a}_{b}", real=True) for b in range(1, m + 1)] for a in range(1, n + 1)]
    P = [[sp.Symbol(f"p{a}_{b}", real=True) for b in range(1, m + 1)] for a in range(1, n + 1)]
    ref = sum(P[a][b] ** 2 / 2 + Q[a][b] * Q[(a + 1) % n][b] + n * Q[a][b] * Q[a][(b + 1) % m]
              for a in range(n) for b in range(m))
    assert sp.expand(H - ref) == 0
    assert qs[1] == Q[0][1]                      # row-major: (1, 2) second
    # negative control: the transposed coupling is another Hamiltonian
    wrong = sum(P[a][b] ** 2 / 2 + Q[a][b] * Q[a][(b + 1) % m] + n * Q[a][b] * Q[(a + 1) % n][b]
                for a in range(n) for b in range(m))
    assert sp.expand(H - wrong) != 0


@pytest.mark.parametrize("text,message", [
    # boundaries: a site near the edge, a partial range, a fixed site
    ("Sum(Sum(p[i, j]**2/2 + (q[i + 1, j] - q[i, j])**2, j, 1, M), i, 1, N)",
     "'i + 1' is a site near the edge, not a periodic neighbour (2-D lattices have no boundaries)"),
    ("Sum(Sum(p[i, j]**2/2 + (q[i, j - 1] - q[i, j])**2, j, 1, M), i, 1, N)", "q[i, (j - 2) % M + 1]"),
    ("Sum(Sum(p[i, j]**2/2, j, 1, M - 1), i, 1, N)", "boundaries and partial ranges are not supported"),
    ("Sum(Sum(p[i, j]**2/2, j, 2, M), i, 1, N)", "every term summed over all sites"),
    ("Sum(Sum(p[i, j]**2/2, j, 1, M), i, 1, N) + q[1, 1]**2", "2-D lattices have no boundary terms at fixed sites"),
    # wider stencils
    ("Sum(Sum(p[i, j]**2/2 + q[(i + 1) % N + 1, j]*q[i, j], j, 1, M), i, 1, N)",
     "couples sites 2 apart along N; 2-D lattice terms may couple nearest neighbours only"),
    ("Sum(Sum(p[i, j]**2/2 + q[i, j % M + 1]*q[i, (j - 2) % M + 1], j, 1, M), i, 1, N)",
     "couples sites 2 apart along M"),
    # the shape of a term
    ("Sum(Sum(p[i]**2/2, j, 1, M), i, 1, N)", "a field of a 2-D lattice takes two indices, p[i, j]"),
    ("Sum(Sum(p[j, i]**2/2, j, 1, M), i, 1, N)", "the first index runs over i = 1 … N"),
    ("Sum(p[i, 1]**2, i, 1, N)", "Sum over i alone: a 2-D site term is Sum(Sum(body, j, 1, M), i, 1, N)"),
    ("Sum(Sum(p[i, j]**2, j, 1, N), i, 1, N)", "two nested Sums over N"),
    ("Sum(Sum(p[i, j]**2/2, j, 1, M), i, 1, N)**2", "enters non-linearly"),
    ("Sum(Sum(p[i, j]**2/2 + i, j, 1, M), i, 1, N)", "may appear only in subscripts"),
])
def test_refusals_name_what_is_wrong_and_what_is_valid(text, message):
    with pytest.raises(ParseError) as exc:
        Lattice(text, size=("N", "M"))
    assert message in str(exc.value)


def test_names_structures_and_sizes_are_checked():
    with pytest.raises(InputError, match="2-D lattices are canonical"):
        Lattice(KG, size=("N", "M"), fields=("u",), skew="(g[i+1] - g[i-1])")
    with pytest.raises(InputError, match="two names"):
        Lattice(KG, size=("N", "M", "K"))
    with pytest.raises(InputError, match="must differ"):
        Lattice(KG, size=("N", "N"))
    lat = Lattice(KG, size=("N", "M"), params={"L": 1.0})
    with pytest.raises(InputError, match="needs M ≥ 3"):
        lat.check_size(4, 2)
    lat.check_size((3, 3))
