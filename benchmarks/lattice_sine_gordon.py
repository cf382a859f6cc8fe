"""Sine-Gordon on a periodic lattice (issue 40): methodgen's lattice module against hand-written
code and the peers, side by side in one run.  A benchmark, not a test (the hand-written AVF
is numba code: install numba to run it; methodgen itself does not use numba).

    python benchmarks/lattice_sine_gordon.py [--sizes 256,4096] [--steps 200] [--peers]

Measured:

* **build**: a fresh cache, a fresh interpreter (`python -c` in a subprocess): import methodgen,
  parse, derive, print, write and import the module -- for each N, and whether the module file is
  the same for every N (it is one module);
* **per step** (warm, min of 5 repeats): the methodgen module (numpy, Newton with block cyclic
  reduction; "newton" and "simplified"), and a hand-written AVF in numba: q eliminated to one
  scalar cyclic-tridiagonal Newton system per iteration (Thomas + Sherman–Morrison), what a
  careful person writes by hand for this one equation;
* **energy**: relative |H - H0| over the steps;
* with ``--peers``, N = 256 to T = 10 at equal final error: scipy's DOP853 and Radau (with
  ``jac_sparsity``) and heyoka's ``taylor_adaptive`` in compact mode (build and run), each with its
  energy error, against a reference (DOP853 at rtol 1e-13).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

L = 2 * np.pi
H_TEXT = ("Sum(p[i]**2/2, i, 1, N) + Sum((q[i % N + 1] - q[i])**2*N**2/(2*L**2), i, 1, N) "
          "+ Sum(1 - cos(q[i]), i, 1, N)")


def y0_of(n):
    x = np.arange(n) * L / n
    return np.concatenate([2 * np.sin(x), 0.5 * np.cos(x)])


def energy(y, n):
    q, p = y[:n], y[n:]
    return float(np.sum(p**2 / 2 + (np.roll(q, -1) - q)**2 * n**2 / (2 * L**2) + 1 - np.cos(q)))


def cold_build(n: int, backend: str) -> tuple[float, str]:
    """Seconds for import + build + the first step in a fresh interpreter with an empty module
    cache (the compiled loop's machine-code cache too); the module's path."""
    cache = tempfile.mkdtemp(prefix="mg-lattice-")
    code = ("import time; t=time.perf_counter(); import methodgen as mg; import numpy as np;"
            f"lat = mg.Lattice({H_TEXT!r}, params={{'L': {L!r}}}, name='sine-gordon');"
            f"m = mg.build_lattice(lat, 'avf', backend={backend!r});"
            f"m.integrate(np.zeros({2 * n}), 0.01, 1);"
            "print(time.perf_counter()-t, m.__file__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "METHODGEN_CACHE": cache}).stdout.split()
    return float(out[0]), out[1]


def per_step(fn, repeats=5) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        k = fn()
        best = min(best, (time.perf_counter() - t0) / k)
    return best


# --- a hand-written AVF step (numba): p eliminated, a scalar cyclic tridiagonal Newton system ------

def handwritten():
    import numba

    @numba.njit(cache=True)
    def sdd(a, b):          # ∫₀¹ sin(a + s(b - a)) ds, and its b-derivative
        d = b - a
        if abs(d) < 1e-4:
            m = 0.5 * (a + b)
            s = math.sin(m) * (1 - d * d / 24)
            ds = 0.5 * math.cos(m) - d * math.sin(m) / 12
            return s, ds
        s = (math.cos(a) - math.cos(b)) / d
        return s, (math.sin(b) - s) / d

    @numba.njit(cache=True)
    def cyclic_tridiag(a, b, c, r, x, work):
        # a[j] x[j-1] + b[j] x[j] + c[j] x[j+1] = r[j], indices mod n (Sherman–Morrison)
        n = b.shape[0]
        gamma = -b[0]
        bb = work[0]
        u = work[1]
        cp = work[2]
        y = work[3]
        z = work[4]
        for j in range(n):
            bb[j] = b[j]
        bb[0] -= gamma
        bb[n - 1] -= a[0] * c[n - 1] / gamma
        for j in range(n):
            u[j] = 0.0
        u[0] = gamma
        u[n - 1] = c[n - 1]
        # Thomas for y (rhs r) and z (rhs u)
        cp[0] = c[0] / bb[0]
        y[0] = r[0] / bb[0]
        z[0] = u[0] / bb[0]
        for j in range(1, n):
            m = bb[j] - a[j] * cp[j - 1]
            cp[j] = c[j] / m
            y[j] = (r[j] - a[j] * y[j - 1]) / m
            z[j] = (u[j] - a[j] * z[j - 1]) / m
        for j in range(n - 2, -1, -1):
            y[j] -= cp[j] * y[j + 1]
            z[j] -= cp[j] * z[j + 1]
        fact = (y[0] + a[0] * y[n - 1] / gamma) / (1.0 + z[0] + a[0] * z[n - 1] / gamma)
        for j in range(n):
            x[j] = y[j] - fact * z[j]

    @numba.njit(cache=True)
    def run(y, h, steps):
        n = y.shape[0] // 2
        k = n * n / (L * L)
        q0 = y[:n].copy()
        p0 = y[n:].copy()
        q1 = np.empty(n)
        a = np.empty(n)
        b = np.empty(n)
        c = np.empty(n)
        r = np.empty(n)
        dq = np.empty(n)
        work = np.empty((5, n))
        s = np.empty(n)
        for _ in range(steps):
            for j in range(n):
                q1[j] = q0[j] + h * p0[j]
            for it in range(50):
                # q1 = q0 + h p0 + h²/2 [k Δ(q0 + q1)/2 - S(q0, q1)]
                big = 0.0
                for j in range(n):
                    jm, jp = (j - 1) % n, (j + 1) % n
                    lap = k * 0.5 * ((q0[jp] + q1[jp]) - 2 * (q0[j] + q1[j]) + (q0[jm] + q1[jm]))
                    sv, ds = sdd(q0[j], q1[j])
                    s[j] = sv
                    r[j] = -(q1[j] - q0[j] - h * p0[j] - 0.5 * h * h * (lap - sv))
                    a[j] = -0.25 * h * h * k
                    c[j] = -0.25 * h * h * k
                    b[j] = 1.0 + 0.5 * h * h * k + 0.5 * h * h * ds
                cyclic_tridiag(a, b, c, r, dq, work)
                for j in range(n):
                    q1[j] += dq[j]
                    big = max(big, abs(dq[j]))
                if big <= 1e-15 * 8:
                    break
            for j in range(n):
                jm, jp = (j - 1) % n, (j + 1) % n
                lap = k * 0.5 * ((q0[jp] + q1[jp]) - 2 * (q0[j] + q1[j]) + (q0[jm] + q1[jm]))
                sv, _ = sdd(q0[j], q1[j])
                p1 = p0[j] + h * (lap - sv)
                p0[j] = p1
            for j in range(n):
                q0[j] = q1[j]
        out = np.empty(2 * n)
        out[:n] = q0
        out[n:] = p0
        return out

    return run


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="256,4096")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--peers", action="store_true")
    args = ap.parse_args(argv)
    import methodgen as mg

    sizes = [int(s) for s in args.sizes.split(",")]
    out = {"load": os.getloadavg()[0], "sizes": {}}
    from methodgen.codegen.store import untagged

    files = set()
    for n in sizes:
        out["sizes"][n] = {}
        for backend in ("numpy", "compiled"):
            sec, path = cold_build(n, backend)
            files.add((backend, untagged(open(path).read())))
            out["sizes"][n][f"cold_build_{backend}_s"] = sec
    out["one_module_for_every_size"] = len(files) == 2
    lat = mg.Lattice(H_TEXT, params={"L": L}, name="sine-gordon")
    mod = mg.build_lattice(lat, "avf", path=os.path.join(tempfile.mkdtemp(), "sg.py"))
    comp = mg.build_lattice(lat, "avf", path=os.path.join(tempfile.mkdtemp(), "sgc.py"), backend="compiled")
    hand = handwritten()
    h, steps = 0.01, args.steps
    for n in sizes:
        y0 = y0_of(n)
        hand(y0, h, 2)
        rec = out["sizes"][n]
        for solver in ("newton", "simplified"):
            rec[f"methodgen_numpy_{solver}_us"] = 1e6 * per_step(
                lambda: (mod.integrate(y0, h, steps // 10, solver=solver), steps // 10)[1], 3)
        for solver in ("newton", "simplified"):
            rec[f"methodgen_compiled_{solver}_us"] = 1e6 * per_step(
                lambda: (comp.integrate(y0, h, steps, solver=solver, save_every=steps), steps)[1])
        rec["handwritten_numba_us"] = 1e6 * per_step(lambda: (hand(y0, h, steps), steps)[1])
        rec["ratio_compiled_to_handwritten"] = min(rec["methodgen_compiled_newton_us"],
                                                   rec["methodgen_compiled_simplified_us"]) / rec["handwritten_numba_us"]
        tc = comp.integrate(y0, h, steps, save_every=steps)
        tr = mod.integrate(y0, h, steps, save_every=steps)
        rec["max_diff_compiled_vs_numpy"] = float(np.max(np.abs(tc[-1] - tr[-1])))
        yh = hand(y0, h, steps)
        rec["max_diff_methodgen_vs_handwritten"] = float(np.max(np.abs(tr[-1] - yh)))
        rec["methodgen_energy_rel"] = abs(energy(tr[-1], n) - energy(y0, n)) / energy(y0, n)
        rec["handwritten_energy_rel"] = abs(energy(yh, n) - energy(y0, n)) / energy(y0, n)
    if args.peers:
        out["peers"] = peers(comp)
    print(json.dumps(out, indent=1))


def peers(mod, n=256, T=10.0):
    """N = 256 to T = 10: methodgen's compiled AVF at h = 0.01 against DOP853, Radau and heyoka
    (compact mode), each at the loosest tolerance reaching methodgen's final error."""
    from scipy.integrate import solve_ivp
    from scipy.sparse import diags, bmat, eye

    k = n * n / (L * L)
    y0 = y0_of(n)

    def f(t, y):
        q, p = y[:n], y[n:]
        return np.r_[p, k * (np.roll(q, -1) - 2 * q + np.roll(q, 1)) - np.sin(q)]

    ref = solve_ivp(f, (0, T), y0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    res = {"N": n, "T": T}
    steps = 1000
    mod.integrate(y0, T / steps, 2)                  # compiled before the clock starts
    t0 = time.perf_counter()
    yT = mod.integrate(y0, T / steps, steps, save_every=steps)[-1]
    err = float(np.max(np.abs(yT - ref)))
    res["methodgen_avf"] = {"steps": steps, "seconds": time.perf_counter() - t0, "error": err,
                            "energy_rel": abs(energy(yT, n) - energy(y0, n)) / energy(y0, n)}
    for method, extra in (("DOP853", {}), ("Radau", {"jac_sparsity": bmat([[None, eye(n)], [diags(
            [1, 1, 1, 1, 1], [-n + 1, -1, 0, 1, n - 1], shape=(n, n)), None]])})):
        for tol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
            t0 = time.perf_counter()
            sol = solve_ivp(f, (0, T), y0, method=method, rtol=tol, atol=tol, **extra)
            e = float(np.max(np.abs(sol.y[:, -1] - ref)))
            if e <= err:
                res[method] = {"rtol": tol, "seconds": time.perf_counter() - t0, "error": e, "nfev": sol.nfev,
                               "energy_rel": abs(energy(sol.y[:, -1], n) - energy(y0, n)) / energy(y0, n)}
                break
    try:
        import heyoka as hy
    except ImportError:
        return res
    qs = hy.make_vars(*[f"q{j}" for j in range(n)])
    ps = hy.make_vars(*[f"p{j}" for j in range(n)])
    sys_ = [(qs[j], ps[j]) for j in range(n)]
    sys_ += [(ps[j], k * (qs[(j + 1) % n] - 2 * qs[j] + qs[(j - 1) % n]) - hy.sin(qs[j])) for j in range(n)]
    for tol in (1e-6, 1e-8, 1e-10, 1e-12, 1e-15):
        t0 = time.perf_counter()
        ta = hy.taylor_adaptive(sys_, list(y0), compact_mode=True, tol=tol)
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        ta.propagate_until(T)
        run = time.perf_counter() - t0
        e = float(np.max(np.abs(ta.state - ref)))
        if e <= err:
            res["heyoka_compact"] = {"tol": tol, "build_s": build, "seconds": run, "error": e,
                                     "energy_rel": abs(energy(ta.state, n) - energy(y0, n)) / energy(y0, n)}
            break
    return res


if __name__ == "__main__":
    main()
