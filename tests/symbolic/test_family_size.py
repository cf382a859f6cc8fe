"""Size-independent derivation (issue 25.5): indexed sums in H text, and the per-family
analyses of the discrete gradient's invariants.

* ``Sum(body, i, lo, hi)`` with ``q[e]`` subscripts parses to the same H as the expanded
  text, and a module built from it steps the same (round-off).  Bad index syntax is one line.
* The kept linear invariants (``cᵀJ∇̄H ≡ 0``) and the kept angular momenta
  (``{L, F_t} = 0`` per term form) are shown once per family and pattern; on the user
  problems and N-body systems they agree with the per-instance (whole-sum) tests.  Negative
  controls: a term that breaks the symmetry makes the per-family test answer "not shown", and
  checking only the first family (the pattern loop broken) would wrongly claim it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.app.bench import nbody_system
from methodgen.errors import ParseError
from methodgen.symbolic.schemes import base, energy_momentum as em
from methodgen.symbolic import derive

USER = Path(__file__).parents[1] / "user_problems"


def _ring(n: int, text: str) -> mg.Hamiltonian:
    return mg.Hamiltonian(text, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                          name=f"ring{n}")


def _toda_expanded(n: int) -> str:
    return (" + ".join(f"p{i}**2/2" for i in range(1, n + 1)) + " + "
            + " + ".join(f"exp(q{i} - q{i % n + 1})" for i in range(1, n + 1)))


TODA_SUM = "Sum(p[i]**2/2, i, 1, {n}) + Sum(exp(q[i] - q[i % {n} + 1]), i, 1, {n})"


def test_indexed_sum_is_the_expanded_hamiltonian():
    """Exact: the Sum form of a periodic Toda ring is, term by term, the written-out H."""
    n = 7
    a, b = _ring(n, TODA_SUM.format(n=n)), _ring(n, _toda_expanded(n))
    assert a.H == b.H
    assert sp.expand(a.H - b.H) == 0


def test_nested_sums_over_pairs():
    syms = {f"x{i}": sp.Symbol(f"x{i}", real=True) for i in range(1, 5)}
    from methodgen.problem.parse import parse_expr
    e = parse_expr("Sum(Sum(1/(x[i] - x[j])**2, j, i + 1, 4), i, 1, 3)", syms)
    x = [syms[f"x{i}"] for i in range(1, 5)]
    assert e == sp.Add(*[1 / (x[i] - x[j]) ** 2 for i in range(4) for j in range(i + 1, 4)])
    # an index may enter the summand as a number
    assert parse_expr("Sum(i*x[i]**2, i, 1, 3)", syms) == x[0] ** 2 + 2 * x[1] ** 2 + 3 * x[2] ** 2


def test_sum_module_steps_as_the_expanded_one(tmp_path):
    """Numerical (round-off): the energy-momentum modules of both forms give the same
    trajectory of a Toda ring of 6 (a family of 5 + the wrap term: the module loops)."""
    n = 6
    y0 = np.concatenate([0.3 * np.sin(np.arange(n)), 0.2 * np.cos(np.arange(n))])
    trajs = []
    for k, text in enumerate((TODA_SUM.format(n=n), _toda_expanded(n))):
        scheme = mg.discretize(_ring(n, text), "energy-momentum")
        assert scheme.loops is not None and scheme.loops.looped
        mod = mg.generate(scheme, tmp_path / f"toda{k}.py")
        trajs.append(mod.integrate(y0, h=0.05, steps=50))
    assert np.max(np.abs(trajs[0] - trajs[1])) <= 1e-13
    assert scheme.traits.preserved == ("H", "P")


def test_scene_file_takes_an_indexed_sum(tmp_path):
    n = 8
    q = ", ".join(f'"q{i}"' for i in range(1, n + 1))
    p = ", ".join(f'"p{i}"' for i in range(1, n + 1))
    path = tmp_path / "fpu.toml"
    path.write_text(f'''name = "fpu_sum"
[system]
H = "Sum(p[i]**2/2, i, 1, {n}) + q[1]**2/2 + beta*q[1]**4/4 + Sum((q[i+1] - q[i])**2/2 + beta*(q[i+1] - q[i])**4/4, i, 1, {n - 1}) + q[{n}]**2/2 + beta*q[{n}]**4/4"
q = [{q}]
p = [{p}]
[params]
beta = 1.0
[run]
method = "energy-momentum"
h = 0.05
steps = 10
y0 = {[0.1 * i for i in range(2 * n)]}
''')
    scene = mg.load_scene(path)
    ref = mg.load_scene(USER / "fpu8.toml")
    assert sp.expand(scene.system.H - ref.system.H) == 0


@pytest.mark.parametrize("text, fragment", [
    ("Sum(exp(q[i] - q[i+1]), i, 1, 5)", "gives 'q6', which is not a declared symbol (declared are q1 … q5)"),
    ("q[0]", "gives 'q0', which is not a declared symbol"),
    ("q[i]", "'i' is not the index of an enclosing Sum"),
    ("Sum(q[i], i, 1)", "Sum(body, i, lo, hi) takes"),
    ("Sum(q[i], q1, 1, 2)", "is a declared symbol; choose another index name"),
    ("Sum(Sum(q[i], i, 1, 2), i, 1, 2)", "already the index of an enclosing Sum"),
    ("Sum(q[i], i, 3, 1)", "is empty"),
    ("q[1.5]", "is not an index expression"),
    ("q[1:3]", "write name[index]"),
    ("Sum(q[i], i, 1, q1)", "is a declared symbol, not an index"),
    ("q[1 // 0]", "integer division by zero"),
    ("Sum(Sum(q[1], j, 1, 1000), i, 1, 1000)", "expand to more than"),
])
def test_bad_index_syntax_is_one_line(text, fragment):
    syms = {f"q{i}": sp.Symbol(f"q{i}", real=True) for i in range(1, 6)}
    from methodgen.problem.parse import parse_expr
    with pytest.raises(ParseError) as err:
        parse_expr(text, syms)
    msg = str(err.value)
    assert fragment in msg and "\n" not in msg


def test_long_summand_times_many_terms_is_refused_before_expanding():
    """The term bound alone does not bound the work: 40 000 terms of a 20-sine summand (a
    380-character text) built ~10⁷ nodes (11 s; a 20 kB summand, half an hour).  It is refused, one line, before expanding; the
    same text with the node bound raised parses (control: the refusal is the bound's); a
    nested sum whose inner ranges grow with the outer index is bounded as well."""
    from methodgen.problem import parse
    syms = {f"q{i}": sp.Symbol(f"q{i}", real=True) for i in range(1, 11)}
    body = " + ".join(f"sin(q[i % 10 + 1]*{j})" for j in range(1, 21))
    with pytest.raises(ParseError) as err:
        parse.parse_expr(f"Sum({body}, i, 1, 40000)", syms)
    assert "syntax nodes" in str(err.value) and "\n" not in str(err.value)
    small = f"Sum({body}, i, 1, 40)"
    nested = f"Sum(Sum({body}, j, 1, i), i, 1, 12)"
    old = parse.MAX_SUM_NODES
    try:
        parse.MAX_SUM_NODES = 5_000
        for text in (small, nested):
            with pytest.raises(ParseError, match="syntax nodes"):
                parse.parse_expr(text, syms)
        parse.MAX_SUM_NODES = 10**9
        assert len(parse.parse_expr(small, syms).args) == 200
        assert sp.expand(parse.parse_expr(nested, syms) - parse.parse_expr(f"Sum(i*({body}), i, 1, 12)", syms)) == 0
    finally:
        parse.MAX_SUM_NODES = old


# --- per-family analyses against the per-instance ones ---------------------------------------------

def _systems():
    out = [mg.load_scene(USER / f"{n}.toml").system for n in ("toda3", "fpu8", "chain3", "calogero")]
    out += [nbody_system(3), _ring(12, TODA_SUM.format(n=12))]
    return out


def _em_scheme(system):
    if em.applies(system) is not None:
        pytest.skip(f"energy-momentum does not apply to {system.name}")
    return mg.discretize(system, "energy-momentum")


@pytest.mark.parametrize("system", _systems(), ids=lambda s: s.name)
def test_per_family_invariants_agree_with_per_instance(system):
    """Exact both ways: the same kept linear invariants and angular momenta whether shown per
    family and pattern or on every instance / the whole sum."""
    scheme = _em_scheme(system)
    fams = scheme.loops.families if scheme.loops is not None else None
    exclude = ("H",)
    whole = base.dg_linear_invariants(system, scheme.discrete_gradient, exclude=exclude)
    if fams:
        per_family = base.dg_linear_invariants(system, scheme.discrete_gradient, exclude=exclude, loops=fams)
        assert per_family == whole
    terms = em.decompose(system)
    assert (tuple(i.name for i in em.kept_angular_momenta(system, terms))
            == tuple(i.name for i in em.kept_angular_momenta(system, terms, by_families=False)))


def test_planar_gravity_keeps_L_and_P_per_family():
    system = mg.Hamiltonian(
        " + ".join(f"(px{b}**2 + py{b}**2)/2" for b in range(4)) + " - "
        + " - ".join(f"1/sqrt((x{a} - x{b})**2 + (y{a} - y{b})**2)" for a in range(4) for b in range(a + 1, 4)),
        q=[v for b in range(4) for v in (f"x{b}", f"y{b}")],
        p=[v for b in range(4) for v in (f"px{b}", f"py{b}")], name="planar4")
    scheme = mg.discretize(system, "energy-momentum")
    assert {"L", "P_x", "P_y"} <= set(scheme.traits.preserved)
    terms = em.decompose(system)
    fams = em.decompose_families(system)
    w = [sp.diff(next(i.expr for i in derive.first_integrals(system) if i.name == "L"), pk) for pk in system.p]
    assert em._forms_commute_by_families(w, list(system.q), fams) is True
    assert [i.name for i in em.kept_angular_momenta(system, terms, by_families=False)] == ["L"]


def test_negative_control_symmetry_breaking_family():
    """One pinned particle (q1⁴, a family of one instance) breaks translation invariance:
    P = Σ p_i is not kept.  The per-family test says so (the pin's pattern is nonzero), and a
    broken test that looked only at the families of several instances (the chain springs,
    translation invariant) would claim P."""
    n = 6
    system = _ring(n, "Sum(p[i]**2/2, i, 1, 6) + Sum((q[i+1] - q[i])**2, i, 1, 5) + q[1]**4")
    scheme = mg.discretize(system, "energy-momentum")
    fams = scheme.loops.families
    c = [sp.S.Zero] * n + [sp.S.One] * n
    assert base._dg_linear_by_families(system, c, scheme.discrete_gradient, fams) is False
    # the whole-sum reduction agrees: not kept
    d = system.dim
    e = sp.Add(*[c[i] * scheme.discrete_gradient[d + i] - c[d + i] * scheme.discrete_gradient[i] for i in range(d)])
    assert not base._claim_zero(e, system)
    springs = [lf for lf in fams if lf.family.size == n - 1]
    assert springs and base._dg_linear_by_families(system, c, scheme.discrete_gradient, springs) is True


def _pairs(bodies: int, pair: str) -> mg.Hamiltonian:
    return mg.Hamiltonian(
        " + ".join(f"(px{b}**2 + py{b}**2)/2" for b in range(bodies)) + " - "
        + " - ".join(pair.format(a=a, b=b) for a in range(bodies) for b in range(a + 1, bodies)),
        q=[v for b in range(bodies) for v in (f"x{b}", f"y{b}")],
        p=[v for b in range(bodies) for v in (f"px{b}", f"py{b}")], name="pairs")


def test_negative_control_anisotropic_pair_breaks_L():
    """A pair term of a non-rotation-invariant form (2(x_a - x_b)² + (y_a - y_b)²) keeps no L:
    the per-family test finds a nonzero pattern (False); the isotropic pair (control of the
    control) is shown to keep it."""
    bodies = 3
    results = []
    for pair in ("1/sqrt(2*(x{a} - x{b})**2 + (y{a} - y{b})**2)", "1/sqrt((x{a} - x{b})**2 + (y{a} - y{b})**2)"):
        system = _pairs(bodies, pair)
        L = sp.Add(*[system.q[2 * b] * system.p[2 * b + 1] - system.q[2 * b + 1] * system.p[2 * b]
                     for b in range(bodies)])
        w = [sp.diff(L, pk) for pk in system.p]
        results.append(em._forms_commute_by_families(w, list(system.q), em.decompose_families(system)))
    assert results == [False, True]


# --- degree tests read off plain terms ------------------------------------------------------------

def test_plain_monomials_agree_with_poly():
    """Exact: the degree tests read off a plain sum of monomials give Poly's answers; a form
    whose terms could cancel ((a + b) q - a q - b q) is not plain and goes to Poly."""
    a, b = sp.symbols("a b", real=True)
    system = mg.Hamiltonian("(px**2 + py**2)/2 + x**2*y", q=["x", "y"], p=["px", "py"])
    x, y = system.q
    px, py = system.p
    cases = [x * py - y * px, px + py, 3 * x + a * px, x * px + 2, x ** 2 * px, a * b * x * py - x * py,
             sp.S(5), sp.S.Zero, x * px * py, px ** 2]
    for e in cases:
        assert base._plain_monomials(e, system.y) is not None, e
        for k in (0, 1, 2):
            poly, _ = base._poly(e, system.y)
            expect = poly is None or poly.total_degree() <= k
            assert base._degree_at_most(e, system.y, k) == expect, (e, k)
    assert base._plain_monomials((a + b) * x - a * x - b * x, system.y) is None
    assert base._plain_monomials(sp.exp(x) * px, system.y) is None
    assert base._plain_monomials(px / x, system.y) is None
    # bilinear: qᵀDp only (a constant or a pure p term is not)
    assert base._qp_degrees_within(x * py - y * px, system, lambda dq, dp: dq == 1 and dp == 1, constant=False)
    assert not base._qp_degrees_within(x * py + 1, system, lambda dq, dp: dq == 1 and dp == 1, constant=False)
    assert not base._qp_degrees_within(px + py, system, lambda dq, dp: dq == 1 and dp == 1, constant=False)


def test_mass_inverse_read_off_plain_terms_is_the_hessian():
    """Exact: M⁻¹ = ∂²T/∂p² read off T's plain terms equals SymPy's Hessian, with equal
    exponents of different coefficients added (a p1² + b p1²); a coefficient depending on
    the state refuses (None), as does a non-quadratic T."""
    from methodgen.symbolic.derive import _mass_inverse
    p1, p2, p3, a, b, x = sp.symbols("p1 p2 p3 a b x", real=True)
    p = [p1, p2, p3]
    for T in (p1 ** 2 / 2 + p1 * p2 + 3 * p2 ** 2 + p3 ** 2, a * p1 ** 2 + b * p1 ** 2 + p2 * p3,
              p1 ** 2 / (2 * a) + p2 ** 2 + p3 ** 2):
        assert _mass_inverse(T, p, {x}) == sp.hessian(T, p), T
    assert _mass_inverse(x * p1 ** 2 + p2 ** 2 + p3 ** 2, p, {x}) is None
    assert _mass_inverse(p1 ** 2 + p2 ** 2 + p3 ** 4, p, {x}) is None


def test_poisson_bracket_by_partials_is_the_diff_formula():
    """Exact: {F, H} from one pass over the terms and the cached (per-family) ∇H equals the
    textbook Σ ∂F/∂q ∂H/∂p - ∂F/∂p ∂H/∂q; {L, H} of a Toda ring is not 0 (refuted, control)."""
    from methodgen.symbolic.derive import poisson_bracket
    system = _ring(5, TODA_SUM.format(n=5))
    q, p = system.q, system.p
    for F in (sp.Add(*p), q[0] * p[1] - q[1] * p[0], q[2] ** 2 * p[3] + sp.exp(q[0]) * p[0]):
        ref = sp.Add(*[sp.diff(F, a) * sp.diff(system.H, b) - sp.diff(F, b) * sp.diff(system.H, a)
                       for a, b in zip(q, p)])
        assert sp.expand(poisson_bracket(system, F, system.H) - ref) == 0
    assert sp.expand(poisson_bracket(system, sp.Add(*p), system.H)) == 0
    assert sp.expand(poisson_bracket(system, q[0] * p[1] - q[1] * p[0], system.H)) != 0


def test_radial_profile_numerical_rejection_keeps_radial_potentials():
    from methodgen.symbolic.derive import radial_profile
    kepler = mg.Hamiltonian("(px**2 + py**2 + pz**2)/2 - 1/sqrt(x**2 + y**2 + z**2)",
                            q=["x", "y", "z"], p=["px", "py", "pz"])
    assert radial_profile(kepler) is not None
    aniso = mg.Hamiltonian("(px**2 + py**2 + pz**2)/2 - 1/sqrt(x**2 + 2*y**2 + z**2)",
                           q=["x", "y", "z"], p=["px", "py", "pz"])
    assert radial_profile(aniso) is None
    assert radial_profile(_ring(200, TODA_SUM.format(n=200))) is None


def test_numerical_rejection_is_not_fooled_by_round_off():
    """The screen that rejects before simplify (radial test, {I, H}, skewness of S) calls a
    value nonzero only if it survives doubling the precision.  Identically-zero expressions
    with large terms are not "clearly nonzero" -- negative control: at 30 digits alone their
    value exceeds the 1e-20 the screen used to trust -- while a true 1e-15 on top of them is
    still seen; and a skew S with such entries is accepted (it was refused as "not skew")."""
    from methodgen.symbolic.derive import _clearly_nonzero, sample_points

    x, y, z = sp.symbols("x y z", real=True)
    traps = [sp.expand((x + y + z) ** 30) - (x + y + z) ** 30,
             sp.Add(sp.exp(40 * x) * (1 + y), -sp.exp(40 * x), -y * sp.exp(40 * x), evaluate=False)]
    for e in traps:
        syms = sorted(e.free_symbols, key=lambda v: v.name)
        at30 = [abs(complex(e.xreplace({v: sp.Float(c, 30) for v, c in zip(syms, pt)}).evalf(30)))
                for pt in sample_points(len(syms))]
        assert max(at30) > 1e-20                         # control: the trap is real
        assert not _clearly_nonzero(e)
        assert _clearly_nonzero(e + sp.Rational(1, 10**15))
    big = mg.PoissonSystem("u + v", y=["u", "v"], name="big",
                           S=[["0", "exp(40*u)*(1 + v)"], ["-exp(40*u) - v*exp(40*u)", "0"]])
    assert big.name == "big"
    with pytest.raises(mg.InputError, match="skew"):      # control: a non-skew S is still refused
        mg.PoissonSystem("u + v", y=["u", "v"], S=[["0", "exp(40*u)*(1 + v)"], ["-exp(40*u)", "0"]])


def test_cli_bad_index_is_exit_2_and_one_line(tmp_path, capsys):
    """A scene whose Sum runs past the declared coordinates: exit 2, one line, no traceback;
    the same scene with the periodic wrap runs (control)."""
    from helpers import cli_main
    scene = '''name = "ring3"
[system]
H = "Sum(p[i]**2/2, i, 1, 3) + Sum(exp(q[i] - q[{nxt}]), i, 1, 3)"
q = ["q1", "q2", "q3"]
p = ["p1", "p2", "p3"]
[run]
method = "energy-momentum"
h = 0.05
steps = 10
y0 = [0.0, 0.5, -0.3, 0.8, -0.2, -0.6]
'''
    bad, good = tmp_path / "bad.toml", tmp_path / "good.toml"
    bad.write_text(scene.format(nxt="i+1"))
    good.write_text(scene.format(nxt="i % 3 + 1"))
    code, out, err = cli_main(capsys, "run", bad)
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and "gives 'q4', which is not a declared symbol" in err
    code, out, err = cli_main(capsys, "run", good)
    assert code == 0, err
