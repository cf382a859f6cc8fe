"""Sums of like terms: families (methodgen.problem.families) and modules that loop over them
(methodgen.codegen.lower_loops) agree with the unrolled modules to round-off."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.app.bench import nbody_initial, nbody_system
from methodgen.symbolic.derive import separable_split
from methodgen.codegen.emit import load_module, render, write_atomic
from methodgen.problem.families import term_families
from methodgen.codegen.lower import LOOP_MIN_INSTANCES, lower, uses_loops

from helpers import fpu_chain


# --- families -----------------------------------------------------------------------------

def test_pair_potential_is_one_family_of_instances():
    s = nbody_system(5)
    sep = separable_split(s)
    fams = term_families(sep.U, s.q, s.params)
    assert len(fams) == 1
    fam = fams[0]
    assert fam.size == 10 and len(fam.slots) == 6 and len(fam.pslots) == 3
    # every instance is its term exactly (a renaming), and the terms are U's
    q, params = list(s.q), list(s.params)
    for k in range(fam.size):
        assert fam.instance(fam.template, k, q, params) == fam.terms[k]
    assert sp.Add(*fam.terms) == sep.U


def test_unlike_terms_stay_apart():
    x, y, z = sp.symbols("x y z", real=True)
    a, b = sp.symbols("a b", real=True)
    U = (x - y)**4 + (y - z)**4 + (x - y)**2 + a * x**2 + b * y**2 + 7
    fams = term_families(U, [x, y, z], [a, b])
    sizes = sorted(f.size for f in fams)
    # the quartics form one family, the quadratic another, the one-coordinate terms a third;
    # the constant has no gradient and is left out
    assert sizes == [1, 2, 2]
    quartic = next(f for f in fams if f.template.has(sp.Integer(4)))
    assert quartic.index == ((0, 1), (1, 2))
    # negative control: a different exponent is a different template
    assert all(f.template != quartic.template for f in fams if f is not quartic)


def test_term_that_is_not_a_renaming_is_its_own_family():
    x, y = sp.symbols("x y", real=True)
    # the same structure with the coordinates in the other order renames to a different
    # template ((u1 - u0)**3): its own family, never merged by accident
    fams = term_families((x - y)**3 + (y - x)**3 * 2, [x, y])
    assert sum(f.size for f in fams) == 2


# --- loop-emitted modules against unrolled ones --------------------------------------------

def _module(scheme, loops, tmp_path, backend="numpy", tag=""):
    ir = lower(scheme, "test", f"m{int(bool(loops))}{tag}", loops=loops)
    assert bool(ir.loop_tables) == bool(loops)
    path = tmp_path / f"loops_{scheme.system.name}_{int(bool(loops))}{tag}_{backend}.py"
    write_atomic(path, render(ir, backend))
    return load_module(path)


@pytest.fixture(scope="module")
def nbody_pairs(tmp_path_factory):
    cache = {}

    def get(n, order=2, method="energy-momentum"):
        if (n, order, method) not in cache:
            scheme = mg.discretize(nbody_system(n), method, order=order)
            root = tmp_path_factory.mktemp(f"loops{n}_{order}_{method}")
            cache[n, order, method] = (scheme, _module(scheme, True, root), _module(scheme, False, root))
        return cache[n, order, method]

    return get


def _state(n, seed=1):
    rng = np.random.default_rng(seed)
    d = 3 * n
    return np.concatenate([nbody_initial(n)[:d] + 0.01 * rng.normal(size=d), 0.3 * rng.normal(size=d)])


@pytest.mark.parametrize("n,method", [(2, "energy-momentum"), (3, "energy-momentum"), (4, "energy-momentum"),
                                      # ten pairs: the loops of n = 3 and 4 (three and six pairs) again
                                      pytest.param(5, "energy-momentum", marks=pytest.mark.slow),
                                      (3, "midpoint"), (4, "midpoint")])
def test_kernels_agree_with_unrolled(nbody_pairs, n, method):
    _, loop, flat = nbody_pairs(n, method=method)
    rng = np.random.default_rng(n)
    d = 3 * n
    p = [0.7] + list(1.0 + 0.1 * np.arange(n))
    for _ in range(3):
        y = _state(n, int(rng.integers(1000)))
        z = 0.01 * rng.normal(size=d)
        c = 1e-17 * rng.normal(size=2 * d)
        for name, args in (("_s_guess", (list(y), 0.01, p)), ("_s_res", (list(z), list(y), list(c), 0.01, p)),
                           ("_s_post", (list(z), list(y), list(c), 0.01, p))):
            a, b = np.array(getattr(loop, name)(*args)), np.array(getattr(flat, name)(*args))
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14 * np.abs(b).max())
        (ra, Ja), (rb, Jb) = loop._s_resjac(list(z), list(y), list(c), 0.01, p), flat._s_resjac(
            list(z), list(y), list(c), 0.01, p)
        np.testing.assert_allclose(ra, rb, rtol=1e-12, atol=1e-16)
        np.testing.assert_allclose(np.array(Ja), np.array(Jb), rtol=1e-12, atol=1e-16)
        # the vector flavour, batch of 4
        Y = np.array([_state(n, s) for s in range(4)])
        Z = 0.01 * rng.normal(size=(4, d))
        C = 1e-17 * rng.normal(size=(4, 2 * d))
        for name in ("_v_res", "_v_increment", "_v_post"):
            a, b = getattr(loop, name)(Z, Y, C, 0.01, p), getattr(flat, name)(Z, Y, C, 0.01, p)
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14 * np.abs(b).max())
        (Ra, Ja), (Rb, Jb) = loop._v_resjac(Z, Y, C, 0.01, p), flat._v_resjac(Z, Y, C, 0.01, p)
        np.testing.assert_allclose(Ra, Rb, rtol=1e-12, atol=1e-16)
        np.testing.assert_allclose(Ja, Jb, rtol=1e-12, atol=1e-16)


@pytest.mark.parametrize("n,order,method", [(3, 2, "energy-momentum"), (4, 2, "energy-momentum"),
                                            (3, 4, "energy-momentum"), (3, 2, "midpoint")])
def test_trajectories_agree_with_unrolled(nbody_pairs, n, order, method):
    _, loop, flat = nbody_pairs(n, order, method)
    y0 = nbody_initial(n)
    for solver in ("newton", "auto"):
        a = loop.integrate(y0, 0.01, 300, check_resolution=False, solver=solver)
        b = flat.integrate(y0, 0.01, 300, check_resolution=False, solver=solver)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_negative_control_wrong_index_table_disagrees(nbody_pairs):
    """The agreement above can fail: a loop over a wrong instance table gives another force."""
    _, loop, flat = nbody_pairs(3)
    y = _state(3)
    args = ([0.001] * 9, list(y), [0.0] * 18, 0.01, [1.0] * 4)
    assert np.allclose(loop._s_res(*args), flat._s_res(*args), rtol=1e-12)
    table = loop._IDX0
    try:
        loop._IDX0 = (table[0], table[0], table[2])     # pair (0, 1) twice, (0, 2) dropped
        assert not np.allclose(loop._s_res(*args), flat._s_res(*args), rtol=1e-6)
    finally:
        loop._IDX0 = table


def test_loops_only_where_a_family_is_large():
    small = mg.discretize(nbody_system(2), "energy-momentum")
    large = mg.discretize(nbody_system(3), "energy-momentum")
    assert LOOP_MIN_INSTANCES == 3
    assert not uses_loops(small) and uses_loops(large)
    assert uses_loops(small, True) and not uses_loops(large, False)
    kepler = mg.discretize(mg.load_scene("kepler").system, "gauss")
    with pytest.raises(ValueError, match="no sums of like terms"):
        uses_loops(kepler, True)


def test_loop_module_is_smaller_and_deterministic(nbody_pairs):
    # The four-body modules of the kernel tests (the scheme, its looped and unrolled lowerings,
    # shared through the fixture: each lowering is ~10 s) against one more lowering of the
    # same scheme with the default choice of loops: the same text.
    scheme, loop, flat = nbody_pairs(4)
    a = Path(loop.__file__).read_text()
    b = render(lower(scheme, "test", "m1"), "numpy")
    assert a == b
    assert "for _i, _pi in zip(_IDX0, _PIDX0):" in a
    assert len(a) < 0.8 * len(Path(flat.__file__).read_text())


def test_nbody8_keeps_energy_and_momenta(tmp_path):
    """N = 8: the claims are made (proved on the scheme), and the looped module keeps H, P
    and L to round-off along a run."""
    scheme = mg.discretize(nbody_system(8), "energy-momentum")
    assert {"H", "P_x", "P_y", "P_z", "L_x", "L_y", "L_z"} <= set(scheme.traits.preserved)
    mod = _module(scheme, True, tmp_path)
    y0 = nbody_initial(8)
    Y = mod.integrate(y0, 0.005, 300, check_resolution=False)
    H = mod.hamiltonian(Y)
    inv = mod.invariants(Y)
    assert np.abs(H - H[0]).max() < 1e-13 * abs(H[0]) + 1e-14
    for name in ("P_x", "P_y", "P_z", "L_x", "L_y", "L_z"):
        assert np.abs(inv[name] - inv[name][0]).max() < 1e-13, name


def test_numba_loops_agree_with_numpy(tmp_path):
    pytest.importorskip("llvmlite")
    scheme = mg.discretize(nbody_system(3), "energy-momentum")
    np_mod = _module(scheme, True, tmp_path)
    nb_mod = _module(scheme, True, tmp_path, backend="numba")
    y0 = nbody_initial(3)
    Y0 = np.array([y0, y0 * 1.01])
    for solver in ("newton", "auto"):
        a = nb_mod.integrate(Y0, 0.01, 200, check_resolution=False, solver=solver)
        b = np_mod.integrate(Y0, 0.01, 200, check_resolution=False, solver=solver)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", ["avf", "midpoint", "energy-momentum"])
def test_chain_loops_agree_with_unrolled(tmp_path, method):
    """A polynomial nearest-neighbour chain (the AVF integral of the template taken once)."""
    n = 6
    scheme = mg.discretize(fpu_chain(n), method)
    assert scheme.loops is not None and scheme.loops.largest == n - 1 and uses_loops(scheme)
    loop, flat = _module(scheme, True, tmp_path), _module(scheme, False, tmp_path)
    rng = np.random.default_rng(3)
    y0 = np.concatenate([0.5 * rng.normal(size=n), rng.normal(size=n)])
    a = loop.integrate(y0, 0.05, 400)
    b = flat.integrate(y0, 0.05, 400)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    if method != "midpoint":    # energy-preserving: H to round-off along the looped run
        H = loop.hamiltonian(a)
        assert np.abs(H - H[0]).max() < 1e-13 * abs(H[0])
    from methodgen.symbolic.verify.loops import loop_certificates
    assert {c.status for c in loop_certificates(scheme)} == {"proved"}


# --- verification: the loops evaluate the scheme's discrete gradient -----------------------

@pytest.mark.parametrize("method", ["energy-momentum", "midpoint"])
def test_loop_certificates_prove_and_can_refute(method):
    import dataclasses

    from methodgen.symbolic.verify.loops import loop_certificates, loop_identities

    scheme = mg.discretize(nbody_system(3), method)
    certs = loop_certificates(scheme)
    assert len(certs) == 2 and {c.status for c in certs} == {"proved"}, [str(c) for c in certs]
    # negative controls on the identities the certificates reduce: a template gradient off
    # by a factor, and an instance table that double-counts one pair, leave them nonzero
    lf = scheme.loops.families[0]
    x = {s: sp.Rational(k + 3, 7) for k, s in enumerate(sorted(
        set(scheme.system.y) | set(scheme.y1) | set(lf.vslots) | set(lf.family.slots) | set(lf.family.pslots)
        | set(scheme.system.params), key=str))}

    def value(e):
        es = e if isinstance(e, list) else [e]
        return max(abs(complex(sp.sympify(v).xreplace(x).evalf(30))) for v in es)

    assert all(value(e) < 1e-25 for _, e in loop_identities(scheme))
    wrong = dataclasses.replace(lf, dg=tuple(2 * g for g in lf.dg))
    bad = dataclasses.replace(scheme, loops=dataclasses.replace(scheme.loops, families=(wrong,)))
    vals = [value(e) for _, e in loop_identities(bad)]
    assert vals[0] < 1e-25 and vals[1] > 1e-6
    fam = lf.family
    doubled = dataclasses.replace(fam, index=(fam.index[0], fam.index[0], fam.index[2]))
    bad = dataclasses.replace(scheme, loops=dataclasses.replace(
        scheme.loops, families=(dataclasses.replace(lf, family=doubled),)))
    vals = [value(e) for _, e in loop_identities(bad)]
    assert vals[0] > 1e-6 and vals[1] > 1e-6


@pytest.mark.slow
def test_verify_reports_the_loop_claims():
    rep = mg.verify(mg.discretize(nbody_system(3), "energy-momentum"), timeout=60)
    loops = [c for c in rep.certificates if "looped" in c.claim or "loops over" in c.claim]
    assert len(loops) == 2 and all(c.status == "proved" for c in loops)
    assert rep.ok and {c.status for c in rep.certificates} == {"proved"}, str(rep)


@pytest.mark.parametrize("system", [nbody_system(4), fpu_chain(7)] + [mg.load_scene(name).system for name in
                                    ("outer-solar-system", "kepler", "henon-heiles", "double-pendulum")],
                         ids=lambda s: s.name)
def test_gradient_by_families_is_the_derivative(system):
    """∇H built from the families' template derivatives is sp.diff's expression, term for term
    (the oracle: differentiating H itself)."""
    from methodgen.symbolic.derive import _gradient_by_families, gradient

    want = [sp.diff(system.H, s) for s in system.y]
    assert list(gradient(system)) == want
    fast = _gradient_by_families(system)
    if system.name in ("nbody4", "fpu7", "outer-solar-system"):
        assert fast is not None
    if fast is not None:
        assert list(fast) == want


def test_brackets_by_families_prove_momenta_and_refuse_what_they_cannot():
    """{P, H} = 0 and {L, H} = 0 of an N-body H shown once per family pattern; an external
    field breaks translation invariance (not shown here, and refuted by the whole bracket)."""
    from methodgen.symbolic.derive import _commutes, _commutes_by_families
    from methodgen.problem.problem import Hamiltonian

    s = nbody_system(4)
    names = {v.name: v for v in s.y}
    Px = sp.Add(*[names[f"px{b}"] for b in range(4)])
    Lz = sp.Add(*[names[f"x{b}"] * names[f"py{b}"] - names[f"y{b}"] * names[f"px{b}"] for b in range(4)])
    assert _commutes_by_families(s, Px) is True and _commutes_by_families(s, Lz) is True
    # negative controls: the momentum of one body is not conserved; an external field
    assert _commutes_by_families(s, names["px0"]) is None and not _commutes(s, names["px0"])
    ext = Hamiltonian(str(s.H) + " + x0**2", q=[v.name for v in s.q], p=[v.name for v in s.p],
                      params=dict(s.param_values), name="nbody4ext")
    names = {v.name: v for v in ext.y}
    Px = sp.Add(*[names[f"px{b}"] for b in range(4)])
    assert _commutes_by_families(ext, Px) is None and not _commutes(ext, Px)


def test_avf_template_of_several_terms_is_integrated_term_by_term():
    """A template k*(cos(u0 - u1) + cos(u2 - u3)) is two of AVF's terms: each is integrated
    exactly (a divided difference), as the scheme integrates them, not by quadrature; the
    loop certificates are then exact proofs (review finding: it was quadrature, numerical)."""
    from methodgen.problem.problem import Hamiltonian
    from methodgen.symbolic.verify.loops import loop_certificates

    q, p = [f"q{i}" for i in range(1, 7)], [f"p{i}" for i in range(1, 7)]
    H = ("+".join(f"{x}**2/2" for x in p)
         + " + k*(cos(q1-q2) + cos(q5-q6)) + cos(q2-q3) + cos(q3-q4) + cos(q4-q5)")
    scheme = mg.discretize(Hamiltonian(H, q=q, p=p, params={"k": 1.0}, name="mix"), "avf")
    assert scheme.traits.energy_preserving and uses_loops(scheme)
    assert not any(g.has(sp.Float) for lf in scheme.loops.families for g in lf.dg)
    assert [c.status for c in loop_certificates(scheme)] == ["proved", "proved"]
