"""Per-step cost of the generated N-body energy-momentum module against a hand-written
numba pair-loop kernel of the same scheme (issue 16's "within 2x" target).

Not a test: run it and read the table.  The hand-written baseline is numba code: install numba
to run it (methodgen itself does not use numba).

    python benchmarks/nbody_pairloop.py [--bodies 2 6 8] [--steps 3000] [--h 0.002]

The scheme is methodgen's energy-momentum for ``bench.nbody_system(N)`` (unit masses, G = 1):
the LaBudde-Greenspan radial discrete gradient of every pair,
``A_a = sum_b G m_a m_b (r0 + r1)_ab / (|r0| |r1| (|r0| + |r1|))``, momenta eliminated,
``dq = h M^-1 (p0 - h/2 A(q0, q0 + dq))``, ``p1 = p0 - h A``, started from the Stormer-Verlet
prediction, iterated until the increment's correction reaches 0 or stops decreasing (the
generated module's rule).  The hand-written kernels below do exactly that with pair loops,
preallocated arrays and (Newton) an in-place Gaussian elimination of the dense
``I + (h^2/2) M^-1 dA/d(dq)``, assembled pair by pair from 3x3 blocks.  They use plain
summation; the generated module (default settings) also carries compensated summation and
compensated stage sums, so it does a little more per step.

Rows: generated numba module (default loop/unroll choice) per solver, hand-written Newton and
fixed-point; the largest deviation of the generated trajectory from the hand-written one after
100 steps (the same scheme: round-off; the N-body flow is chaotic, so longer runs part).
CPU times (least of 5 repeats), after compilation; first use (derive + emit + compile + 2
steps) wall-clock, with numba's on-disk cache as found.
"""

from __future__ import annotations

import argparse
import pathlib
import tempfile
import time

import numpy as np
import numba as nb

from methodgen.app.bench import nbody_initial, nbody_system
from methodgen.codegen.emit import load_module, render, write_atomic
from methodgen.codegen.lower import lower
from methodgen.symbolic.schemes import discretize


@nb.njit(cache=True)
def dgA(q0, dq, m, G, A):
    n = m.size
    A[:] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            r0x = q0[3*a] - q0[3*b]; r0y = q0[3*a+1] - q0[3*b+1]; r0z = q0[3*a+2] - q0[3*b+2]
            r1x = r0x + dq[3*a] - dq[3*b]; r1y = r0y + dq[3*a+1] - dq[3*b+1]; r1z = r0z + dq[3*a+2] - dq[3*b+2]
            s0 = r0x*r0x + r0y*r0y + r0z*r0z; s1 = r1x*r1x + r1y*r1y + r1z*r1z
            x = np.sqrt(s0); y = np.sqrt(s1)
            g = G * m[a] * m[b] / (x * y * (x + y))
            cx = g * (r0x + r1x); cy = g * (r0y + r1y); cz = g * (r0z + r1z)
            A[3*a] += cx; A[3*b] -= cx; A[3*a+1] += cy; A[3*b+1] -= cy; A[3*a+2] += cz; A[3*b+2] -= cz

@nb.njit(cache=True)
def dgAJ(q0, dq, m, G, A, D):
    n = m.size
    A[:] = 0.0; D[:, :] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            r0x = q0[3*a] - q0[3*b]; r0y = q0[3*a+1] - q0[3*b+1]; r0z = q0[3*a+2] - q0[3*b+2]
            r1x = r0x + dq[3*a] - dq[3*b]; r1y = r0y + dq[3*a+1] - dq[3*b+1]; r1z = r0z + dq[3*a+2] - dq[3*b+2]
            s0 = r0x*r0x + r0y*r0y + r0z*r0z; s1 = r1x*r1x + r1y*r1y + r1z*r1z
            x = np.sqrt(s0); y = np.sqrt(s1)
            K = G * m[a] * m[b]
            g = K / (x * y * (x + y))
            dgdy = -K * (x + 2 * y) / (x * y * y * (x + y) ** 2)
            gp = dgdy / (2 * y)                 # dg/ds1
            r0 = (r0x, r0y, r0z); r1 = (r1x, r1y, r1z)
            for k in range(3):
                c = g * (r0[k] + r1[k])
                A[3*a+k] += c; A[3*b+k] -= c
                for l in range(3):
                    e = (r0[k] + r1[k]) * gp * 2 * r1[l] + (g if k == l else 0.0)
                    D[3*a+k, 3*a+l] += e; D[3*a+k, 3*b+l] -= e
                    D[3*b+k, 3*a+l] -= e; D[3*b+k, 3*b+l] += e

