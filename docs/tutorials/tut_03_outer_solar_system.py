"""
The outer solar system: Wisdom–Holman splittings
================================================

The Sun, Jupiter, Saturn, Uranus, Neptune and Pluto (Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, Sect. I.2.4). With one dominant mass, H = H_K + H_I splits into Kepler
problems in Jacobi coordinates, solved exactly, and a small interaction of the size of the mass
ratio ε ≈ 1e-3. The splittings of Laskar & Robutel (2001) then have errors O(ε h^2n + ε² h²):
steps of months instead of days. We compare one of them with a generated energy–momentum
solver at the scene's own step.
"""

import matplotlib.pyplot as plt
import numpy as np

import methodgen as mg

scene = mg.load_scene("outer-solar-system")
y0 = np.array(scene.y0)
print(scene.description)

# %%
# A splitting with its corrector
# ------------------------------
# :func:`methodgen.wisdom_holman` needs no generated module (the masses are data); its claims
# are certified by ``methodgen verify outer-solar-system --method sbab4``.

wh = mg.wisdom_holman(scene, "sbab4")
print(wh.TRAITS["error"], f"epsilon = {wh.epsilon:.3g}")
T = 200_000.0                                   # days (about 550 years)
h_wh = 180.0
Y_wh = wh.integrate(y0, h_wh, int(T / h_wh), save_every=50)

# %%
# The same interval with the energy–momentum method at h = 10 days
# -----------------------------------------------------------------
# It keeps the energy and the total angular momentum exactly, but its error in the positions
# is second order in h.

em = mg.build(scene.system, "energy-momentum")
Y_em = em.integrate(y0, 10.0, 20_000, save_every=1000)
print("energy-momentum: relative |ΔH| =",
      float(np.max(np.abs(em.hamiltonian(Y_em) / em.hamiltonian(y0) - 1))))

# %%
# Orbits
# ------
# State layout: the positions of the six bodies, then their momenta (3 coordinates each).

names = ["Sun", "Jupiter", "Saturn", "Uranus", "Neptune", "Pluto"]
fig, ax = plt.subplots(figsize=(5.5, 5.5))
for b, name in enumerate(names):
    ax.plot(Y_wh[:, 3 * b], Y_wh[:, 3 * b + 1], lw=0.6, label=name)
ax.set_aspect("equal")
ax.set(xlabel="x [AU]", ylabel="y [AU]", title=f"sbab4, h = {h_wh:g} days, T = {T:g} days")
ax.legend(fontsize=7, loc="upper right")

# %%
# Which final state is right? Halving the splitting's step changes it by far less than the
# distance between the two methods: the difference is the energy–momentum method's phase
# error (second order in h, growing linearly in time), not the splitting's.


def positions(Y):
    return np.linalg.norm((Y[-1, :18]).reshape(6, 3) - (Y_ref[-1, :18]).reshape(6, 3), axis=1)


Y_ref = wh.integrate(y0, h_wh / 2, int(2 * T / h_wh), save_every=100)
print("sbab4, h = 180 d, against h = 90 d [AU]:", np.array2string(positions(Y_wh), precision=2))
print("energy-momentum, h = 10 d, against it [AU]:", np.array2string(positions(Y_em), precision=2))
