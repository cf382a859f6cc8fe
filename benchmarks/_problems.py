"""The benchmarks' problems by name: a built-in scene, ``fpu<N>`` or ``toda<N>``.

``fpu<N>``: the FPU-beta chain of N particles with fixed ends, written with indexed sums
(β = 1; y0 the lowest mode, q_i = sin(π i/(N+1)), p = 0; h = 0.05).  ``toda<N>``: the periodic
Toda ring of N, ``Σ p_i²/2 + Σ exp(q_i - q_(i mod N + 1))`` (y0 a small wave; h = 0.05).
Imported by the probes the benchmarks run in fresh processes (``build_targets.py``,
``first_use_phases.py``): they put this folder on ``sys.path``.  Not a test.
"""

from __future__ import annotations

import numpy as np

import methodgen as mg

HERE = __file__.rsplit("/", 1)[0]


def problem(name: str):
    """``(system, y0, h)`` for ``name``."""
    if name.startswith("fpu"):
        n = int(name[3:])
        H = (f"Sum(p[i]**2/2, i, 1, {n}) + q[1]**2/2 + beta*q[1]**4/4 + Sum((q[i+1] - q[i])**2/2 "
             f"+ beta*(q[i+1] - q[i])**4/4, i, 1, {n - 1}) + q[{n}]**2/2 + beta*q[{n}]**4/4")
        system = mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                                params={"beta": 1.0}, name=name)
        y0 = np.array([np.sin(np.pi * i / (n + 1)) for i in range(1, n + 1)] + [0.0] * n)
        return system, y0, 0.05
    if name.startswith("toda"):
        n = int(name[4:])
        H = f"Sum(p[i]**2/2, i, 1, {n}) + Sum(exp(q[i] - q[i % {n} + 1]), i, 1, {n})"
        system = mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                                name=name)
        y0 = np.array([0.1 * np.sin(2 * np.pi * i / n) for i in range(n)]
                      + [0.2 * np.cos(2 * np.pi * i / n) for i in range(n)])
        return system, y0, 0.05
    sc = mg.load_scene(name)
    return sc.system, np.array(sc.y0, dtype=float), sc.h