@nb.njit(cache=True)
def solve(J, b):
    """Gaussian elimination with partial pivoting, in place (b <- J^-1 b)."""
    n = b.size
    for k in range(n):
        piv = k
        for i in range(k + 1, n):
            if abs(J[i, k]) > abs(J[piv, k]):
                piv = i
        if piv != k:
            for j in range(n):
                J[k, j], J[piv, j] = J[piv, j], J[k, j]
            b[k], b[piv] = b[piv], b[k]
        for i in range(k + 1, n):
            f = J[i, k] / J[k, k]
            for j in range(k, n):
                J[i, j] -= f * J[k, j]
            b[i] -= f * b[k]
    for k in range(n - 1, -1, -1):
        t = b[k]
        for j in range(k + 1, n):
            t -= J[k, j] * b[j]
        b[k] = t / J[k, k]


@nb.njit(cache=True)
def hand_run(y0, h, steps, m, G, newton):
    n = m.size; d = 3 * n
    Y = np.empty((steps + 1, 2 * d)); Y[0] = y0
    q = y0[:d].copy(); p = y0[d:].copy()
    minv = np.empty(d)
    for a in range(n):
        minv[3*a:3*a+3] = 1.0 / m[a]
    A = np.empty(d); D = np.empty((d, d)); J = np.empty((d, d)); R = np.empty(d); dq = np.empty(d); zero = np.zeros(d)
    its = 0
    for s in range(steps):
        dgA(q, zero, m, G, A)                 # F(q0): the SV prediction
        for i in range(d):
            dq[i] = h * minv[i] * (p[i] - h / 2 * A[i])
        prev = np.inf
        for it in range(50):
            if newton:
                dgAJ(q, dq, m, G, A, D)
                for i in range(d):
                    for j in range(d):
                        J[i, j] = h * h / 2 * minv[i] * D[i, j] + (1.0 if i == j else 0.0)
                    R[i] = dq[i] - h * minv[i] * (p[i] - h / 2 * A[i])
                solve(J, R)
                nrm = 0.0
                for i in range(d):
                    dq[i] -= R[i]
                    nrm = max(nrm, abs(R[i]))
            else:
                dgA(q, dq, m, G, A)
                nrm = 0.0
                for i in range(d):
                    new = h * minv[i] * (p[i] - h / 2 * A[i])
                    nrm = max(nrm, abs(new - dq[i]))
                    dq[i] = new
            its += 1
            if nrm == 0.0 or nrm >= prev:
                break
            prev = nrm
        dgA(q, dq, m, G, A)
        for i in range(d):
            q[i] += dq[i]; p[i] -= h * A[i]
            Y[s + 1, i] = q[i]; Y[s + 1, d + i] = p[i]
    return Y, its / steps


def _best(f, repeats=5):
    best = float("inf")
    for _ in range(repeats):
        t = time.process_time()
        out = f()
        best = min(best, time.process_time() - t)
    return best, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bodies", type=int, nargs="+", default=[2, 6])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--h", type=float, default=0.002)
    args = ap.parse_args(argv)
    h, steps = args.h, args.steps
    folder = pathlib.Path(tempfile.mkdtemp(prefix="nbody_pairloop_"))
    print(f"h = {h}, {steps} steps, CPU us per step (least of 5)")
    for n in args.bodies:
        y0 = nbody_initial(n)
        m, G = np.ones(n), 1.0
        t0 = time.perf_counter()
        scheme = discretize(nbody_system(n), "energy-momentum")
        ir = lower(scheme, "bench", f"nbody{n}")
        path = folder / f"nbody{n}_em_numba.py"
        write_atomic(path, render(ir, "numba"))
        mod = load_module(path)
        mod.integrate(y0, h, 2)
        first = time.perf_counter() - t0
        looped = "loops" if ir.loop_tables else "unrolled"
        print(f"N = {n}: generated module ({looped}), first use {first:.1f} s")
        for solver in mod.SOLVERS:
            mod.integrate(y0, h, 10, solver=solver)
            sec, _ = _best(lambda: mod.integrate(y0, h, steps, solver=solver))
            print(f"  generated  {solver:12s} {sec / steps * 1e6:8.2f}")
        for newton in (True, False):
            hand_run(y0, h, 10, m, G, newton)
            sec, (Y, its) = _best(lambda: hand_run(y0, h, steps, m, G, newton))
            label = "newton" if newton else "fixed-point"
            print(f"  hand-written {label:10s} {sec / steps * 1e6:8.2f}   ({its:.2f} iterations/step)")
        Yh, _ = hand_run(y0, h, 100, m, G, False)
        Yg = mod.integrate(y0, h, 100, solver="fixed-point")
        print(f"  max |generated - hand-written| after 100 steps: {np.abs(Yh - Yg).max():.1e}")


if __name__ == "__main__":
    main()
