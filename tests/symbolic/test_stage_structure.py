"""Issue 25, item 1: the stage systems of Gauss and energy collocation by structure.

The modules derive f = J∇H and its Jacobian f' once and assemble the s-stage residual and
Newton matrix with loops over the stages (:mod:`methodgen.symbolic.stages`).  Checked here: the
structured modules agree with the expanded ones (``expanded=True``, the former route) to
round-off, kernel by kernel and along trajectories; the generated source grows linearly in
s (the expanded one quadratically: negative control); a perturbed table is seen (negative
control of the agreement).  The exact-energy certificates of energy collocation read the
scheme, not the module: tests/test_energy_collocation.py keeps them and their controls.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from conftest import HH_Y0
from methodgen.symbolic.derive import vector_field
from methodgen.codegen.emit import emit_source, load_module, write_module

KEPLER_Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])

#: A planar three-body problem (unit masses, G = 1) near the figure-eight choreography.
THREE_BODY = mg.Hamiltonian(
    "(p1**2 + r1**2 + p2**2 + r2**2 + p3**2 + r3**2)/2"
    " - 1/sqrt((x1 - x2)**2 + (y1 - y2)**2) - 1/sqrt((x1 - x3)**2 + (y1 - y3)**2)"
    " - 1/sqrt((x2 - x3)**2 + (y2 - y3)**2)",
    q=["x1", "y1", "x2", "y2", "x3", "y3"], p=["p1", "r1", "p2", "r2", "p3", "r3"], name="three_body")
_V = (0.466203685, 0.43236573)
THREE_BODY_Y0 = np.array([0.97000436, -0.24308753, -0.97000436, 0.24308753, 0.0, 0.0,
                          _V[0], _V[1], _V[0], _V[1], -2 * _V[0], -2 * _V[1]])

CASES = {
    "kepler": (lambda: mg.load_scene("kepler").system, KEPLER_Y0, 0.05),
    "henon-heiles": (lambda: mg.load_scene("henon-heiles-2d").system, np.asarray(HH_Y0, float), 0.2),
    "three-body": (lambda: THREE_BODY, THREE_BODY_Y0, 0.02),
}


def _module(tmp_path, case, method, stages, expanded, backend="numpy"):
    system = CASES[case][0]()
    scheme = mg.discretize(system, method, stages=stages)
    name = f"{case}_{method}_{stages}_{'expanded' if expanded else 'structured'}_{backend}".replace("-", "_")
    path = tmp_path / f"{name}.py"
    write_module(path, emit_source(scheme, module_name=name, backend=backend, expanded=expanded))
    return load_module(path)


@pytest.fixture(scope="module")
def modules(tmp_path_factory):
    root = tmp_path_factory.mktemp("stages")
    cache = {}

    def get(case, method, stages, expanded, backend="numpy"):
        key = (case, method, stages, expanded, backend)
        if key not in cache:
            cache[key] = _module(root, *key)
        return cache[key]

    return get


def _kernels(mod, case, seed=0):
    """Residual and Newton matrix at a random point near the start (scalar and batch kernels)."""
    _, y0, h = CASES[case]
    rng = np.random.default_rng(seed)
    z = rng.normal(size=mod._N) * 1e-2
    c = np.zeros_like(y0)
    p = list(mod.DEFAULT_PARAMS.values()) if hasattr(mod, "DEFAULT_PARAMS") else []
    r, J = mod._s_resjac(list(z), list(y0), list(c), h, p)
    R, JJ = mod._v_resjac(z[None], y0[None], c[None], h, p)
    return (np.array(r), np.array(J), np.asarray(mod._s_res(list(z), list(y0), list(c), h, p)),
            R[0], JJ[0], mod._v_res(z[None], y0[None], c[None], h, p)[0])


CASE_IDS = [("kepler", "gauss", 2), ("kepler", "gauss", 3), ("kepler", "energy-collocation", 2),
            ("henon-heiles", "gauss", 3), ("henon-heiles", "energy-collocation", 3),
            ("three-body", "gauss", 2), ("three-body", "energy-collocation", 1)]


@pytest.mark.parametrize("case, method, stages", CASE_IDS)
def test_kernels_agree_with_expanded(modules, case, method, stages):
    """Residual and Newton matrix equal the expanded kernels' to round-off (scalar and batch)."""
    a = _kernels(modules(case, method, stages, False), case)
    b = _kernels(modules(case, method, stages, True), case)
    for x, y in zip(a, b):
        scale = max(1.0, np.abs(y).max())
        assert np.abs(x - y).max() <= 1e-14 * scale, (np.abs(x - y).max(), scale)


