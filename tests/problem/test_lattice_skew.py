"""Skew lattices, u' = S ∇H with S a constant periodic stencil: the stencil is parsed by the
whitelist parser and checked exactly to be skew (refused otherwise, naming the coefficient);
the energy and mass claims are certificates per stencil (N never enters), each with a
negative control that is refuted; the KdV lattice's vector field is the intended discretisation."""

from __future__ import annotations

import re

import pytest
import sympy as sp

from methodgen.errors import InputError, ParseError
from methodgen.problem.lattice import Lattice, slot_symbol
from methodgen.symbolic.lattice_scheme import (certificates, discretize_lattice, proved_invariants,
                                               skew_certificates)

KDV = "Sum(L/N*(-u[i]**3 + (u[i % N + 1] - u[i])**2*N**2/(2*L**2)), i, 1, N)"
KDV_S = "(g[i+1] - g[i-1])*N**2/(2*L**2)"


def kdv(**kw):
    return Lattice(KDV, fields=("u",), skew=KDV_S, params={"L": 40.0}, name="kdv", **kw)


def test_the_stencil_is_kept_as_its_coefficients():
    lat = kdv()
    N, L = lat.size, sp.Symbol("L", real=True)
    assert lat.structure == "skew" and lat.fields == ("u",)
    assert lat.stencil == {-1: -N**2 / (2 * L**2), 1: N**2 / (2 * L**2)}
    assert lat.nmin == 5 and lat.half_width == 2          # I - h S ∂∇̄H couples sites 2 apart: N ≥ 2·2 + 1
    # the periodic index form is the same stencil
    other = Lattice(KDV, fields=("u",), skew="(g[i % N + 1] - g[(i - 2) % N + 1])*N**2/(2*L**2)",
                    params={"L": 40.0})
    assert other.stencil == lat.stencil
    # the canonical API is unchanged
    canon = Lattice("Sum(p[i]**2/2 + q[i]**2/2, i, 1, N)")
    assert canon.structure == "canonical" and canon.fields == ("q", "p") and canon.stencil == {}


@pytest.mark.parametrize("skew,message", [
    ("g[i+1] + g[i-1]", "is not skew: c_1 = 1 and c_-1 = 1 (must be opposite)"),
    ("g[i+1] - g[i-1] + g[i]/2", "c_0 = 1/2 (must be 0)"),
    ("g[i+1] - 2*g[i-1]", "c_1 = 1 and c_-1 = -2 (must be opposite)"),
    # a wide stencil: the failing pair named, the others skew
    ("(-g[i+2] + 8*g[i+1] - 8*g[i-1] - g[i-2])/12", "is not skew: c_2 = -1/12 and c_-2 = -1/12 (must be opposite)"),
    ("g[i+4] - g[i-4]", "g[i - 4]: stencils of half-width at most 3 only (g[i - 3] … g[i + 3])"),
    ("g[i+1]*g[i-1]", "not linear in g"),
    ("g[i+1] - g[i-1] + 1", "not linear in g"),
    ("u[i]*(g[i+1] - g[i-1])", "subscripting 'u[i]' is not allowed"),
    ("Sum(g[i], i, 1, N)", "no Sum"),
    ("g[1] - g[N]", "names a fixed site"),
    ("0*g[i+1]", "is zero"),
    ("g[i+1] - g[i-1] + x", "unknown symbol 'x'"),
    ("__import__('os')", "unknown function"),
    ("exp(g[i+1])", "not linear in g"),
])
def test_a_bad_stencil_is_refused_naming_what_is_valid(skew, message):
    with pytest.raises(ParseError, match=re.escape(message)):
        Lattice(KDV, fields=("u",), skew=skew, params={"L": 40.0})


@pytest.mark.parametrize("text,kw,message", [
    (KDV + " + u[1]**2", {}, "is a boundary term at a fixed site; skew lattices are periodic only"),
    ("Sum(u[i]*u[i+1], i, 1, N - 1) + Sum(u[i]**2, i, 1, N)", {}, "is summed over i = 1 … N - 1"),
    (KDV, {"fields": ("u", "v")}, "one field per site"),
    (KDV, {"fields": "u"}, "one field per site"),
    (KDV, {"q": "x"}, "q= and p= name the fields of a canonical lattice"),
    (KDV, {"skew": 3}, "skew must be text"),
])
def test_skew_lattices_are_periodic_with_one_field(text, kw, message):
    kw = {"fields": ("u",), "skew": KDV_S, "params": {"L": 40.0}, **kw}
    with pytest.raises((ParseError, InputError), match=re.escape(message)):
        Lattice(text, **kw)


def test_fields_without_a_structure_and_name_clashes_are_refused():
    with pytest.raises(InputError, match="needs its structure, skew="):
        Lattice(KDV, fields=("u",), params={"L": 40.0})
    with pytest.raises(InputError, match="'g' is the gradient"):
        Lattice(KDV.replace("u[", "g["), fields=("g",), skew=KDV_S, params={"L": 40.0})
    with pytest.raises(InputError, match="may not start with 'u_'"):
        Lattice(KDV, fields=("u",), skew=KDV_S, params={"L": 40.0, "u_p1": 1.0})


