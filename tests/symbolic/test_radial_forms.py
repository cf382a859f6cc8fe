"""Exercise 1.1 (3) of the lecture notes, however U = V(|q|) is written.

The energy–momentum method keeps every component of q × p for a radial potential.  SymPy
distributes a rational factor over a sum, so ``r⁴/4 - r²/2`` arrives as one term of the
form ``x² + y² + z²`` and three one-coordinate terms; the method then claimed only H.  Each
way of writing the same radial V below must give the claim, and ``verify`` must prove it
for the method (``L(y1) = L(y0)``), listed apart from the exact flow's ``{L, H} = 0``.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.symbolic.schemes import energy_momentum as em
from methodgen.symbolic.verify.report import FLOW, METHOD

P = "(px**2 + py**2 + pz**2)/2"
R2 = "(x**2 + y**2 + z**2)"
RADIAL = {
    "sum of radial terms": f"{R2}**2/4 - {R2}/2",
    "powers of sqrt": f"sqrt({R2})**4/4 - sqrt({R2})**2/2",
    "Kepler plus harmonic": f"-1/sqrt({R2}) + {R2}/2",
    "one product": f"{R2}*({R2} - 2)/4",
    "expanded quadratic": "x**2/2 + y**2/2 + z**2/2",
    "added quadratic terms and a constant": f"{R2}**2/4 - x**2/2 - y**2/2 - z**2/2 + 7",
    "with a parameter": f"k*{R2}**3 - x**2 - y**2 - z**2",
}
#: not radial (the quadratic part is anisotropic): no angular momentum may be claimed
NOT_RADIAL = {
    "anisotropic quadratic part": f"{R2}**2/4 - x**2/2 - y**2/2 - z**2",
    "anisotropic form": "(x**2 + 2*y**2 + z**2)**2 - x**2 - y**2 - z**2",
}


def _system(U):
    return mg.Hamiltonian(f"{P} + {U}", q=["x", "y", "z"], p=["px", "py", "pz"], params={"k": 0.25},
                          name="radial")


def _method_proofs(report):
    return {c.claim.split("(y1)")[0].split(": ")[-1] for c in report.certificates
            if c.subject == METHOD and c.status == "proved" and "(y1) = " in c.claim
            and c.claim.split(": ")[-1].startswith("L")}


@pytest.mark.parametrize("U", list(RADIAL.values()), ids=list(RADIAL))
def test_radial_potential_claims_and_proves_angular_momentum(U):
    scheme = mg.discretize(_system(U), "energy-momentum")
    assert scheme.traits.preserved == ("H", "Lx", "Ly", "Lz")
    report = mg.verify(scheme)
    assert report.ok, str(report)
    assert _method_proofs(report) == {"Lx", "Ly", "Lz"}, str(report)


@pytest.mark.parametrize("U", list(NOT_RADIAL.values()), ids=list(NOT_RADIAL))
def test_non_radial_control_claims_no_angular_momentum(U):
    scheme = mg.discretize(_system(U), "energy-momentum")
    assert scheme.traits.preserved == ("H",)
    assert _method_proofs(mg.verify(scheme)) == set()


def test_negative_control_terms_as_written_miss_the_claim(monkeypatch):
    """Without the grouping (the terms as SymPy writes them) the sum of radial terms
    claims only H: the test above can fail."""
    monkeypatch.setattr(em, "grouped_terms", lambda terms, q: list(terms))
    scheme = mg.discretize(_system(RADIAL["sum of radial terms"]), "energy-momentum")
    assert scheme.traits.preserved == ("H",)


def test_grouped_terms_groups_only_functions_of_one_form():
    import sympy as sp

    x, y, z, w = sp.symbols("x y z w", real=True)
    q = [x, y, z, w]
    r2 = x**2 + y**2 + z**2
    terms = list(sp.Add.make_args(r2**2 / 4 - r2 / 2 + sp.cos(w)))
    got = em.grouped_terms(terms, q)
    assert len(got) == 2 and sp.cos(w) in got
    assert sp.expand(sum(got) - sum(terms)) == 0
    # anisotropic quadratic part: nothing is grouped
    terms = list(sp.Add.make_args(r2**2 / 4 - x**2 / 2 - y**2 / 2 - z**2))
    assert em.grouped_terms(terms, q) == terms


def test_angular_momentum_kept_in_a_run():
    """Numerical (not a proof): over 2000 steps the method keeps q × p to round-off for the
    sum of radial terms, the trajectory far from a circle."""
    scheme = mg.discretize(_system(RADIAL["sum of radial terms"]), "energy-momentum")
    mod = mg.generate(scheme)
    traj = mod.integrate(np.array([1.2, 0.1, -0.3, 0.05, 0.7, 0.4]), h=0.05, steps=2000)
    inv = mod.invariants(traj)
    for name in ("Lx", "Ly", "Lz"):
        drift = float(np.max(np.abs(inv[name] - inv[name][0])))
        assert drift < 1e-13, (name, drift)


def test_report_lists_flow_facts_apart_from_the_method():
    """{L, H} = 0 is a fact of the ODE: marked as such and rendered under its own heading,
    after every certificate of the method's own."""
    from methodgen.symbolic.verify.report import FLOW_HEADING

    report = mg.verify(mg.discretize(_system(RADIAL["Kepler plus harmonic"]), "energy-momentum"))
    flow = [c for c in report.certificates if c.subject == FLOW]
    assert flow and all("{" in c.claim and ", H}" in c.claim for c in flow)
    assert not [c for c in report.certificates if c.subject == METHOD and ", H} = 0" in c.claim]
    text = str(report)
    head = text.index(FLOW_HEADING)
    for c in report.certificates:
        assert (text.index(c.claim) > head) == (c.subject == FLOW), c.claim
    assert FLOW_HEADING[1:] in report.markdown() and report.to_dict()["certificates"][0]["subject"]