@pytest.mark.parametrize("case, method, stages", CASE_IDS)
def test_trajectories_agree_with_expanded(modules, case, method, stages):
    _, y0, h = CASES[case]
    a = modules(case, method, stages, False).integrate(y0, h, 100)
    b = modules(case, method, stages, True).integrate(y0, h, 100)
    assert np.isfinite(a).all()
    assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max(), np.abs(a - b).max()


def test_perturbed_table_is_seen(modules):
    """Negative control of the agreement: one Butcher entry off by 1e-10 (the structured
    module's table ``_SQ``, read at call time) shows in the residual far above round-off."""
    mod = modules("kepler", "gauss", 3, False)
    ref = _kernels(modules("kepler", "gauss", 3, True), "kepler")
    saved = mod._SQ
    try:
        mod._SQ = tuple(tuple(q + (1e-10 if (j, k) == (0, 1) else 0.0) for k, q in enumerate(row))
                        for j, row in enumerate(saved))
        bad = _kernels(mod, "kepler")
    finally:
        mod._SQ = saved
    assert np.abs(bad[2] - ref[2]).max() > 1e-13


def _size_growth(sizes) -> float:
    """Quadratic over linear coefficient of the least-squares fit of size against s."""
    s = np.arange(1, len(sizes) + 1)
    c2, c1, _ = np.polyfit(s, np.asarray(sizes, float), 2)
    return c2 / c1


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_source_grows_linearly_in_stages(backend):
    """Gauss s = 1..6 on Kepler: the module grows by about the same amount per stage (measured
    ~1.2-1.7 kB: the guess, the increment and the table's row and column); the expanded stage
    system (negative control, s = 1..4) adds (s·n)² Jacobian entries: quadratic.  The numba
    module too (both its routes: the shared runtime's kernels and the template route's)."""
    system = mg.load_scene("kepler").system
    structured = [len(emit_source(mg.discretize(system, "gauss", stages=s), backend=backend)) for s in range(1, 7)]
    expanded = [len(emit_source(mg.discretize(system, "gauss", stages=s), backend=backend, expanded=True))
                for s in range(1, 5)]
    print("structured", structured, "expanded", expanded)
    assert abs(_size_growth(structured)) < 0.05, structured
    assert _size_growth(expanded) > 0.2, expanded


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_no_expanded_jacobian_is_derived(monkeypatch, backend):
    """The lowering of a stage method never builds the scheme's (s·n)² symbolic Jacobian, and
    the numba module (shared runtime) loops over the stages like the numpy one."""
    from methodgen.symbolic.schemes.base import Scheme

    scheme = mg.discretize(mg.load_scene("kepler").system, "gauss", stages=3)
    touched = []
    real = Scheme.jacobian.func
    monkeypatch.setattr(Scheme, "jacobian", property(lambda self: touched.append(1) or real(self)))
    src = emit_source(scheme, backend=backend)
    assert not touched
    if backend == "numba":
        assert "_nb_fieldjac(" in src and "_rt.run(" in src
    src = emit_source(scheme, backend=backend, expanded=True)      # control: the expanded route does read it
    assert touched
    assert "_nb_fieldjac(" not in src


@pytest.mark.slow
@pytest.mark.parametrize("case, method, stages", [("kepler", "gauss", 2), ("henon-heiles", "energy-collocation", 2),
                                                  ("three-body", "gauss", 2)])
def test_numba_agrees_with_expanded(modules, case, method, stages):
    """The compiled stage loops: numba structured vs numba expanded vs numpy structured."""
    pytest.importorskip("llvmlite")
    _, y0, h = CASES[case]
    a = modules(case, method, stages, False, "numba").integrate(y0, h, 100)
    b = modules(case, method, stages, True, "numba").integrate(y0, h, 100)
    c = modules(case, method, stages, False).integrate(y0, h, 100)
    scale = np.abs(b).max()
    assert np.abs(a - b).max() <= 1e-12 * scale and np.abs(a - c).max() <= 1e-12 * scale


def _program_values(dag, point):
    """The program's outputs at an exact point (rationals; radicals stay exact)."""
    env = dict(point)
    for sym, e in dag.assignments:
        env[sym] = e.xreplace(env)
    return [sp.sympify(e).xreplace(env) for e in dag.field], [sp.sympify(e).xreplace(env) for e in dag.jacobian]


