"""methodgen bench --peers: heyoka and REBOUND on the same problem (structure, never timings).

heyoka and REBOUND are optional (``methodgen[peers]``): what needs one skips cleanly
without it; the missing-peer path is simulated by hiding the modules.
"""

from __future__ import annotations

import json
import struct
import sys

import mpmath
import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.app import bench, peers
from methodgen.codegen.build import scene_module_path
from methodgen.app.cli import main
from methodgen.symbolic.derive import vector_field
from methodgen.codegen.emit import load_module
from methodgen.errors import SceneError

KEPLER_NBODY = """
# For methodgen bench --peers (REBOUND): one body about a fixed centre, G*M*m = k (m = 1).
[nbody]
G = 1.0
masses = ["m"]
centre_mass = "k"
"""


def _kepler_scene(tmp_path, nbody: str = KEPLER_NBODY, name: str = "kepler-nbody"):
    text = mg.load_scene("kepler").path.read_text().replace('name = "kepler"', f'name = "{name}"')
    # kepler.toml declares its own [nbody] table: drop it, this helper supplies the one under test
    # (every table after it is kept; the [run] table follows [nbody] in kepler.toml).
    start = text.find("\n[nbody]")
    if start >= 0:
        end = text.find("\n[", start + 1)
        text = text[:start] + text[end:]
    path = tmp_path / f"{name}.toml"
    path.write_text(text + nbody)
    return path


def _lambdified_field(system):
    subs = {s: system.param_values[s.name] for s in system.params}
    f = sp.lambdify([list(system.y)], list(vector_field(system).xreplace(subs)), "numpy")
    return lambda Y: np.array([f(y) for y in Y], dtype=float)


# --- heyoka's f = J∇H, translated from the SymPy tree -----------------------------------

@pytest.mark.parametrize("system", [
    "kepler", "henon-heiles-2d", "simple-pendulum", "outer-solar-system",
    # every function of the grammar, rationals, pi, a fractional power
    mg.Hamiltonian("p**2/2 + exp(q)/3 - log(2 + q**2) + sin(q)*cos(2*q) + tan(q/5) + sinh(q/2)"
                   " + cosh(q)/7 + tanh(q) + atan(q*p) + pi*sqrt(1 + q**2) + (1 + q**2)**(3/2)/9",
                   q=["q"], p=["p"], name="grammar"),
], ids=lambda s: s if isinstance(s, str) else s.name)
def test_heyoka_vector_field_equals_methodgens(system):
    hy = pytest.importorskip("heyoka")
    if isinstance(system, str):
        scene = mg.load_scene(system)
        system, center = scene.system, np.array(scene.y0)
    else:
        center = np.array([0.3, -0.2])
    variables, sys_ = peers.heyoka_system(system)
    assert [v for v, _ in sys_] == variables
    cf = hy.cfunc([rhs for _, rhs in sys_], variables)
    rng = np.random.default_rng(3)
    scale = np.maximum(np.abs(center), 0.1 * np.max(np.abs(center)))
    Y = center + 0.05 * scale * rng.standard_normal((25, center.size))
    got = cf(np.ascontiguousarray(Y.T)).T
    want = _lambdified_field(system)(Y)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15 * np.max(np.abs(want)))
    # Negative control: the translation is of *this* field (swap two components).
    assert not np.allclose(got[:, ::-1], want, rtol=1e-6)


def test_heyoka_translation_refuses_what_it_cannot_translate():
    hy = pytest.importorskip("heyoka")
    x = sp.Symbol("x")
    with pytest.raises(peers.PeerUnsupported, match="erf"):
        peers._to_heyoka(sp.erf(x), {x: hy.make_vars("x")}, lambda c: hy.expression(float(c)), hy)
    with pytest.raises(peers.PeerUnsupported, match="DAE"):
        peers.heyoka_system(mg.load_scene("pendulum").system)


