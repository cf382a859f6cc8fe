"""Processed compositions (issue 26, item 2; methodgen/symbolic/processing.py).

(a) Effective order decided in the free algebra (60 digits, to the published digits): the
    whole sequence pre-processor, kernel, post-processor has order 6 / 8 while the kernel
    alone has order 4.  Controls: the processors applied the other way round, and one
    processor coefficient moved (Σ = 0 kept), fail the order-5 conditions.
(b) Measured orders on Hénon–Heiles (error ratio under halving h against DOP853) for
    energy–momentum and Störmer–Verlet.  Control: the processors swapped in the built
    integrator drop the measured order to the kernel's 4.
(c) What is kept: energy–momentum processed keeps H and q × p on Kepler to round-off at every
    row (control: Störmer–Verlet processed does not keep H).
(d) Rows: row 0 is y0; chunked runs with ``info`` and ``save_every`` rows equal the run in
    one piece bitwise; a batch row by row to round-off (control: without the record the chunk boundary re-processes and the
    bits change).
(e) Clear errors: unknown family or order, a method that is not symmetric, ``t_eval``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg
from conftest import HH_T, HH_Y0, KEPLER_Y0
from methodgen.errors import InputError, MethodNotApplicable
from methodgen.codegen.build import build_processed
from methodgen.symbolic.processing import (PROCESSED, Processed, ProcessedIntegrator, achieved_order, order_defects,
                                  processed_composition)

CASES = [(f, o) for f, orders in PROCESSED.items() for o in orders]



@pytest.fixture(scope="module")
def kep(kepler):
    return kepler


# --- (a) order conditions ---------------------------------------------------------------

@pytest.mark.parametrize("family, order", CASES)
def test_effective_order_decided(family, order):
    proc = processed_composition(order, family)
    r = achieved_order(proc)
    assert r["order"] == order, r["defects"]
    assert r["kernel_order"] == 4, r["kernel_defects"]         # processing is what lifts it
    assert r["defects"][order + 1] > 1e-6                       # the next condition is a real one
    assert max(r["defects"][w] for w in range(1, order + 1)) < 1e-15
    assert math.isclose(sum(float(g) for g in proc.kernel), 1.0, abs_tol=1e-15)
    assert abs(sum(float(g) for g in proc.pre)) < 1e-15
    assert proc.kernel == tuple(reversed(proc.kernel))          # symmetric kernel


@pytest.mark.parametrize("family, order", CASES)
def test_processors_the_other_way_round_fail(family, order):
    proc = processed_composition(order, family)
    d = order_defects(proc.post + proc.kernel + proc.pre, order)
    assert d[5] > 1e-4, d


def test_a_moved_processor_coefficient_fails():
    proc = processed_composition(8)
    pre = [float(g) for g in proc.pre]
    pre[1] += 1e-4
    pre[2] -= 1e-4                      # Σ = 0 kept
    bad = Processed("moved", 8, proc.kernel, tuple(map(repr, pre)), "test")
    r = achieved_order(bad)
    # the processor is not symmetric: an even weight fails first
    assert r["order"] == 3 and r["defects"][4] > 1e-6, r["defects"]


def test_post_is_the_inverse_sequence():
    proc = processed_composition(6)
    assert [float(x) for x in proc.post] == [-float(x) for x in reversed(proc.pre)]


# --- (b) measured orders ------------------------------------------------------------------

#: (method, order, N): N and 2N steps over HH_T, in the asymptotic range, above round-off.
MEASURED = [("energy-momentum", 6, 20), ("energy-momentum", 8, 20),
            ("stormer-verlet", 6, 80), ("stormer-verlet", 8, 40)]


def _errors(P, ref, N):
    return [float(np.abs(P.integrate(HH_Y0, HH_T / n, n, check_resolution=False)[-1] - ref).max())
            for n in (N, 2 * N)]


@pytest.mark.parametrize("method, K, N", MEASURED)
def test_measured_order(hh, hh_reference, method, K, N):
    P = build_processed(hh, method, K)
    assert P.ORDER == K and P.TRAITS["order"] == K and not P.TRAITS["symmetric"]
    errs = _errors(P, hh_reference, N)
    assert errs[1] > 3e-13, f"error {errs[1]:.1e} at 2N is at round-off: the case measures nothing"
    rate = math.log2(errs[0] / errs[1])
    assert K - 0.5 < rate < K + 0.7, f"measured order {rate:.2f}, claimed {K} ({errs})"


def test_swapped_processors_lose_the_order(hh, hh_reference):
    P = build_processed(hh, "energy-momentum", 8)
    swapped = ProcessedIntegrator(P.processed, P.kernel, P.post, P.pre)
    errs = _errors(swapped, hh_reference, 20)
    assert math.log2(errs[0] / errs[1]) < 5, errs
    good = _errors(P, hh_reference, 20)
    assert good[1] < errs[1] / 100


# --- (c) what is kept ---------------------------------------------------------------------

def test_energy_momentum_processed_keeps_H_and_L(kep):
    P = build_processed(kep, "energy-momentum", 8)
    Y = P.integrate(KEPLER_Y0, 0.1, 400)
    H = P.hamiltonian(Y)
    L = np.cross(Y[:, :3], Y[:, 3:])
    assert np.abs(H - H[0]).max() < 4e-15
    assert np.abs(L - L[0]).max() < 4e-15
    # control: the same processing of Störmer–Verlet keeps H only approximately
    S = build_processed(kep, "stormer-verlet", 8)
    HS = S.hamiltonian(S.integrate(KEPLER_Y0, 0.1, 400, check_resolution=False))
    assert np.abs(HS - HS[0]).max() > 1e-9


# --- (d) rows -----------------------------------------------------------------------------

@pytest.mark.parametrize("method", ["stormer-verlet", "energy-momentum"])
def test_chunks_and_save_every_equal_one_piece(kep, method):
    P = build_processed(kep, method, 6)
    h = 0.05
    whole = P.integrate(KEPLER_Y0, h, 60)
    assert np.array_equal(whole[0], KEPLER_Y0)
    info: dict = {}
    a = P.integrate(KEPLER_Y0, h, 25, info=info)
    b = P.integrate(a[-1], h, 35, info=info)
    assert np.array_equal(np.vstack([a, b[1:]]), whole)
    sparse = P.integrate(KEPLER_Y0, h, 60, save_every=7)
    assert np.array_equal(sparse, whole[list(range(0, 61, 7)) + [60]])
    # control: without the record the second chunk starts from π⁻¹(last row), not the kernel state
    c = P.integrate(a[-1], h, 35)
    assert not np.array_equal(c, b)
    assert np.abs(c - b).max() < 1e-12


def test_a_batch_is_row_by_row(kep):
    P = build_processed(kep, "stormer-verlet", 8)
    y0 = np.vstack([KEPLER_Y0, KEPLER_Y0 * [1.1, 1, 1, 1, 0.95, 1]])
    Y = P.integrate(y0, 0.05, 20)
    assert Y.shape == (21, 2, 6)
    for i in range(2):     # a module's batch path agrees with its one-trajectory path to round-off
        np.testing.assert_allclose(Y[:, i], P.integrate(y0[i], 0.05, 20), rtol=0, atol=1e-14)


# --- (e) errors ---------------------------------------------------------------------------

def test_clear_errors(kep):
    with pytest.raises(InputError, match="orders"):
        build_processed(kep, "energy-momentum", 4)
    with pytest.raises(InputError, match="unknown processed family"):
        build_processed(kep, "energy-momentum", 8, family="nope")
    with pytest.raises(MethodNotApplicable, match="symmetric"):
        build_processed(kep, "itoh-abe", 8)
    P = build_processed(kep, "stormer-verlet", 6)
    with pytest.raises(ValueError, match="t_eval"):
        P.integrate(KEPLER_Y0, 0.1, 10, t_eval=[0.0, 0.5])


def test_numba_agrees_with_numpy(kep):
    pytest.importorskip("llvmlite")
    P = build_processed(kep, "stormer-verlet", 8)
    F = build_processed(kep, "stormer-verlet", 8, backend="numba")
    assert F.BACKEND == "numba" and F.kernel.BACKEND == "numba"
    np.testing.assert_allclose(F.integrate(KEPLER_Y0, 0.05, 200, save_every=50),
                               P.integrate(KEPLER_Y0, 0.05, 200, save_every=50), rtol=0, atol=1e-12)


# --- (f) the API, the command line, verify and bench ---------------------------------------

def test_build_with_a_processed_family(kep):
    P = mg.build(kep, "energy-momentum", order=6, composition="blanes-casas-murua")
    assert isinstance(P, ProcessedIntegrator) and P.COMPOSITION["processed"] and P.ORDER == 6
    assert P.INVARIANT_NAMES == P.kernel.INVARIANT_NAMES and P.ConvergenceError is P.kernel.ConvergenceError
    with pytest.raises(AttributeError, match="three generated modules"):
        P.residual
    with pytest.raises(InputError, match="path="):
        mg.build(kep, "energy-momentum", "x.py", order=6, composition="blanes-casas-murua")
    with pytest.raises(InputError, match="processed composition"):
        mg.discretize(kep, "energy-momentum", order=6, composition="blanes-casas-murua")
    # one step is post(K(pre(y0)))
    y1 = P.step(KEPLER_Y0, 0.05)
    assert np.array_equal(y1, P.integrate(KEPLER_Y0, 0.05, 1)[-1])


def _cli(capsys, *args):
    import methodgen.app.cli as cli
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_run_verify_generate(capsys):
    import json
    code, out, err = _cli(capsys, "run", "kepler", "--order", "8", "--composition", "blanes-casas-murua",
                          "--steps", "300", "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert rep["composition"]["processed"] and rep["order"] == 8
    assert rep["invariants"]["H"]["max_abs_error"] < 4e-15 and rep["invariants"]["H"]["claim"] == "exact"
    code, out, err = _cli(capsys, "verify", "kepler", "--method", "energy-momentum", "--order", "8",
                          "--composition", "blanes-casas-murua", "--json")
    assert code == 0, err
    rep = json.loads(out)
    first = rep["certificates"][0]
    assert "processed composition" in first["claim"] and first["status"] == "numerical"
    assert rep["verdict"] == "ok" and rep["composition"]["processor_stages"] == 20
    code, out, err = _cli(capsys, "generate", "kepler", "--order", "8", "--composition", "blanes-casas-murua",
                          "--out", "unused-dir")
    assert code == 2 and "three generated modules" in err and "Traceback" not in err


def test_effective_order_certificate_and_its_control():
    from methodgen.symbolic.verify.processed import effective_order_certificate, float64_certificate
    proc = processed_composition(8)
    c = effective_order_certificate(proc)
    assert c.status == "numerical" and c.details["passed"] and c.details["kernel_order"] == 4
    f = float64_certificate(proc)
    assert f.status == "numerical" and f.details["passed"]
    pre = [float(g) for g in proc.pre]
    pre[3] += 1e-4
    pre[4] -= 1e-4
    bad = Processed("moved", 8, proc.kernel, tuple(map(repr, pre)), "test")
    assert effective_order_certificate(bad).status == "refuted"


def test_bench_peers_rows_of_a_processed_family():
    pytest.importorskip("heyoka")
    from methodgen.app import bench
    wp = bench.work_precision(mg.load_scene("henon-heiles-2d"), ["stormer-verlet"], quick=True,
                              T=2.0, peers=True, orders=(8,), composition="blanes-casas-murua")
    rows = [r for r in wp["rows"] if r["kind"] == "methodgen" and r["order"] == 8]
    assert rows and all(r["processed"] and r["stages"] == 13 for r in rows), rows
    assert all(r["error"] < 1e-3 for r in rows)


# --- (g) failures say where, and keep the processed rows -----------------------------------

def test_a_kernel_failure_names_the_kernel_and_keeps_processed_rows(kep):
    """From the apocentre with h = 0.3 the kernel's local error guard stops at the pericentre;
    the error says it was the kernel of the processed composition (not "the order-4
    composition") and its partial trajectory is post-processed rows, row 0 = y0."""
    P = build_processed(kep, "energy-momentum", 8)
    y0 = np.array([-1.6, 0.0, 0.0, 0.0, -0.5, 0.0])
    with pytest.raises(P.ResolutionError) as info:
        P.integrate(y0, 0.3, 40)
    msg, part = str(info.value), info.value.trajectory
    assert msg.startswith("in the kernel of the processed composition (blanes-casas-murua, order 8")
    assert "order-4 composition" not in msg
    assert part.ndim == 2 and len(part) > 2 and np.array_equal(part[0], y0)
    ok = P.integrate(y0, 0.3, len(part) - 1)
    np.testing.assert_allclose(part, ok, rtol=0, atol=1e-12)   # processed rows, not kernel states
    # control: the kernel's own states differ from the processed rows by the processor's O(h^k)
    ks = P.kernel.integrate(P._apply(P.pre, y0, 0.3, None, {}), 0.3, len(part) - 1)
    assert np.abs(ks[1:] - part[1:]).max() > 1e-8


def test_a_processor_failure_on_the_command_line(capsys):
    code, out, err = _cli(capsys, "run", "kepler", "--order", "8", "--composition", "blanes-casas-murua",
                          "--h", "0.5", "--steps", "100")
    assert code == 3 and "Traceback" not in err
    assert "in the pre-processor of the processed composition" in err and "order-4" not in err