@pytest.mark.parametrize("case", ["kepler", "henon-heiles", "three-body"])
def test_field_derivative_is_exact(case):
    """The chain-rule program gives f and f' exactly at two rational points (the difference
    to SymPy's own Jacobian reduces to 0 there with no floating point; the identity itself is
    test_field_derivative_is_an_identity), and the
    structural nonzeros it emits cover every nonzero of f'.  Negative control: one entry
    of the program negated is seen."""
    from methodgen.symbolic.stages import field_derivative

    system = CASES[case][0]()
    f = vector_field(system)
    y = list(system.y)
    dag = field_derivative(tuple(f), tuple(y))
    J = sp.Matrix(f).jacobian(sp.Matrix(y))
    assert {(a, b) for a in range(len(y)) for b in range(len(y)) if J[a, b] != 0} <= set(dag.pattern)
    pv = {s: sp.Rational(system.param_values[s.name]).limit_denominator(1000) for s in system.params}
    rng = np.random.default_rng(3)
    for _ in range(2):
        point = {v: sp.Rational(int(rng.integers(1, 50)), int(rng.integers(51, 99))) * (1 + i) for i, v in enumerate(y)}
        point.update(pv)
        fv, jv = _program_values(dag, point)
        assert all(sp.simplify(a - b.xreplace(point)) == 0 for a, b in zip(fv, f))
        ref = [J[a, b].xreplace(point) for a, b in dag.pattern]
        assert all(sp.simplify(a - b) == 0 for a, b in zip(jv, ref))
        bad = list(jv)
        bad[-1] = -bad[-1]
        assert not all(sp.simplify(a - b) == 0 for a, b in zip(bad, ref))


PARAM_SYSTEM = mg.Hamiltonian("p1**2/(2*m1) + p2**2/(2*m2) + k*(q2 - q1)**2/2 + a*q1**4*exp(q2/b)",
                              q=["q1", "q2"], p=["p1", "p2"], params={"m1": 1.0, "m2": 3.5, "k": 2.0, "a": 0.3, "b": 2.0},
                              name="spring_params")


@pytest.mark.parametrize("case", ["kepler", "henon-heiles", "three-body", "params"])
def test_field_derivative_is_an_identity(case):
    """Exact as an identity, not only at sample points: the program inlined (each assigned
    symbol replaced by its right-hand side) minus SymPy's Jacobian expands to 0 in the state
    and the parameters, entry by entry, and f' is 0 off the pattern.  Negative control: an
    entry with one parameter or state symbol perturbed does not expand to 0."""
    from methodgen.symbolic.stages import field_derivative

    system = PARAM_SYSTEM if case == "params" else CASES[case][0]()
    f = vector_field(system)
    y = list(system.y)
    dag = field_derivative(tuple(f), tuple(y))
    J = sp.Matrix(f).jacobian(sp.Matrix(y))
    env: dict = {}
    for sym, e in dag.assignments:
        env[sym] = e.xreplace(env)
    fv = [sp.sympify(e).xreplace(env) for e in dag.field]
    jv = [sp.sympify(e).xreplace(env) for e in dag.jacobian]
    assert all(sp.expand(a - b) == 0 for a, b in zip(fv, f))
    assert all(sp.expand(a - J[i, j]) == 0 for a, (i, j) in zip(jv, dag.pattern))
    off = set(dag.pattern)
    assert all(J[i, j] == 0 for i in range(len(y)) for j in range(len(y)) if (i, j) not in off)
    # control: the same test sees a wrong entry (the last one's first symbol doubled)
    a, (i, j) = jv[-1], dag.pattern[-1]
    x = sorted(a.free_symbols, key=lambda v: v.name)[0]
    assert sp.expand(a.xreplace({x: 2 * x}) - J[i, j]) != 0


def test_module_tables_are_the_certified_ones(modules):
    """The loops read exactly the float64 tables that verify certifies (the scheme's
    ``structure['tables']`` for energy collocation, the rounded A for Gauss).  Control: the
    entry-by-entry rounded tables (``consistent=False``) are not the module's."""
    from methodgen.symbolic.schemes.energy_collocation import build
    from methodgen.symbolic.schemes.gauss import coefficients

    system = CASES["henon-heiles"][0]()
    mod = modules("henon-heiles", "energy-collocation", 3, False)
    tab = build(system, 3).structure["tables"]
    assert mod._SQ == tab["quad"] and mod._SP == tab["path"] and mod._SG == tab["inv_b"]
    bad = build(system, 3, consistent=False).structure["tables"]
    assert (mod._SQ, mod._SP) != (bad["quad"], bad["path"])
    g = modules("kepler", "gauss", 3, False)
    assert g._SQ == tuple(tuple(float(a) for a in row) for row in coefficients(3)["A"])
