"""Splitting methods made for H = T + U (issue 26, item 2; methodgen/symbolic/splittings.py).

(a) Order conditions in the free associative algebra on {A, B} (60 digits): each family's
    general order is what is claimed (4, 6; 4 for the RKN families), exactly zero defects (< 1e-40) for McLachlan's
    algebraic coefficients, round-off of the 15 published digits for Blanes & Moan.
    Control: a symmetric perturbation of one kick (the sums kept) fails the order-3
    conditions (general order 2).
    The RKN order (T quadratic) is decided modulo the ideal of [B, [B, [B, A]]]: SRKN_11^b
    has RKN order 6 and general order 4 (control: without the ideal, and a perturbed kick).
(b) Measured orders on Hénon–Heiles (error ratio under halving h against DOP853), including
    the RKN order 6 of SRKN_11^b.
    Control: one stage fraction perturbed in the module (the sums kept, symmetry lost)
    drops the measured order to 2.
(c) Stages: stage 0 = (b_1, a_1, b_2), stage k >= 1 = (0, a_{k+1}, b_{k+2}); the fractions
    sum to 1; one ∇U per stage (first-same-as-last), counted.
(d) A run in chunks passing ``info`` is bitwise the run in one piece (numpy, one trajectory
    and a batch; numba); a perturbed ``info["force"]`` changes the bits (control: the
    record is used).
(e) Clear errors: a splitting with another method, an RKN family with a T that is not
    quadratic, ``extended=True``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg
from conftest import HH_T, HH_Y0
from methodgen.errors import InputError, MethodNotApplicable
from methodgen.symbolic.splittings import (SPLITTING_FAMILIES, Splitting, general_order, splitting,
                                  splitting_defects)

CASES = [(f, o) for f, orders in SPLITTING_FAMILIES.items() for o in orders]



# --- (a) order conditions ---------------------------------------------------------------

@pytest.mark.parametrize("family, order", CASES)
def test_general_order_decided(family, order):
    s = splitting(order, family)
    K = 4 if s.rkn else order          # an RKN order is not a general one (see below)
    d = splitting_defects(s, K + 1)
    assert general_order(s) == K, d
    # the first condition that fails is a real one, far above the tolerance
    assert d[K + 1] > 1e-6
    if s.exact:
        assert max(d[w] for w in range(1, K + 1)) < 1e-40


@pytest.mark.parametrize("family, order", CASES)
def test_rkn_flag_is_where_the_general_order_falls_short(family, order):
    # rkn (refused off RKN problems, labelled RKN) exactly where the decided general order is
    # below the claimed one: SRKN_6^b was flagged although its order 4 holds for every splitting
    s = splitting(order, family)
    assert s.rkn == (general_order(s) < s.order), (s.rkn, general_order(s))


def test_srkn6_applies_to_a_non_quadratic_t_with_order_4():
    # T = sqrt(1 + p^2): SRKN_6^b was refused ("order 4 for T quadratic only"), yet it has order
    # 4 for every splitting -- measured: error ratio under halving h ~ 16.  Control: SRKN_11^b
    # (order 6 RKN only) is still refused there
    rel = mg.Hamiltonian("sqrt(1 + p**2) + q**4/4", q=["q"], p=["p"])
    mod = mg.build(rel, "stormer-verlet", order=4, composition="blanes-moan-rkn")
    ref = mg.build(rel, "stormer-verlet", order=10)
    y0, T = np.array([1.0, 0.5]), 4.0
    exact = ref.integrate(y0, T / 400, 400)[-1]
    e1, e2 = (np.max(np.abs(mod.integrate(y0, T / n, n)[-1] - exact)) for n in (20, 40))
    assert 3.7 < math.log2(e1 / e2) < 4.3, (e1, e2)
    with pytest.raises(MethodNotApplicable, match="Runge-Kutta-Nystrom"):
        mg.discretize(rel, "stormer-verlet", order=6, composition="blanes-moan-rkn")


@pytest.mark.parametrize("family, order", CASES)
def test_rkn_order_decided(family, order):
    """Modulo the ideal of [B, [B, [B, A]]] (zero for T quadratic): every family has its order
    for RKN problems, SRKN_11^b 6 although its general order is 4."""
    from methodgen.symbolic.splittings import rkn_defects, rkn_order
    s = splitting(order, family)
    assert rkn_order(s) == order, rkn_defects(s, order + 1)


def test_rkn_ideal_is_what_makes_srkn11_order_6():
    """Control: without the ideal (general conditions) the degree-5 defect of SRKN_11^b is
    1e-5; modulo the ideal it is at the printed digits; a symmetric perturbation of two
    kicks (the sum kept) breaks the RKN conditions at degree 3."""
    from methodgen.symbolic.splittings import rkn_defects, rkn_order
    s = splitting(6, "blanes-moan-rkn")
    assert splitting_defects(s, 5)[5] > 1e-6 and rkn_defects(s, 5)[5] < 1e-15
    b = [float(x) for x in s.kicks]
    b[0] += 1e-6
    b[-1] += 1e-6
    b[5] -= 1e-6
    b[6] -= 1e-6
    bad = Splitting("perturbed", 6, tuple(map(repr, b)), s.drifts, False, "test", rkn=True)
    assert rkn_order(bad) == 2 and rkn_defects(bad, 3)[3] > 1e-8


def test_a_perturbed_kick_fails_the_order_conditions():
    s = splitting(4, "blanes-moan")
    b = [float(x) for x in s.kicks]
    eps = 1e-6   # symmetric (both ends) and the middle kick keeps Σ b = 1
    b[0] += eps
    b[-1] += eps
    b[len(b) // 2] -= 2 * eps
    bad = Splitting("perturbed", 4, tuple(repr(x) for x in b), s.drifts, False, "test")
    d = splitting_defects(bad, 5)
    assert d[1] < 1e-13 and d[3] > 1e-8
    assert general_order(bad) == 2


# --- (b) measured orders ----------------------------------------------------------------

#: (family, order, N): N and 2N steps over HH_T, both above round-off and in the asymptotic range.
MEASURED = [("blanes-moan", 4, 25), ("blanes-moan", 6, 25), ("blanes-moan-rkn", 4, 25),
            ("blanes-moan-rkn", 6, 25), ("mclachlan", 4, 25)]


def _errors(mod, ref, N):
    return [float(np.abs(mod.integrate(HH_Y0, HH_T / n, n, check_resolution=False)[-1] - ref).max())
            for n in (N, 2 * N)]


@pytest.mark.parametrize("family, K, N", MEASURED)
def test_measured_order(hh, hh_reference, family, K, N):
    mod = mg.build(hh, "stormer-verlet", order=K, composition=family)
    errs = _errors(mod, hh_reference, N)
    assert errs[1] > 3e-13, f"error {errs[1]:.1e} at 2N is at round-off: the case measures nothing"
    rate = math.log2(errs[0] / errs[1])
    assert K - 0.5 < rate < K + 0.7, f"measured order {rate:.2f}, claimed {K} ({errs})"


def test_a_perturbed_stage_loses_the_order(hh, hh_reference, monkeypatch):
    mod = mg.build(hh, "stormer-verlet", order=6, composition="blanes-moan-rkn")
    kb = list(mod._KICK_B)
    kb[1] += 1e-3       # one kick moved to another stage: Σ b = 1 kept, symmetry lost
    kb[-2] -= 1e-3
    monkeypatch.setattr(mod, "_KICK_B", tuple(kb))
    errs = _errors(mod, hh_reference, 25)
    assert math.log2(errs[0] / errs[1]) < 2.5, errs


# --- (c) stages -------------------------------------------------------------------------

@pytest.mark.parametrize("family, order", CASES)
def test_stage_fractions(family, order):
    s = splitting(order, family)
    ka, dr, kb = s.stage_fractions()
    b = [float(x) for x in s.kicks]
    assert len(ka) == len(dr) == len(kb) == s.stages == len(b) - 1
    assert ka[0] == b[0] and all(x == 0.0 for x in ka[1:]) and list(kb) == b[1:]
    assert math.isclose(sum(dr), 1.0, abs_tol=1e-14) and math.isclose(sum(ka) + sum(kb), 1.0, abs_tol=1e-14)
    # symmetric: the palindromes b and a
    assert list(dr) == list(dr)[::-1] and b == b[::-1]


@pytest.mark.parametrize("batch", [False, True], ids=["one", "batch"])
def test_one_force_per_stage(monkeypatch, batch):
    """∇U evaluations per step = stages (the pendulum's sin calls; see test_force_count.py)."""
    from test_force_count import _per_step
    scene = mg.load_scene("simple-pendulum")
    mod = mg.build(scene.run_system, "stormer-verlet", order=4, composition="blanes-moan")
    y0 = np.array(scene.y0)
    if batch:
        per = _per_step(mod, np.stack([y0, 0.9 * y0]), 0.05, 8, "numpy", np, monkeypatch)
    else:
        per = _per_step(mod, y0, 0.05, 8, "math", math, monkeypatch)
    assert per["sin"] == len(mod.DRIFT) == 6


# --- (d) chunks ---------------------------------------------------------------------------

def _chunked(mod, y0, h, splits, perturb=False):
    """The run in chunks passing ``info``; ``perturb``: each chunk's force record changed by a
    relative 1e-9 (a record the module accepts, whose use is then visible in the bits).
    (Dropping the record is no control here: the force evaluated afresh at y + c has the
    carried force's bits at most boundaries.)"""
    info = {}
    y, parts = np.asarray(y0, dtype=float), []
    for n in splits:
        part = mod.integrate(y, h, n, info=info)
        parts.append(part if not parts else part[1:])
        y = part[-1]
        if perturb:
            key, yy, comp, p, g = info["force"]
            info["force"] = (key, yy, comp, p, g * (1 + 1e-9))
    return np.concatenate(parts)


@pytest.mark.parametrize("batch", [False, True], ids=["one", "batch"])
def test_chunks_are_bitwise_one_piece(hh, batch):
    mod = mg.build(hh, "stormer-verlet", order=6, composition="blanes-moan-rkn")
    y0 = np.stack([HH_Y0, 0.8 * HH_Y0]) if batch else HH_Y0
    whole = mod.integrate(y0, 0.2, 200)
    assert np.array_equal(_chunked(mod, y0, 0.2, [1] * 200), whole)
    assert np.array_equal(_chunked(mod, y0, 0.2, [70, 1, 129]), whole)
    # negative control: the carried force is what the next chunk uses (perturbed, the bits change)
    changed = _chunked(mod, y0, 0.2, [1] * 200, perturb=True)
    assert not np.array_equal(changed, whole)
    assert np.abs(changed - whole).max() < 1e-6


def test_numba_chunks_and_agreement(hh):
    pytest.importorskip("llvmlite")
    nb = mg.build(hh, "stormer-verlet", order=4, composition="blanes-moan", backend="numba")
    npm = mg.build(hh, "stormer-verlet", order=4, composition="blanes-moan")
    whole = nb.integrate(HH_Y0, 0.2, 200)
    assert np.array_equal(_chunked(nb, HH_Y0, 0.2, [1] * 200), whole)
    assert not np.array_equal(_chunked(nb, HH_Y0, 0.2, [1] * 200, perturb=True), whole)
    assert np.abs(npm.integrate(HH_Y0, 0.2, 200) - whole).max() < 1e-12


# --- (e) errors ---------------------------------------------------------------------------

def test_a_splitting_with_another_method_is_refused(hh):
    with pytest.raises(InputError, match="stormer-verlet") as exc:
        mg.discretize(hh, "midpoint", order=4, composition="blanes-moan")
    # the alternatives offered have the order asked for (kahan-li has no order 4), and the
    # text names no API keyword (the CLI shows it under --composition)
    msg = str(exc.value)
    assert "order 4 for midpoint: triple-jump, suzuki)" in msg and "composition=" not in msg
    for family in msg.split(": ")[-1].rstrip(")").split(", "):
        assert mg.discretize(hh, "midpoint", order=4, composition=family).traits.order == 4


def test_rkn_family_needs_quadratic_t():
    rel = mg.Hamiltonian("sqrt(1 + p**2) + q**2/2", q=["q"], p=["p"])
    with pytest.raises(MethodNotApplicable, match="Runge-Kutta-Nystrom") as exc:
        mg.discretize(rel, "stormer-verlet", order=6, composition="blanes-moan-rkn")
    # offered: what has order 6 for every T (mclachlan has order 4 only)
    assert str(exc.value).endswith("of order 6 for every T: blanes-moan") and "composition=" not in str(exc.value)
    assert mg.discretize(rel, "stormer-verlet", order=6, composition="blanes-moan").traits.order == 6
    # the general families apply (order 4 for every splitting)
    assert mg.discretize(rel, "stormer-verlet", order=4, composition="blanes-moan").traits.order == 4


def test_extended_is_refused(hh):
    mod = mg.build(hh, "stormer-verlet", order=4, composition="mclachlan")
    with pytest.raises(ValueError, match="extended=True is not available for a splitting"):
        mod.integrate(HH_Y0, 0.1, 5, extended=True)
    # control: a composition of Störmer–Verlet refines
    sv4 = mg.build(hh, "stormer-verlet", order=4)
    assert np.isfinite(sv4.integrate(HH_Y0, 0.1, 5, extended=True)).all()


# --- (f) verify ---------------------------------------------------------------------------

def test_verify_certificates():
    from methodgen.symbolic.verify.report import NUMERICAL, PROVED
    from methodgen.symbolic.verify.splittings import (splitting_float_certificate, splitting_order_certificate,
                                             splitting_symmetry_certificate)
    mcl = splitting(4, "mclachlan")
    assert splitting_order_certificate(mcl).status == PROVED          # √19: exact zeros
    assert splitting_order_certificate(splitting(4, "blanes-moan")).status == NUMERICAL
    rkn = splitting_order_certificate(splitting(6, "blanes-moan-rkn"))
    assert rkn.status == NUMERICAL and "Runge–Kutta–Nyström" in rkn.claim and rkn.details["general_order"] == 4
    for s in (mcl, splitting(6, "blanes-moan-rkn")):
        assert splitting_float_certificate(s).status == NUMERICAL
        assert splitting_symmetry_certificate(s).status == PROVED


def test_verify_negative_controls():
    """A perturbed exact coefficient (symmetric, sums kept) is refuted exactly; a perturbed
    decimal one numerically; a non-palindromic set is not symmetric."""
    import sympy as sp
    from methodgen.symbolic.verify.report import REFUTED
    from methodgen.symbolic.verify.splittings import splitting_order_certificate, splitting_symmetry_certificate
    mcl = splitting(4, "mclachlan")
    d = list(mcl.drifts)
    eps = sp.Rational(1, 1000)
    d[0] += eps
    d[-1] += eps
    d[2] -= eps
    d[3] -= eps
    bad = Splitting("perturbed", 4, mcl.kicks, tuple(d), True, "test")
    assert splitting_order_certificate(bad).status == REFUTED
    bm = splitting(4, "blanes-moan")
    b = [float(x) for x in bm.kicks]
    b[0] += 1e-6
    b[-1] += 1e-6
    b[3] -= 2e-6
    assert splitting_order_certificate(Splitting("p", 4, tuple(map(repr, b)), bm.drifts, False, "t")).status == REFUTED
    b = [float(x) for x in bm.kicks]
    b[0] += 1e-6
    b[3] -= 1e-6
    assert splitting_symmetry_certificate(Splitting("p", 4, tuple(map(repr, b)), bm.drifts, False, "t")).status \
        == REFUTED


# --- (g) command line ---------------------------------------------------------------------

def test_cli_run_with_a_splitting(capsys, tmp_path, monkeypatch):
    import json
    from methodgen.app import cli
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    code = cli.main(["run", "henon-heiles-2d", "--method", "stormer-verlet", "--order", "6",
                     "--composition", "blanes-moan-rkn", "--steps", "20", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    rep = json.loads(out)
    assert rep["order"] == 6 and "blanes-moan-rkn" in json.dumps(rep["composition"])
    # a splitting with another method: one line, exit 2, no traceback
    code = cli.main(["run", "henon-heiles-2d", "--method", "midpoint", "--order", "4",
                     "--composition", "blanes-moan", "--steps", "2"])
    out, err = capsys.readouterr()
    assert code == 2 and "stormer-verlet" in err and "Traceback" not in err


def test_bench_peers_rows_use_the_family():
    """``work_precision(..., peers=True, composition=F)``: the rows above order 2 of
    stormer-verlet are F's; a method F does not apply to keeps the order's default family."""
    pytest.importorskip("heyoka")
    from methodgen.app import bench
    wp = bench.work_precision(mg.load_scene("henon-heiles-2d"), ["stormer-verlet", "midpoint"], quick=True,
                              T=2.0, peers=True, orders=(6,), composition="blanes-moan-rkn")
    labels = {r["method"] for r in wp["rows"] if r["kind"] == "methodgen"}
    assert any("blanes-moan-rkn" in m and "stormer-verlet" in m for m in labels), labels
    assert not any("blanes-moan-rkn" in m and "midpoint" in m for m in labels), labels
    with pytest.raises(InputError, match="unknown composition family"):
        bench.work_precision(mg.load_scene("henon-heiles-2d"), ["stormer-verlet"], quick=True, T=2.0,
                             peers=True, orders=(6,), composition="bogus")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_an_unresolved_step_is_refused(hh, backend):
    """The per-stage local error estimate refuses a step that does not resolve the dynamics
    (Hénon–Heiles, SRKN_11^b, h = 2: estimate 0.118 > 0.1), naming the stage; h = 1 runs."""
    if backend == "numba":
        pytest.importorskip("llvmlite")
    mod = mg.build(hh, "stormer-verlet", order=6, composition="blanes-moan-rkn", backend=backend)
    assert np.isfinite(mod.integrate(HH_Y0, 1.0, 200)).all()
    with pytest.raises(mod.ResolutionError, match=r"DRIFT\[\d+\] \* h") as exc:
        mod.integrate(HH_Y0, 2.0, 200)
    assert exc.value.suggested_h is not None and exc.value.suggested_h < 2.0
    # control: without the check the run goes on (the estimate is what refused it)
    assert mod.integrate(HH_Y0, 2.0, 20, check_resolution=False).shape == (21, 4)


def test_verify_report_of_a_splitting_scheme(hh):
    rep = mg.verify(mg.discretize(hh, "stormer-verlet", order=6, composition="blanes-moan-rkn"))
    assert rep.ok
    claims = " | ".join(c.claim for c in rep.certificates)
    assert "splitting coefficients" in claims and "symplectic" in claims and "symmetric" in claims


def test_a_scene_declares_a_splitting(tmp_path, capsys, monkeypatch):
    from methodgen.app import cli
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    f = tmp_path / "hh.toml"
    f.write_text('name = "hh"\n[system]\nH = "(p1**2 + p2**2)/2 + (q1**2 + q2**2)/2 + q1**2*q2 - q2**3/3"\n'
                 'q = ["q1", "q2"]\np = ["p1", "p2"]\n[run]\nmethod = "stormer-verlet"\nh = 0.1\nsteps = 10\n'
                 'order = 4\ncomposition = "mclachlan"\ny0 = [0.0, 0.0, 0.4330127018922193, 0.25]\n')
    assert mg.load_scene(f).composition == "mclachlan"
    assert cli.main(["run", str(f)]) == 0
    assert "mclachlan composition, 5 stages" in capsys.readouterr().out
    # control: a family without that order is refused at load, naming what is valid
    f.write_text(f.read_text().replace("order = 4", "order = 8"))
    with pytest.raises(Exception, match="mclachlan family has order 4, not 8"):
        mg.load_scene(f)
