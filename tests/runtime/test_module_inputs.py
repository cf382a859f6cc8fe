"""Types at the generated module's interface (issue 13, items 3 and 6).

One rule for numbers everywhere in a generated module: real numbers -- Python int and
float, numpy integer and floating scalars and arrays -- never bool, str or complex
(numpy would convert them silently: a complex y0 lost its imaginary part with only a
ComplexWarning, ``out=`` of dtype int truncated the trajectory).  Both backends share
this code (templates/_inputs.py.j2); it runs before anything is compiled.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import methodgen as mg

Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])


@pytest.fixture(scope="module")
def both(modules, kepler, tmp_path_factory):
    """The numpy module and, if llvmlite is installed, the compiled module (never compiled here:
    every call below is refused before the compiled loop runs)."""
    scheme, np_mod = modules(kepler, "energy-momentum")
    mods = [np_mod]
    try:
        import llvmlite  # noqa: F401
    except ImportError:
        return mods
    path = tmp_path_factory.mktemp("numba_inputs") / "kepler_energy_momentum_numba.py"
    return mods + [mg.generate(scheme, path, backend="numba")]


@pytest.fixture(autouse=True)
def _no_silent_conversion():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a ComplexWarning would fail the test
        yield


def test_out_must_be_float64_of_the_right_shape(both):
    for mod in both:
        with pytest.raises(TypeError, match=r"float64 array of shape \(4, 6\).*got dtype int64"):
            mod.integrate(Y0, 0.01, 3, out=np.zeros((4, 6), dtype=int))
        with pytest.raises(TypeError, match="float64"):
            mod.integrate(Y0, 0.01, 3, out=np.zeros((4, 6), dtype=np.float32))
        with pytest.raises(TypeError, match="float64"):
            mod.integrate(Y0, 0.01, 3, out=[[0.0] * 6] * 4)
        with pytest.raises(ValueError, match=r"shape \(4, 6\)"):
            mod.integrate(Y0, 0.01, 3, out=np.zeros((3, 6)))
        ro = np.zeros((4, 6))
        ro.flags.writeable = False
        with pytest.raises(ValueError, match="writeable"):
            mod.integrate(Y0, 0.01, 3, out=ro)


def test_out_float64_is_written_in_place(both, modules, kepler, tmp_path):
    """Negative control: a float64 array, and a float64 memmap, are accepted and filled."""
    _, np_mod = modules(kepler, "energy-momentum")
    ref = np_mod.integrate(Y0, 0.01, 3)
    out = np.zeros((4, 6))
    assert np_mod.integrate(Y0, 0.01, 3, out=out) is out and np.array_equal(out, ref)
    mm = np.lib.format.open_memmap(tmp_path / "t.npy", mode="w+", dtype=np.float64, shape=(4, 6))
    np_mod.integrate(Y0, 0.01, 3, out=mm)
    assert np.array_equal(np.asarray(mm), ref)


@pytest.mark.parametrize("bad", [
    dict(y0=Y0 + 0j),
    dict(y0=[0.4, 0, 0, 0, 1.6 + 1e-3j, 1.2]),
    dict(params={"k": 1.0 + 0j}),
    dict(params={"k": np.complex128(1.0)}),
    dict(h=0.01 + 0j),
])
def test_complex_input_is_refused(both, bad):
    for mod in both:
        kw = dict(y0=Y0, h=0.01, params=None)
        kw.update(bad)
        with pytest.raises(TypeError, match="real number"):
            mod.integrate(kw["y0"], kw["h"], 3, kw["params"])


@pytest.mark.parametrize("bad, what", [
    (dict(params={"k": True}), "bool"),
    (dict(params={"m": np.bool_(True)}), "bool"),
    (dict(params={"k": "1.0"}), "str"),
    (dict(h=True), "bool"),
    (dict(h="0.01"), "str"),
    (dict(y0=[0.4, 0, 0, 0, True, 1.2]), "bool"),
    (dict(y0=np.ones(6, dtype=bool)), "bool"),
    (dict(y0=["0.4", "0", "0", "0", "1.6", "1.2"]), "str"),
    (dict(tol=True), "bool"),
])
def test_bool_and_str_are_not_numbers(both, bad, what):
    for mod in both:
        kw = dict(y0=Y0, h=0.01, params=None, tol=None)
        kw.update(bad)
        with pytest.raises(TypeError, match=what):
            mod.integrate(kw["y0"], kw["h"], 3, kw["params"], tol=kw["tol"])
        if "y0" in bad:
            with pytest.raises(TypeError, match=what):
                mod.hamiltonian(bad["y0"])


def test_numpy_real_numbers_are_numbers(modules, kepler):
    """Negative control: numpy integer and floating scalars and arrays, and Python ints."""
    _, mod = modules(kepler, "energy-momentum")
    ref = mod.integrate(Y0, 0.01, 3, {"k": 2.0, "m": 1.0})
    for params, h, y0 in [({"k": np.float32(2.0), "m": np.int64(1)}, np.float64(0.01), Y0),
                          ({"k": 2, "m": 1}, 0.01, [np.float64(v) for v in Y0]),
                          ({"k": np.array(2.0)}, 0.01, tuple(Y0.tolist()))]:
        np.testing.assert_array_equal(mod.integrate(y0, h, 3, params), ref)
    traj = mod.integrate(np.array([1, 0, 0, 0, 1, 0]), 0.01, 3)  # an int array
    assert traj.dtype == np.float64


def test_maxiter_and_steps(both):
    for mod in both:
        for bad in (0, 1.5, True):
            with pytest.raises(ValueError, match="maxiter"):
                mod.integrate(Y0, 0.01, 3, maxiter=bad)
        with pytest.raises(ValueError, match="steps"):
            mod.integrate(Y0, 0.01, True)


def test_info_must_be_a_dict(both):
    for mod in both:
        for bad in ([], "info", 3, ()):
            with pytest.raises(TypeError, match="info must be a dict"):
                mod.integrate(Y0, 0.01, 3, info=bad)


def test_info_dict_is_filled(modules, kepler):
    """Negative control: a dict receives the iterations and the compensation."""
    _, mod = modules(kepler, "energy-momentum")
    info = {}
    mod.integrate(Y0, 0.01, 3, info=info)
    assert info["newton_iterations"].shape == (3,) and info["compensation"].shape == (6,)


def test_a_non_finite_batch_row_is_named():
    """A batch y0 with NaN names the row and the component (a batch of thousands is otherwise
    searched by hand); a single state names the component.  Control: the finite batch runs."""
    mod = mg.generate(mg.discretize(mg.load_scene("harmonic").system, "midpoint"))
    Y = np.ones((5, 2))
    mod.integrate(Y, 0.1, 2)                                  # control
    Y[3, 1] = np.nan
    Y[4, 0] = np.inf
    with pytest.raises(ValueError, match=r"row 3, p = nan \(2 of its 5 rows are not finite\)"):
        mod.integrate(Y, 0.1, 2)
    with pytest.raises(ValueError, match=r"y0 contains NaN or infinite values: q = inf"):
        mod.integrate(np.array([np.inf, 0.0]), 0.1, 2)
