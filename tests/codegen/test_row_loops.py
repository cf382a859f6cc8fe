"""Loops over like rows in compiled kernels (issue 25; methodgen/codegen/lower_rows.py).

(a) A numba module whose kernels print like rows as loops gives the straight-line module's
    trajectory *bitwise* (Toda ring and FPU chain; energy-momentum, Störmer–Verlet with its
    Δq ahead of the term loops, midpoint, AVF), and its kernels' outputs bitwise on random
    inputs.
(b) The compiled kernels stop growing with the size: the numba kernel section of a ring of 60
    is barely longer than that of a ring of 30, where the straight-line section doubles.
(c) Controls: one template offset moved in the printed module changes the trajectory; the
    loops run in their written order instead of the hazard-free order, the post kernel reads
    accumulators it has overwritten and the trajectory changes.
(d) Small systems (fewer than 48 state components: Kepler, the outer solar system) are not
    touched (their modules are byte-identical with and without).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import methodgen as mg
import methodgen.codegen.lower_rows as LR
from methodgen.codegen.emit import load_module, render, write_atomic
from methodgen.codegen.lower import lower

pytest.importorskip("llvmlite")


def toda(n):
    H = f"Sum(p[i]**2/2, i, 1, {n}) + Sum(exp(q[i] - q[i % {n} + 1]), i, 1, {n})"
    return mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                          name=f"toda{n}")


def fpu(n):
    H = (f"Sum(p[i]**2/2, i, 1, {n}) + q[1]**2/2 + beta*q[1]**4/4 + Sum((q[i+1] - q[i])**2/2 "
         f"+ beta*(q[i+1] - q[i])**4/4, i, 1, {n - 1}) + q[{n}]**2/2 + beta*q[{n}]**4/4")
    return mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                          params={"beta": 1.0}, name=f"fpu{n}")


def source(scheme, rows: bool, tag: str) -> str:
    old = LR.MIN_KERNEL_ROWS
    if not rows:
        LR.MIN_KERNEL_ROWS = 10 ** 9
    try:
        return render(lower(scheme, "test", f"rows_{tag}_{rows}"), "numba")
    finally:
        LR.MIN_KERNEL_ROWS = old


def load(text: str, tmp_path: Path, name: str):
    path = tmp_path / f"{name}.py"
    write_atomic(path, text)
    return load_module(path)


def restamp(text: str) -> str:
    """An edited module with its content hash made to match (a control edits on purpose)."""
    import hashlib

    from methodgen.codegen.emit import HEADER_CONTENT
    body = text.partition("\n")[2]
    return HEADER_CONTENT + hashlib.sha256(body.encode()).hexdigest() + "\n" + body


def start(system, seed=1):
    n = system.dim
    rng = np.random.default_rng(seed)
    return np.concatenate([0.3 * rng.normal(size=n), 0.5 * rng.normal(size=n)])


@pytest.fixture(scope="module")
def toda30(tmp_path_factory):
    """The Toda ring of 30, energy–momentum: scheme, straight-line numba module, row-loop source."""
    system = toda(30)
    scheme = mg.discretize(system, "energy-momentum")
    off = load(source(scheme, False, "t30"), tmp_path_factory.mktemp("t30"), "t30_off")
    return system, scheme, off, source(scheme, True, "t30")


def differs(A, B, y0, steps) -> bool:
    """Whether module A's run differs from B's (a wrong module may also fail loudly)."""
    b = B.integrate(y0, 0.05, steps, check_resolution=False)
    try:
        a = A.integrate(y0, 0.05, steps, check_resolution=False)
    except (A.ConvergenceError, A.NonFiniteError, A.ResolutionError):
        return True
    return not np.array_equal(a, b)


CASES = [("toda", 30, "energy-momentum"), ("toda", 24, "stormer-verlet"),
         pytest.param("fpu", 24, "energy-momentum", marks=pytest.mark.slow),
         pytest.param("toda", 30, "midpoint", marks=pytest.mark.slow),
         pytest.param("toda", 26, "avf", marks=pytest.mark.slow)]


@pytest.mark.parametrize("kind, n, method", CASES)
def test_row_loops_are_bitwise_the_straight_line_kernels(tmp_path, request, kind, n, method):
    if (kind, n, method) == ("toda", 30, "energy-momentum"):
        system, scheme, B, text = request.getfixturevalue("toda30")
    else:
        system = (toda if kind == "toda" else fpu)(n)
        scheme = mg.discretize(system, method)
        text = source(scheme, True, f"{kind}{n}{method}")
        B = load(source(scheme, False, f"{kind}{n}{method}"), tmp_path, "rows_off")
    assert "like rows (methodgen.codegen.lower_rows)" in text
    A = load(text, tmp_path, "rows_on")
    y0 = start(system)
    a, b = A.integrate(y0, 0.05, 200), B.integrate(y0, 0.05, 200)
    assert np.array_equal(a, b)
    # the kernels themselves, on random inputs (the residual's unknowns, compensation, step)
    rng = np.random.default_rng(3)
    for _ in range(3):
        y = start(system, rng.integers(1000))
        c = 1e-17 * rng.normal(size=y.size)
        p = np.array([float(v) for v in A.DEFAULT_PARAMS.values()])
        for kern in ("_nb_check", "_nb_hs"):     # H and the field at one state
            if hasattr(A, kern):
                oa, ob = np.zeros(4 * y.size + 8), np.zeros(4 * y.size + 8)
                getattr(A, kern)(y, p, oa)
                getattr(B, kern)(y, p, ob)
                assert np.array_equal(oa, ob), kern
        if hasattr(A, "_nb_guess"):
            oa, ob = np.zeros(len(A.UNKNOWN_NAMES)), np.zeros(len(A.UNKNOWN_NAMES))
            A._nb_guess(y, 0.05, p, oa)
            B._nb_guess(y, 0.05, p, ob)
            assert np.array_equal(oa, ob)
        if hasattr(A, "_nb_res"):
            z = 0.05 * rng.normal(size=len(A.UNKNOWN_NAMES))
            ra, rb = np.zeros(z.size), np.zeros(z.size)
            A._nb_res(z, y, c, 0.05, p, ra)
            B._nb_res(z, y, c, 0.05, p, rb)
            assert np.array_equal(ra, rb)


def _kernel_section(text: str) -> str:
    a = text.index("# --- compiled kernels")
    b = text.index("# --- kernels on numpy arrays", a)
    return text[a:b]


def test_kernels_stop_growing_with_the_size():
    s30, s60 = (mg.discretize(toda(n), "energy-momentum") for n in (30, 60))
    on = [len(_kernel_section(source(s, True, f"g{n}")).splitlines()) for n, s in ((30, s30), (60, s60))]
    off = [len(_kernel_section(source(s, False, f"g{n}")).splitlines()) for n, s in ((30, s30), (60, s60))]
    assert off[1] > 1.8 * off[0]          # straight-line: linear in the size
    assert on[1] < 1.1 * on[0] and on[0] < off[0] / 2, (on, off)


def test_a_moved_offset_changes_the_trajectory(tmp_path, monkeypatch, toda30):
    """Control for (a): the comparison can fail.  One read of the row loops moved to another
    (in-bounds) element -- in the kernel IR, which the compiled route translates (editing the
    printed function would change nothing there)."""
    system, scheme, B, text = toda30
    real = LR._at

    def moved_at(arr, var, off):
        return real(arr, var, off - 1 if (arr, var, off) == ("_sA", "_i", 0) else off)

    monkeypatch.setattr(LR, "_at", moved_at)
    moved = source(scheme, True, "t30")
    assert moved != text and "_sA[_i - 1]" in moved
    A = load(moved, tmp_path, "moved")
    assert differs(A, B, start(system), 50)


def test_hazard_order_matters(tmp_path, monkeypatch, toda30):
    """Control for (c): without the ordering the post kernel overwrites accumulators (Δq is
    written over the accumulated gradient before the momenta's rows read it)."""
    system, scheme, B, good = toda30
    monkeypatch.setattr(LR, "_order", lambda blocks: sorted(blocks, key=lambda B: B[0]))
    bad = source(scheme, True, "t30")
    assert bad != good
    A = load(bad, tmp_path, "bad_order")
    assert differs(A, B, start(system), 20)


@pytest.mark.parametrize("scene", ["kepler", "outer-solar-system"])
def test_small_systems_are_untouched(scene):
    """Fewer than MIN_KERNEL_ROWS (48) state components: byte-identical modules."""
    scheme = mg.discretize(mg.load_scene(scene).system, "energy-momentum")
    assert source(scheme, True, "small") == source(scheme, False, "small")


def test_sums_keep_their_printed_order():
    """A long sum becomes a loop over its terms in the printed order (SymPy's, not index order)."""
    text = source(mg.discretize(toda(30), "energy-momentum"), True, "sums")
    m = re.search(r"# (\d+) terms in their printed order.*\n\s*for _e in \(([0-9, ]+),?\):", text)
    assert m is not None
    codes = [int(x) for x in m.group(2).split(",") if x.strip()]
    ks = [c >> 3 for c in codes]
    assert ks != sorted(ks)                 # SymPy's order (q1, q10, q11, …), kept as printed