def _kepler_exact(y0, T, mu=1.0, dps=40):
    """Kepler's equation solved in mpmath (f and g functions): the exact state at T."""
    mpmath.mp.dps = dps
    r0 = mpmath.matrix([mpmath.mpf(float(v)) for v in y0[:3]])
    v0 = mpmath.matrix([mpmath.mpf(float(v)) for v in y0[3:]])
    mu, T = mpmath.mpf(mu), mpmath.mpf(T)
    rn = mpmath.sqrt(sum(c ** 2 for c in r0))
    a = 1 / (2 / rn - sum(c ** 2 for c in v0) / mu)
    n = mpmath.sqrt(mu / a ** 3)
    sigma = sum(x * y for x, y in zip(r0, v0)) / mpmath.sqrt(mu)
    E = n * T
    for _ in range(100):
        F = E + sigma / mpmath.sqrt(a) * (1 - mpmath.cos(E)) - (1 - rn / a) * mpmath.sin(E) - n * T
        dF = 1 + sigma / mpmath.sqrt(a) * mpmath.sin(E) - (1 - rn / a) * mpmath.cos(E)
        E -= F / dF
        if abs(F) < mpmath.mpf(10) ** (-dps + 5):
            break
    r = a + (rn - a) * mpmath.cos(E) + sigma * mpmath.sqrt(a) * mpmath.sin(E)
    f = 1 - a / rn * (1 - mpmath.cos(E))
    g = T - (E - mpmath.sin(E)) / n
    fd = -mpmath.sqrt(mu * a) / (r * rn) * mpmath.sin(E)
    gd = 1 - a / r * (1 - mpmath.cos(E))
    q = f * r0 + g * v0
    v = fd * r0 + gd * v0
    return np.array([float(c) for c in q] + [float(c) for c in v])


def test_heyoka_reference_is_closer_to_the_exact_kepler_orbit_than_dop853():
    """Why ``--peers`` uses heyoka (long double, tol 1e-18) as its reference: on Kepler
    e = 0.6 against Kepler's equation it is orders of magnitude closer than DOP853."""
    pytest.importorskip("heyoka")
    if np.finfo(np.longdouble).nmant <= 52:
        pytest.skip("numpy.longdouble is plain double here")
    sc = mg.load_scene("kepler")
    y0, T = np.array(sc.y0), 50.0
    exact = _kepler_exact(y0, T)
    hy_ref = bench.reference(sc.system, y0, T, heyoka=True)
    dop = bench.reference(sc.system, y0, T)
    assert hy_ref.kind.startswith("heyoka") and dop.kind.startswith("DOP853")
    e_hy = np.max(np.abs(hy_ref.y - exact))
    e_dop = np.max(np.abs(dop.y - exact))
    assert e_hy < 1e-14
    assert e_dop > 100 * e_hy


# --- the bench table -------------------------------------------------------------------

@pytest.fixture(scope="module")
def kepler_peers(tmp_path_factory):
    pytest.importorskip("heyoka")
    pytest.importorskip("rebound")
    path = _kepler_scene(tmp_path_factory.mktemp("scenes"))
    return path, bench.work_precision(mg.load_scene(path), ["energy-momentum"], quick=True, T=10.0, peers=True)


def test_bench_rows_of_peers_have_the_columns_of_methodgens(kepler_peers):
    _, wp = kepler_peers
    assert wp["reference"].startswith("heyoka") and wp["T"] == 10.0
    rows = wp["rows"]
    kinds = {r["kind"] for r in rows}
    assert kinds == {"methodgen", "heyoka", "rebound"}
    assert {r["method"] for r in rows if r["kind"] == "rebound"} == {"REBOUND IAS15", "REBOUND WHFast"}
    assert sorted(r["tol"] for r in rows if r["kind"] == "heyoka") == sorted(peers.QUICK_HEYOKA_TOLERANCES)
    columns = {"method", "kind", "steps", "seconds", "error", "energy_error", "energy_rel_error",
               "invariant_errors"}
    for r in rows:
        assert columns <= set(r), r["method"]
        assert ("h" in r) or ("tol" in r)
        assert set(r["invariant_errors"]) == {"H", "Lx", "Ly", "Lz"}
        assert r["seconds"] >= 0 and np.isfinite(r["error"])
    # The physics the rows show: methodgen's energy-momentum keeps H and q x p to round-off;
    # heyoka at tol 1e-9 does not; every peer at its tightest setting is accurate.
    em = [r for r in rows if r["kind"] == "methodgen"]
    assert max(r["energy_rel_error"] for r in em) < 1e-13
    assert max(max(r["invariant_errors"].values()) for r in em) < 1e-13
    loose = next(r for r in rows if r["kind"] == "heyoka" and r["tol"] == 1e-9)
    tight = next(r for r in rows if r["kind"] == "heyoka" and r["tol"] == 1e-15)
    assert loose["energy_rel_error"] > 100 * tight["energy_rel_error"]
    assert tight["error"] < 1e-11
    ias15 = [r for r in rows if r["method"] == "REBOUND IAS15"]
    assert min(r["error"] for r in ias15) < 1e-10


