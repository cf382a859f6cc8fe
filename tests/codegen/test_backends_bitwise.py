"""The numpy and the compiled backend give the same bits.

An integer power ``u**n`` (and a half-integer one, ``sqrt(u)**k``) is printed in every
flavour as the products the compiled kernels compute for ``**``: exponentiation by squaring
(:func:`methodgen.codegen.kir_build._power_by_squaring`).  CPython's float ``**`` and numpy's
``power`` call libm's ``pow``, which rounds otherwise for 0.1 % of squares and about a quarter
of cubes, so a numpy module used to agree with the compiled one to round-off only.  Now one
trajectory of a numpy module is bitwise the compiled module's on each method kind: explicit
compositions, Newton (energy-momentum, midpoint composed, AVF, Gauss), constrained (RATTLE),
time-transformed (the log Hamiltonian), with powers, roots and ``sin``/``cos``.

Control: with powers printed as ``**`` again (:data:`MAX_PRODUCT_POWER` = 1 for the numpy
module; the compiled kernels still square) the trajectories differ.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen import kir_build, lower

HH = mg.Hamiltonian("(p1**2 + p2**2)/2 + (q1**2 + q2**2)/2 + q1**2*q2 - q2**3/3",
                    q=["q1", "q2"], p=["p1", "p2"], name="hh")
KEPLER = mg.Hamiltonian("(px**2 + py**2 + pz**2)/(2*m) - k/sqrt(x**2 + y**2 + z**2)",
                        q=["x", "y", "z"], p=["px", "py", "pz"], params={"m": 1.0, "k": 1.0}, name="kep")
PENDULUM = mg.Hamiltonian("p**2/2 - cos(q)", q=["q"], p=["p"], name="pend")
QUARTIC = mg.Hamiltonian("p**2/2 + q**4/4 - q**2/2 + q**5/7", q=["q"], p=["p"], name="quartic")

HH_Y0 = np.array([0.0, 0.1, 0.35, 0.2])
KEPLER_Y0 = np.array([0.4, 0.0, 0.1, 0.0, math.sqrt(3.5), 0.2])

CASES = {
    "hh-sv10": (HH, "stormer-verlet", {"order": 10}, HH_Y0, 0.05, 400),
    "hh-em8": (HH, "energy-momentum", {"order": 8}, HH_Y0, 0.05, 200),
    "hh-midpoint4": (HH, "midpoint", {"order": 4}, HH_Y0, 0.05, 200),
    "hh-gauss3": (HH, "gauss", {"stages": 3}, HH_Y0, 0.05, 200),
    "kepler-em": (KEPLER, "energy-momentum", {}, KEPLER_Y0, 0.01, 600),
    "kepler-midpoint": (KEPLER, "midpoint", {}, KEPLER_Y0, 0.01, 600),
    "kepler-sv6": (KEPLER, "stormer-verlet", {"order": 6}, KEPLER_Y0, 0.01, 600),
    "pendulum-avf": (PENDULUM, "avf", {}, np.array([2.5, 0.3]), 0.1, 400),
    "quartic-itoh-abe": (QUARTIC, "itoh-abe", {}, np.array([0.6, 0.3]), 0.05, 400),
}


def _modules(tmp_path, case, tag=""):
    system, method, kw, *_ = CASES[case]
    scheme = mg.discretize(system, method, **kw)
    stem = f"{case}{tag}".replace("-", "_")
    return (mg.generate(scheme, tmp_path / f"{stem}_np.py", backend="numpy"),
            mg.generate(scheme, tmp_path / f"{stem}_c.py", backend="numba"))


@pytest.mark.parametrize("case", sorted(CASES))
def test_numpy_trajectory_is_bitwise_the_compiled_one(tmp_path, case):
    *_, y0, h, steps = CASES[case]
    mn, mc = _modules(tmp_path, case)
    a = mn.integrate(y0, h, steps)
    c = mc.integrate(y0, h, steps)
    assert np.all(np.isfinite(a)) and np.array_equal(a, c)


@pytest.mark.parametrize("case", ["hh-sv10", "hh-em8", "kepler-em", "kepler-midpoint"])
def test_numpy_batch_is_bitwise_its_single_trajectories(tmp_path, case):
    *_, y0, h, steps = CASES[case]
    mn, _ = _modules(tmp_path, case)
    Y0 = np.stack([y0, y0 * (1 + 1e-3)])
    b = mn.integrate(Y0, h, steps)
    for i in range(2):
        assert np.array_equal(b[:, i], mn.integrate(Y0[i], h, steps))


def test_log_hamiltonian_numpy_is_bitwise_compiled(tmp_path):
    logh = mg.time_transform(KEPLER, form="log")
    scheme = mg.discretize(logh, "stormer-verlet", order=4)
    mn = mg.generate(scheme, tmp_path / "logh_np.py", backend="numpy")
    mc = mg.generate(scheme, tmp_path / "logh_c.py", backend="numba")
    y0 = np.array([0.1, 0.0, 0.0, 0.0, 1.9, 0.0])          # e = 0.9 near pericentre
    Y = mn.initial_state(np.array([0.1, 0.0, 0.0, 0.0, math.sqrt(19.0), 0.0]), 0.0)
    assert np.array_equal(Y, mc.initial_state(np.array([0.1, 0.0, 0.0, 0.0, math.sqrt(19.0), 0.0]), 0.0))
    a, c = mn.integrate(Y, 0.02, 500), mc.integrate(Y, 0.02, 500)
    assert np.all(np.isfinite(a)) and np.array_equal(a, c) and y0.shape == (6,)


def test_rattle_numpy_is_bitwise_compiled(tmp_path):
    pend = mg.Hamiltonian("(px**2 + py**2)/2 + y", q=["x", "y"], p=["px", "py"],
                          constraints=["x**2 + y**2 - 1"], name="cpend")
    scheme = mg.discretize(pend, "rattle")
    mn = mg.generate(scheme, tmp_path / "rattle_np.py", backend="numpy")
    mc = mg.generate(scheme, tmp_path / "rattle_c.py", backend="numba")
    y0 = np.array([math.sin(1.0), -math.cos(1.0), 0.3 * math.cos(1.0), 0.3 * math.sin(1.0)])
    a, c = mn.integrate(y0, 0.05, 400), mc.integrate(y0, 0.05, 400)
    assert np.all(np.isfinite(a)) and np.array_equal(a, c)


@pytest.mark.parametrize("case", ["hh-sv10", "hh-em8"])
def test_control_powers_through_pow_differ(tmp_path, monkeypatch, case):
    """The test above can fail: the numpy module printed with ``**`` (libm's pow) for every
    power, against the compiled kernels' squaring, is not bitwise the compiled run."""
    *_, y0, h, steps = CASES[case]
    _, mc = _modules(tmp_path, case)
    monkeypatch.setattr(kir_build, "MAX_PRODUCT_POWER", 1)
    monkeypatch.setattr(lower, "MAX_PRODUCT_POWER", 1)
    lower._CSE_CACHE.clear()
    system, method, kw, *_ = CASES[case]
    mn = mg.generate(mg.discretize(system, method, **kw), tmp_path / "pow_np.py", backend="numpy")
    assert "**" in (tmp_path / "pow_np.py").read_text().split("def _s_post", 1)[1][:4000]
    a, c = mn.integrate(y0, h, steps), mc.integrate(y0, h, steps)
    np.testing.assert_allclose(a, c, rtol=0, atol=1e-12)      # the same method
    assert not np.array_equal(a, c)                            # other bits
