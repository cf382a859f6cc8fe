"""The Newton solve of a lattice of any half-bandwidth w and any N: the stepper's bordered block
elimination over groups of w sites (methodgen.runtime.lattice_stepper, run as Python) and the numpy
module's solve (block cyclic reduction, with the last group as a border where w does not divide
N) against numpy's dense solve of the same matrix, for several N -- odd, near the minimum 2w + 1,
divisible by w and not; negative controls: a wrong wrap (corner) entry, a wrong band entry."""

from __future__ import annotations

import numpy as np
import pytest

from methodgen.runtime import lattice_stepper as ls
from methodgen.runtime.lattice_driver import shape_constants, stepper_functions


def random_diagonals(rng, n, nf, w, periodic=True):
    """Site diagonals P[e, f, f', s] (e = 0 … 2w: the offset e - w) of a banded matrix near I (a
    resolved step's Newton matrix: I + O(1) coupling), zero wrap entries unless periodic."""
    P = 0.3 * rng.normal(size=(2 * w + 1, nf, nf, n))
    P[w] += 2.0 * np.eye(nf)[:, :, None]
    if not periodic:
        for e in range(2 * w + 1):
            for s in range(n):
                if not 0 <= s + e - w < n:
                    P[e, :, :, s] = 0.0
    return P


def dense(P):
    """The matrix of site diagonals P as a dense (nf n, nf n) array, site-major (f fastest)."""
    e2, nf, _, n = P.shape
    w = (e2 - 1) // 2
    M = np.zeros((nf * n, nf * n))
    for e in range(e2):
        for s in range(n):
            t = (s + e - w) % n
            M[nf * s:nf * s + nf, nf * t:nf * t + nf] += P[e, :, :, s]
    return M


def stepper_solve(P, r):
    """x with M x = r (r (nf, n)) by the stepper's assemble/factor/solve, run as Python."""
    e2, nf, _, n = P.shape
    w = (e2 - 1) // 2
    shape = shape_constants(n, nf, w)
    st = stepper_functions(shape)
    Pr = np.ascontiguousarray(P.reshape(e2 * nf * nf, n))
    F = np.zeros(ls.factor_size(n, nf, shape["_GS"]))
    W = np.zeros((ls.W_ROWS, n))
    assert st.factor(Pr, F, n) == 0
    W[ls._IR:ls._IR + nf] = -r              # solve() takes -R and leaves the update
    st.solve(W, F, n)
    return W[ls._IR:ls._IR + nf].copy()


CASES = [(nf, w, n) for nf, w, ns in [(2, 1, (3, 4, 5, 9)), (1, 2, (5, 6, 7, 11, 12)), (2, 2, (5, 6, 9)),
                                      (1, 4, (9, 10, 11, 13, 16, 23)), (2, 3, (7, 8, 10, 14)), (1, 1, (3, 8))]
         for n in ns]


@pytest.mark.parametrize("nf,w,n", CASES)
@pytest.mark.parametrize("periodic", [True, False])
def test_stepper_solve_agrees_with_a_dense_solve(nf, w, n, periodic):
    rng = np.random.default_rng(1000 * w + 10 * n + nf)
    P = random_diagonals(rng, n, nf, w, periodic)
    r = rng.normal(size=(nf, n))
    M = dense(P)
    x = stepper_solve(P, r)
    xd = np.linalg.solve(M, r.T.reshape(-1)).reshape(n, nf).T
    assert np.max(np.abs(x - xd)) < 1e-11 * max(1.0, np.max(np.abs(xd)))
    # negative control: a wrong wrap entry (site 0 to site n - w) and a wrong band entry are seen
    for s, e in ((0, 0), (n // 2, 2 * w)):
        P2 = P.copy()
        P2[e, 0, 0, s] += 0.5
        x2 = np.linalg.solve(dense(P2), r.T.reshape(-1)).reshape(n, nf).T
        assert np.max(np.abs(x - x2)) > 1e-6


def test_the_kernel_and_the_stepper_agree_on_the_work_rows():
    from methodgen.codegen.lattice_emit import KERNEL_Z_ROW
    assert KERNEL_Z_ROW == ls._IZ and ls._IG == 0


def test_a_singular_block_is_reported():
    n, nf, w = 7, 1, 2
    P = np.zeros((2 * w + 1, nf, nf, n))
    F = np.zeros(ls.factor_size(n, nf, w))
    assert stepper_functions(shape_constants(n, nf, w)).factor(P.reshape(-1, n), F, n) == 1