def test_cli_table_and_plot_have_the_peer_rows(tmp_path, capsys):
    pytest.importorskip("heyoka")
    pytest.importorskip("rebound")
    pytest.importorskip("matplotlib")
    path = _kepler_scene(tmp_path)
    png = tmp_path / "wp.png"
    assert main(["bench", str(path), "--peers", "--quick", "--t-final", "5", "--methods", "energy-momentum",
                 "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    table = out.split("nonlinear solvers")[0]
    assert "reference: heyoka (Taylor) in long double" in table
    for label in ("energy-momentum", "heyoka (Taylor)", "REBOUND IAS15", "REBOUND WHFast"):
        assert label in table
    assert "rel. dE" in table
    with open(png, "rb") as fh:
        head = fh.read(24)
    assert struct.unpack(">II", head[16:24]) == (1400, 600)  # error and energy panels


def test_missing_peers_are_a_note_and_exit_0(tmp_path, capsys, monkeypatch):
    # A module set to None in sys.modules raises ImportError on import: as if not installed.
    monkeypatch.setitem(sys.modules, "heyoka", None)
    monkeypatch.setitem(sys.modules, "rebound", None)
    path = _kepler_scene(tmp_path)
    assert main(["bench", str(path), "--peers", "--quick", "--t-final", "2", "--methods", "energy-momentum",
                 "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    wp = rep["work_precision"]
    assert {r["kind"] for r in wp["rows"]} == {"methodgen"}
    assert wp["peers"] == {"heyoka": None, "rebound": None}
    assert wp["reference"].startswith("DOP853")
    for name in ("heyoka", "rebound"):
        (note,) = [n for n in wp["notes"] if n.startswith(f"{name} is not installed")]
        assert "\n" not in note and "methodgen[peers]" in note
    assert main(["bench", str(path), "--peers", "--quick", "--t-final", "2", "--methods", "energy-momentum"]) == 0
    out = capsys.readouterr().out
    assert "note: heyoka is not installed" in out and "note: rebound is not installed" in out


def test_rebound_is_skipped_with_a_note_without_a_matching_nbody_table(tmp_path):
    pytest.importorskip("rebound")
    module = load_module(scene_module_path(mg.load_scene("kepler"), "energy-momentum"))
    kepler = mg.load_scene(_kepler_scene(tmp_path, nbody="", name="kepler-plain"))   # no [nbody]
    y0, T = np.array(kepler.y0), 1.0
    with pytest.raises(peers.PeerUnsupported, match=r"no \[nbody\] table"):
        peers.rebound_rows(kepler, module, y0, T, y0, lambda traj: {})
    wrong = mg.load_scene(_kepler_scene(tmp_path, KEPLER_NBODY.replace('centre_mass = "k"', "centre_mass = 2.0")))
    with pytest.raises(peers.PeerUnsupported, match="does not describe its H"):
        peers.rebound_rows(wrong, module, y0, T, y0, lambda traj: {})


@pytest.mark.parametrize("table, fragment", [
    ('[nbody]\nG = 1.0\nmasses = ["m", "m"]\n', "2 bodies"),
    ('[nbody]\nG = "Gee"\nmasses = ["m"]\n', "not in [params]"),
    ('[nbody]\nG = 1.0\nmasses = [-1.0]\n', "positive"),
    ('[nbody]\nmasses = ["m"]\n', "missing key 'G'"),
    ('[nbody]\nG = 1.0\nmasses = ["m"]\nspin = 3\n', "unknown key"),
])
def test_bad_nbody_tables(tmp_path, table, fragment):
    with pytest.raises(SceneError) as err:
        mg.load_scene(_kepler_scene(tmp_path, table))
    assert fragment in str(err.value)


# --- the outer solar system -------------------------------------------------------------

def test_outer_solar_system_scene_loads_and_energy_momentum_keeps_its_invariants():
    sc = mg.load_scene("outer-solar-system")
    assert sc.builtin and sc.system.dim == 18 and sc.h == 10.0
    assert "Hairer, Lubich & Wanner" in sc.description
    G, masses, centre = sc.nbody.values(sc.system.param_values)
    assert G == 2.95912208286e-4 and centre is None and len(masses) == 6
    assert masses[5] == 1 / 1.3e8 and masses[0] == 1.00000597682
    y0 = np.array(sc.y0)
    np.testing.assert_array_equal(y0[3:6], [-3.5023653, -3.8169847, -1.5507963])  # Jupiter
    np.testing.assert_allclose(y0[18 + 3:18 + 6] / masses[1], [0.00565429, -0.00412490, -0.00190589],
                               rtol=1e-15)
    em = load_module(scene_module_path(sc, "energy-momentum"))
    assert peers.nbody_mismatch(sc, em) < 1e-13  # the [nbody] table describes this H
    traj = em.integrate(y0, sc.h, 300)  # 3000 days
    H = em.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-13
    mon = peers.nbody_monitors(sc)(traj)
    for name in ("Lx", "Ly", "Lz", "Px", "Py", "Pz"):
        assert np.max(np.abs(mon[name] - mon[name][0])) < 1e-18, name  # |L| ~ 3e-5, |P| ~ 5e-6
    # Negative control: Störmer-Verlet (symplectic, not energy-preserving) has a visible energy error.
    sv = load_module(scene_module_path(sc, "stormer-verlet"))
    H_sv = sv.hamiltonian(sv.integrate(y0, sc.h, 300))
    assert np.max(np.abs(H_sv - H_sv[0])) / abs(H[0]) > 1e-8


def test_henon_heiles_2d_is_not_the_figure_2_scene():
    two, one = mg.load_scene("henon-heiles-2d"), mg.load_scene("henon-heiles")
    assert two.system.dim == 2 and one.system.dim == 1
    mod = load_module(scene_module_path(two, "energy-momentum"))
    assert float(mod.hamiltonian(np.array(two.y0))) == pytest.approx(1 / 8, abs=1e-16)


def test_work_precision_plot_with_peer_rows(tmp_path):
    pytest.importorskip("matplotlib")
    from methodgen.app.plots import plot_work_precision
    rows = [{"method": "energy-momentum", "kind": "methodgen", "seconds": s, "error": e, "energy_rel_error": 0.0}
            for s, e in [(0.1, 1e-3), (0.2, 2.5e-4)]]
    rows += [{"method": "heyoka (Taylor)", "kind": "heyoka", "seconds": s, "error": e, "energy_rel_error": de}
             for s, e, de in [(0.01, 1e-8, 1e-10), (0.02, 1e-12, 1e-15)]]
    path = plot_work_precision(rows, tmp_path / "wp.png")
    with open(path, "rb") as fh:
        assert struct.unpack(">II", fh.read(24)[16:24]) == (1400, 600)
    path = plot_work_precision(rows[:2], tmp_path / "wp1.png")  # methodgen only: one panel, as before
    with open(path, "rb") as fh:
        assert struct.unpack(">II", fh.read(24)[16:24]) == (800, 600)


def test_timed_repeats_start_from_the_same_state(tmp_path, monkeypatch):
    """Every timed repeat of a bench row is the same run: nothing (the compensation) is
    carried from one repeat into the next."""
    pytest.importorskip("heyoka")
    pytest.importorskip("rebound")
    results = []

    def twice(run, *args, **kwargs):
        first, second = run(), run()
        results.append((first, second))
        return 0.0, second

    monkeypatch.setattr(peers, "min_cpu", twice)
    path = _kepler_scene(tmp_path)
    bench.work_precision(mg.load_scene(path), ["stormer-verlet"], quick=True, T=10.0, peers=True)
    ours = [(a, b) for a, b in results if isinstance(a, np.ndarray) and a.ndim == 2 and a.shape[1] == 6]
    assert ours
    for a, b in ours:
        assert np.array_equal(a, b)
    # control: the same module run twice with one info dict does differ (so the test can fail)
    module = mg.build(mg.load_scene(path).system, "stormer-verlet")
    y0, info = np.array(mg.load_scene(path).y0), {}
    a = module.integrate(y0, 0.05, 200, info=info, check_resolution=False)
    b = module.integrate(y0, 0.05, 200, info=info, check_resolution=False)
    assert not np.array_equal(a, b)


def test_heyoka_runs_its_own_nbody_model_on_nbody_scenes():
    """On an [nbody] scene of free bodies heyoka runs model.nbody (its best formulation), its
    (x, v) state mapped to our (q, p = m v): the same trajectory as heyoka on our translation
    of H's field.  Negative control: a model with one mass changed is caught."""
    hy = pytest.importorskip("heyoka")
    import types

    from test_wisdom_holman import star_and_planets

    system, nbody, y0 = star_and_planets(1e-3, 2)
    scene = types.SimpleNamespace(nbody=nbody, system=system, y0=tuple(y0))
    module = mg.generate(mg.discretize(system, "stormer-verlet"))
    got = peers.heyoka_nbody(scene, module)
    assert got is not None
    sys_, to_h, from_h = got
    assert np.array_equal(from_h(to_h(y0)), y0)
    T = 3.0

    def final(sys_, s0, back):
        ta = hy.taylor_adaptive(sys_, [float(v) for v in s0], tol=1e-15)
        ta.propagate_until(T)
        return back(ta.state)

    ours = final(peers.heyoka_system(system)[1], y0, np.array)
    theirs = final(sys_, to_h(y0), from_h)
    assert np.max(np.abs(ours - theirs)) < 1e-12
    wrong = hy.model.nbody(3, masses=[1.0, 1e-3, 2e-3], Gconst=1.0)
    assert np.max(np.abs(final(wrong, to_h(y0), from_h) - ours)) > 1e-6
    # a fixed centre (the kepler scene's declaration) is not model.nbody's: the translation is used
    kepler = mg.load_scene("kepler")
    assert peers.heyoka_nbody(kepler, mg.generate(mg.discretize(kepler.system, "stormer-verlet"))) is None


def test_quick_wisdom_holman_ladder_spans_the_full_range(tmp_path):
    """--quick runs each Wisdom–Holman family on every other step of the full ladder (a factor
    2 apart, nearly its whole range, so the useful step is on it) and says so; control: the
    full ladder's √2 strides."""
    import math

    from test_wisdom_holman import star_scene

    scene, y0 = star_scene(tmp_path)
    T = 20.0
    ref = bench.reference(scene.system, y0, T)
    base = mg.generate(mg.discretize(scene.system, "stormer-verlet"))
    for quick, ratio in ((True, 2.0), (False, math.sqrt(2))):
        notes = []
        rows = bench._wisdom_holman_rows(scene, y0, T, ref, None, base, quick, notes)
        hs = [r["h"] for r in rows if r["base_method"] == "sbab3" and "project" not in r]
        assert len(hs) >= 2
        for a, b in zip(hs, hs[1:]):
            assert a / b == pytest.approx(ratio, rel=0.05)
        assert len(hs) <= (bench.WH_QUICK_POINTS if quick else bench.WH_MAX_POINTS)
        assert any(n.startswith("--quick: the Wisdom–Holman") for n in notes) == quick