def test_any_size_from_the_minimum():
    """Odd sizes too (the Newton matrix is grouped by w sites, the last group taking the rest);
    below 2 w + 1 sites the band's sites would wrap onto each other: refused."""
    lat = kdv()
    for n in (5, 6, 65):
        lat.check_size(n)
    with pytest.raises(InputError, match="N ≥ 5"):
        lat.check_size(4)


def test_the_kdv_vector_field_is_the_intended_discretisation():
    """Exact, at N = 8 with L symbolic: S ∇H = -3 D(u²) - D3 u, D and D3 the centred first and third
    differences over dx = L/N (the conservative form of -6 u u_x - u_xxx, to O(dx²)).  Negative
    control: the same check against -6 u D u - D3 u (another discretisation of the same PDE) fails."""
    lat = kdv()
    n = 8
    H, us, _ = lat.expand(n)
    S = lat.stencil_matrix(n)
    f = S * sp.Matrix([sp.diff(H, u) for u in us])
    dx = sp.Symbol("L", real=True) / n
    at = lambda k: us[k % n]  # noqa: E731
    D = lambda v, i: (v(i + 1) - v(i - 1)) / (2 * dx)  # noqa: E731
    D3 = lambda i: (at(i + 2) - 2 * at(i + 1) + 2 * at(i - 1) - at(i - 2)) / (2 * dx**3)  # noqa: E731
    want = [-3 * D(lambda k: at(k)**2, i) - D3(i) for i in range(n)]
    assert all(sp.cancel(f[i] - want[i]) == 0 for i in range(n))
    other = [-6 * at(i) * D(at, i) - D3(i) for i in range(n)]
    assert all(sp.cancel(f[i] - other[i]) != 0 for i in range(n))


def test_the_skew_certificate_is_proved_and_a_non_skew_stencil_is_refuted():
    """gᵀ S g = 0 for every N, per stencil (the density plus its re-indexed form reduced exactly);
    negative control: a symmetric stencil (bypassing the parser's refusal) is refuted at an exact
    rational point, and then the energy is not claimed."""
    lat = kdv(invariants={"mass": "Sum(u[i], i, 1, N)"})
    scheme = discretize_lattice(lat, "avf")
    certs = certificates(scheme)
    assert [c.status for c in certs] == ["proved"] * len(certs)
    claims = [c.claim.split(":")[0] for c in certs]
    assert claims == ["term lemma", "symmetric", "skew stencil", "the linear invariant mass = Σ_i a·u_i is kept"]
    assert proved_invariants(scheme, certs) == ["H", "mass"]
    N, L = lat.size, sp.Symbol("L", real=True)
    lat.stencil = {-1: N**2 / (2 * L**2), 1: N**2 / (2 * L**2)}          # symmetric: not skew
    bad = skew_certificates(lat, "avf")
    assert [c.status for c in bad] == ["refuted", "refuted"]
    assert set(bad[0].details["counterexample"]) >= {"g_0", "g_p1", "g_m1"}
    assert proved_invariants(scheme, certificates(scheme)) == []


def test_a_wider_skew_stencil_is_proved_by_the_same_reindexing():
    """The certificate is about any stencil Σ_k c_k g_(i+k) (the module takes half-width 1 only):
    a half-width-2 skew stencil is proved, and one with an unpaired c_2 refuted."""
    lat = kdv()
    a, b = sp.Symbol("a", real=True), sp.Symbol("b", real=True)
    lat.stencil = {-2: -b, -1: -a, 1: a, 2: b}
    assert [c.status for c in skew_certificates(lat, "avf")] == ["proved"]
    lat.stencil = {-2: -b, -1: -a, 1: a, 2: 2 * b}
    assert [c.status for c in skew_certificates(lat, "avf")] == ["refuted"]


def test_linear_invariants_only_are_claimed():
    """The mass (linear, constant coefficients) is proved kept by both methods; the L2 norm
    Σ u² is not claimed (nothing is decided for it)."""
    lat = kdv(invariants={"mass": "Sum(L/N*u[i], i, 1, N)", "l2": "Sum(u[i]**2, i, 1, N)"})
    for method in ("avf", "midpoint"):
        scheme = discretize_lattice(lat, method)
        certs = certificates(scheme)
        assert all(c.status == "proved" for c in certs)
        assert proved_invariants(scheme, certs) == (["H", "mass"] if method == "avf" else ["mass"])


def test_expansion_and_the_stencil_matrix():
    lat = kdv()
    S = lat.stencil_matrix(6)
    assert S + S.T == sp.zeros(6, 6) and S[0, 5] == -S[0, 1] and S[0, 1] == sp.Integer(36) / (2 * sp.Symbol("L", real=True)**2)
    H, us, rest = lat.expand(6)
    assert rest == [] and len(us) == 6 and H.has(us[0]) and slot_symbol("u", 0) not in H.free_symbols
