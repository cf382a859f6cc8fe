"""
Proving the lecture notes' exercises with ``verify``
====================================================

The lecture notes ask for proofs: the energy–momentum method keeps H and the angular momentum
of any radial potential (Exercise 1.1), the trapezoidal rule is conjugate to the midpoint rule
(Exercise 2.1), Kahan's method keeps a modified energy. :func:`methodgen.verify` does each proof
for *your* Hamiltonian: an identity is **proved** only when it reduces to exactly 0 with no
floating point, **refuted** with an exact counterexample, and a check at sample points is
labelled **numerical** — never a proof.
"""

import methodgen as mg

# %%
# Exercise 1.1 for a potential written as a sum of radial terms
# -------------------------------------------------------------
# V(‖q‖) = −1/‖q‖ + 1/‖q‖² + exp(−‖q‖): each term is radial, so the method must keep all three
# components of L = q × p as well as H.

H = mg.Hamiltonian(
    "(px**2 + py**2 + pz**2)/2 - 1/sqrt(x**2 + y**2 + z**2) + 1/(x**2 + y**2 + z**2)"
    " + exp(-sqrt(x**2 + y**2 + z**2))",
    q=["x", "y", "z"], p=["px", "py", "pz"], name="radial")
report = mg.verify(mg.discretize(H, "energy-momentum"))
print(report.verdict, "—", len(report.certificates), "certificates")
for c in report.certificates:
    print(f"[{c.status:>9}] {c.claim[:100]}")

# %%
# In a notebook the report renders as Markdown on its own; ``report.markdown()``,
# ``report.latex()`` and ``report.to_json()`` give the text.

print(report.markdown()[:600])

# %%
# A claim that is false is refuted, with a counterexample
# -------------------------------------------------------
# Declare a quantity that is *not* a first integral — the linear momentum px + py of the
# Kepler problem — and ``verify`` refutes it at an exact rational point.

kepler = mg.Hamiltonian(
    "(px**2 + py**2 + pz**2)/2 - 1/sqrt(x**2 + y**2 + z**2)",
    q=["x", "y", "z"], p=["px", "py", "pz"], invariants={"P": "px + py"}, name="kepler_p")
bad = mg.verify(mg.discretize(kepler, "midpoint"))
print(bad.verdict)
for c in bad.certificates:
    if c.status == "refuted":
        print(c.claim[:100])
        print("   ", str(c.details)[:200])

# %%
# Exercise 2.1: the trapezoidal rule is conjugate to the midpoint rule
# --------------------------------------------------------------------
# For an arbitrary vector field f in dimension n (here n = 2), symbolically.

cubic = mg.load_scene("henon-heiles")
conj = mg.verify(mg.discretize(cubic.system, "trapezoidal"), conjugacy_dim=2)
for c in conj.certificates:
    print(f"[{c.status:>9}] {c.claim[:100]}")

# %%
# Kahan's method: the modified energy and the volume form
# -------------------------------------------------------
# For a quadratic vector field Kahan's linearly implicit method keeps a modified energy
# H̃ = H + h/3 ∇Hᵀ(I − h/2 f′)⁻¹ f (Celledoni, McLachlan, Owren & Quispel 2013).

kahan = mg.verify(mg.discretize(cubic.system, "kahan"))
print(kahan.verdict)
for c in kahan.certificates:
    print(f"[{c.status:>9}] {c.claim[:100]}")
