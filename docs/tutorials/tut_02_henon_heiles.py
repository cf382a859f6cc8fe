"""
Hénon–Heiles: a Poincaré section on the method's own map
========================================================

The Hénon–Heiles system at energy E = 1/8 has regular and chaotic orbits side by side. A
Poincaré section — the points where an orbit crosses q1 = 0 upwards — shows which is which. We
take the built-in scene, the energy–momentum method (every section point then lies on the
energy surface to round-off), and :func:`methodgen.poincare`, which locates each crossing by
solving for the sub-step τ with g(Φ_τ(yₙ)) = 0: steps of the method itself, never an
interpolant.
"""

import matplotlib.pyplot as plt
import numpy as np

import methodgen as mg

scene = mg.load_scene("henon-heiles-2d")
print(scene.system)
mod = mg.build(scene.system, "energy-momentum")

# %%
# Initial states on the energy surface
# ------------------------------------
# On the section q1 = 0 with p2 = 0, H = E fixes p1 > 0 from q2.

E = 1 / 8


def on_shell(q2, p2=0.0):
    V = q2**2 / 2 - q2**3 / 3
    return np.array([0.0, q2, np.sqrt(2 * (E - V) - p2**2), p2])


starts = [on_shell(q2) for q2 in (-0.30, -0.15, 0.0, 0.12, 0.25, 0.35, 0.45)]
print("H(y0) - E:", [float(mod.hamiltonian(y) - E) for y in starts])

# %%
# The section
# -----------
# 250 crossings of each orbit; ``sol`` is the :class:`Solution` of each run.

fig, ax = plt.subplots(figsize=(5.5, 5))
worst = 0.0
for y0 in starts:
    t, pts, sol = mg.poincare(mod, y0, 0.05, "q1 = 0, p1 > 0", crossings=250)
    ax.plot(pts[:, 1], pts[:, 3], ".", ms=1.5)
    worst = max(worst, float(np.max(np.abs(mod.hamiltonian(pts) - E))), float(np.max(np.abs(pts[:, 0]))))
ax.set(xlabel="q2", ylabel="p2", title="Hénon–Heiles, E = 1/8, section q1 = 0, p1 > 0")
print(f"largest |H − E| or |q1| at a section point: {worst:.1e}")

# %%
# Closed curves are regular (quasi-periodic) orbits; a scattered cloud is a chaotic one.
# Every point is a state of the method's own trajectory, so the energy is kept there to
# round-off, as it is at every step.
#
# The same on the command line::
#
#     methodgen run henon-heiles-2d --section "q1 = 0, p1 > 0" --steps 20000 --plot section.png
#
# What an interpolant would have done
# -----------------------------------
# Linear interpolation between the two steps around a crossing lands off the energy surface
# (an error of order h²); the located state does not.

ev = mg.section_event(mod, "q1 = 0, p1 > 0")
sol = mod.solve(starts[2], (0.0, 50.0), 0.05, events=ev)
tk = sol.t_events[0][0]
i = np.searchsorted(sol.t, tk)
w = (tk - sol.t[i - 1]) / (sol.t[i] - sol.t[i - 1])
lerp = (1 - w) * sol.y[i - 1] + w * sol.y[i]
print("H − E, located:      ", float(mod.hamiltonian(sol.y_events[0][0]) - E))
print("H − E, interpolated: ", float(mod.hamiltonian(lerp) - E))
