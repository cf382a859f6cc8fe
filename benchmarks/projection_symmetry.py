"""Symmetry defect and cost of the two ways to solve the symmetric projection's equations.

Not a test: run it and read the table.

    python benchmarks/projection_symmetry.py

(a) what the generated modules do: Φ_h re-evaluated at every iterate of λ;
(b) the first-order expansion Φ_h(y0 + G(y0)ᵀλ) ≈ Φ_h(y0) + G(y0)ᵀλ: Φ_h once per step, the
    iteration on λ then costs only evaluations of g and G.
(Hénon–Heiles has unit masses: the metric w is 1, D = Gᵀ.)  For each: max |Φ_{-h}(Φ_h(y0)) - y0| over 200 start points along the Hénon–Heiles orbit
(H = 1/8), and Φ_h evaluations per step.  numpy backend, from the module's kernels.
"""

from __future__ import annotations

import numpy as np

import methodgen as mg

Y0 = np.array([0.0, 0.0, 0.4330127018922193, 0.25])


def expanded_step(mod, y, h):
    """(b): Φ_h once; y1 = Φ_h(y0) + G(y0)ᵀλ + G(y1)ᵀλ, g(y1) = g(y0), λ by Newton."""
    v0 = mod._s_proj(list(y), ())
    tgt, G0 = v0[0], np.array(v0[1:5])
    yh = np.array(mod._base_flow(list(y), [0.0] * 4, h, ())[0])
    lam = 0.0
    y1 = yh
    for _ in range(50):
        G1 = np.array(mod._s_proj(list(y1), ())[1:5])
        y1 = yh + (G0 + G1) * lam
        v = mod._s_proj(list(y1), ())
        d = (tgt - v[0]) / (np.array(v[1:5]) @ (G0 + np.array(v[1:5])))
        lam += d
        if abs(d) < 1e-19:
            break
    return yh + (G0 + np.array(mod._s_proj(list(y1), ())[1:5])) * lam


def main():
    hh = mg.load_scene("henon-heiles-2d").run_system
    print("order  h     (a) re-evaluated: defect, Φ per step   (b) expanded: defect, Φ per step")
    for order, h in ((2, 0.1), (4, 0.2), (6, 0.3)):
        mod = mg.build(hh, "stormer-verlet", order=order, project="energy")
        starts = mod.integrate(Y0, h, 200)
        info = {}
        worst_a = 0.0
        for y in starts[:-1]:
            fwd = mod.integrate(y, h, 1, info=info)[-1]
            worst_a = max(worst_a, float(np.max(np.abs(mod.integrate(fwd, -h, 1)[-1] - y))))
        its = mod.integrate(Y0, h, 200, info=info) is not None and info["newton_iterations"].mean()
        worst_b = max(float(np.max(np.abs(expanded_step(mod, expanded_step(mod, y, h), -h) - y)))
                      for y in starts[:-1])
        print(f"{order:5d}  {h:<5g} {worst_a:.2e}, {its:.2f}                        {worst_b:.2e}, 1")


if __name__ == "__main__":
    main()
