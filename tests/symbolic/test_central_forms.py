"""Energy-momentum recognises a function of a quadratic form however SymPy arranges it.

SymPy stores ``exp(-(x² + y²))`` as ``exp(-x² - y²)``: a function of the form
``-(x² + y²)``, i.e. of ``x² + y²`` (issue 27.8: it was refused, while
``exp(-sqrt(x² + y²))`` and ``1/(x² + y²)`` were accepted).  The scheme must still be
proved exactly by verify (H and the angular momentum L), and a non-central potential
must still be refused.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
import methodgen.symbolic.verify  # noqa: F401  (makes mg.verify callable)
from methodgen.symbolic.schemes.energy_momentum import _as_function_of_form, decompose

X, Y = sp.symbols("x y", real=True)

CENTRAL = ["-exp(-(x**2 + y**2))", "-exp(-x**2 - y**2)", "-exp(-(x**2 + y**2)/2 + 1)",
           "-3*exp(-2*x**2 - 2*y**2)", "exp(-sqrt(x**2 + y**2))", "1/(x**2 + y**2)", "-log(x**2 + y**2 + 1)"]


def _system(U: str) -> mg.Hamiltonian:
    return mg.Hamiltonian("(a**2 + b**2)/2 + " + U, q=["x", "y"], p=["a", "b"], name="central")


@pytest.mark.parametrize("U", CENTRAL)
def test_central_potential_recognised_and_proved(U):
    """Exact: each arrangement is one quadratic-form term; verify proves H and L."""
    system = _system(U)
    terms = decompose(system)
    assert terms is not None and [t.kind for t in terms] == ["quadratic-form"]
    # the form found has a positive coefficient: |q|² up to a positive factor
    E = terms[0].E
    ratio = sp.cancel(E / (X**2 + Y**2))
    assert ratio.is_number and ratio > 0
    scheme = mg.discretize(system, "energy-momentum")
    assert {"H", "L"} <= set(scheme.traits.preserved)
    report = mg.verify(scheme)
    assert report.ok and not report.undecided
    for text in ("discrete-gradient identity", "L(y1) = L(y0)"):
        (cert,) = report.find(text)
        assert cert.status == "proved", (text, cert.status)


def test_negated_form_run_keeps_energy_and_angular_momentum():
    """Numerical: the generated module keeps H and L to round-off on exp(-x² - y²)."""
    mod = mg.build(_system("-exp(-(x**2 + y**2))"), "energy-momentum")
    Y0 = np.array([0.6, -0.2, 0.1, 0.7])
    traj = mod.integrate(Y0, 0.05, 200)
    H = mod.hamiltonian(traj)
    L = mod.invariants(traj)["L"]
    assert np.abs(H - H[0]).max() < 1e-14 and np.abs(L - L[0]).max() < 1e-14


@pytest.mark.parametrize("U", ["-exp(-x**2 - y**2)*x", "-exp(-x**2 - y**3)", "-exp(-x**2 - y**2 + x)"])
def test_non_central_potential_still_refused(U):
    """Negative control: U not a function of a quadratic form (or a sum of allowed terms)."""
    with pytest.raises(mg.MethodgenError, match="energy-momentum needs"):
        mg.discretize(_system(U), "energy-momentum")


def test_a_wrong_form_is_not_accepted():
    """Negative control: the sign flip is checked, not assumed: exp(-x² + y²) is a function
    of x² - y² (accepted, with that indefinite form), never of x² + y²."""
    found = _as_function_of_form(sp.exp(-X**2 + Y**2), [X, Y])
    assert found is not None
    E, s, V = found
    assert sp.expand(E - (X**2 - Y**2)) == 0
    assert sp.simplify(V.xreplace({s: E}) - sp.exp(-X**2 + Y**2)) == 0
    assert _as_function_of_form(sp.exp(-X**2 - Y**2) * X, [X, Y]) is None
