"""Time-dependent Hamiltonians (issue 15, item 3): ``Hamiltonian(..., time="t")`` and the scene's
``[system] time = "t"``.  Every method integrates the autonomous extension K = H(q, p, t) + e on
(q, t; p, e): a forced oscillator and a parametrically driven pendulum against DOP853 at the
methods' orders; K kept exactly by the discrete gradients; the certificates and their negative
controls; the scene through the command line; the errors (t undeclared, a parameter named t)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.app import cli
from methodgen.symbolic.derive import declared
from methodgen.errors import InputError, MethodNotApplicable, ParseError, SceneError
from methodgen.symbolic.verify.report import PROVED, REFUTED
from methodgen.symbolic.verify.timetransform import time_transform_certificates

FORCED = "p**2/2 + w**2*x**2/2 - F*x*cos(W*t)"
FORCED_PARAMS = {"w": 1.0, "F": 0.5, "W": 1.3}
PARAMETRIC = "p**2/2 - (w**2 + a*cos(W*t))*cos(x)"       # pendulum with a vibrating pivot
PARAMETRIC_PARAMS = {"w": 1.0, "a": 0.4, "W": 2.1}
Y0, T0, T = [1.0, 0.0], 0.5, 10.0


def forced_rhs(t, y):
    return [y[1], -y[0] + 0.5 * np.cos(1.3 * t)]


def parametric_rhs(t, y):
    return [y[1], -(1.0 + 0.4 * np.cos(2.1 * t)) * np.sin(y[0])]


def dop853(rhs, y0, t0, t1):
    from scipy.integrate import solve_ivp

    sol = solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol=1e-12, atol=1e-14)
    assert sol.success
    return sol.y[:, -1]


@pytest.fixture(scope="module", autouse=True)
def cache(tmp_path_factory):
    """A private module cache for the scenes' modules (not generated/)."""
    root = tmp_path_factory.mktemp("td") / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("METHODGEN_CACHE", str(root))
        yield root


@pytest.fixture(scope="module")
def systems():
    return {"forced": mg.Hamiltonian(FORCED, q=["x"], p=["p"], params=FORCED_PARAMS, time="t", name="forced"),
            "parametric": mg.Hamiltonian(PARAMETRIC, q=["x"], p=["p"], params=PARAMETRIC_PARAMS, time="t",
                                         name="parametric")}


@pytest.fixture(scope="module")
def modules(systems, tmp_path_factory):
    root = tmp_path_factory.mktemp("tdmods")
    store = {}

    def get(name, method, **options):
        key = (name, method, tuple(sorted(options.items())))
        if key not in store:
            path = root / f"{name}_{method}_{len(store)}.py".replace("-", "_")
            store[key] = mg.build(systems[name], method, path=path, **options)
        return store[key]

    return get


# --- the system and its extension ------------------------------------------------------------

def test_the_system_stays_the_users_and_is_integrated_extended(systems):
    H = systems["forced"]
    assert H.state_names == ("x", "p") and H.time == sp.Symbol("t", real=True) and not H.autonomous
    K = mg.autonomise(H)
    assert K is mg.autonomise(H) and mg.autonomise(K) is K            # one object, idempotent
    assert K.state_names == ("x", "t", "p", "e") and K.name == "forced"
    assert K.time_transform.autonomised and K.time_transform.original is H
    assert sp.expand(K.H - H.H - K.symbol("e")) == 0
    # discretize and build work on the user's system: the scheme's system is K
    assert mg.discretize(H, "midpoint").system is K
    # declaring the time is part of the system's identity
    frozen = mg.Hamiltonian(FORCED, q=["x"], p=["p"], params={**FORCED_PARAMS, "t": 0.0})
    assert frozen.fingerprint() != H.fingerprint()
    assert mg.autonomise(frozen) is frozen                           # autonomous: unchanged


def test_every_method_for_K_applies_and_energy_momentum_says_why(systems):
    ok = set(mg.applicable_methods(systems["forced"]))
    assert {"midpoint", "gauss", "avf", "gonzalez", "itoh-abe", "trapezoidal", "kahan",
            "stormer-verlet", "energy-collocation"} <= ok
    with pytest.raises(MethodNotApplicable) as exc:
        mg.discretize(systems["forced"], "energy-momentum")
    msg = str(exc.value)
    assert "autonomous extension K = H(q, p, t) + e" in msg and "linear in e" in msg
    assert "quadratic kinetic energy" in msg and "Methods that apply" in msg


# --- against DOP853 -------------------------------------------------------------------------

ORDER_CASES = [("forced", "midpoint", {}, 2), ("forced", "avf", {}, 2), ("forced", "gauss", {"stages": 2}, 4),
               ("forced", "stormer-verlet", {}, 2), ("parametric", "midpoint", {}, 2),
               ("parametric", "gauss", {"stages": 2}, 4), ("parametric", "stormer-verlet", {}, 2)]


@pytest.mark.parametrize("name, method, options, order", ORDER_CASES)
def test_order_against_dop853(modules, name, method, options, order):
    """From t0 = 0.5 to 10.5 at h = 0.1, 0.05, 0.025: the state at the time reached against
    DOP853 (rtol 1e-12); the fitted order is the method's (measured 2.00 / 4.00)."""
    mod = modules(name, method, **options)
    rhs = forced_rhs if name == "forced" else parametric_rhs
    hs = np.array([0.1, 0.05, 0.025])
    errs = []
    for h in hs:
        tr = mod.integrate(mod.initial_state(Y0, T0), h, int(round(T / h)))
        y, t = mod.physical_state(tr[-1])
        assert t == pytest.approx(T0 + T, abs=1e-12)          # t' = 1: the fictive time is the physical one
        errs.append(np.abs(y - dop853(rhs, Y0, T0, t)).max())
    fitted = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(fitted - order) < 0.15, (errs, fitted)
    assert errs[-1] < (2e-3 if order == 2 else 2e-8), errs


@pytest.mark.parametrize("method", ["gonzalez", "itoh-abe"])
def test_discrete_gradients_keep_K_exactly_and_H_is_minus_e(modules, method):
    """K = H + e to round-off; H itself changes (it is forced), and H_phys = −e along the run."""
    mod = modules("forced", method)
    tr = mod.integrate(mod.initial_state(Y0, T0), 0.05, 200)
    inv = mod.invariants(tr)
    assert np.abs(inv["H"]).max() < 1e-13                      # K = 0 from initial_state
    assert np.ptp(inv["H_phys"]) > 0.5                         # the forcing pumps energy
    assert np.abs(inv["H_phys"] + tr[:, 3]).max() < 1e-13      # H = −e
    assert "H" in mod.TRAITS["preserved"] and "H_phys" not in mod.TRAITS["preserved"]
    y, t = mod.physical_state(tr[-1])
    # Gonzalez's correction term is along Δy, which has an e-component: t advances by h only
    # up to O(h³) per step — the state is compared at the time it reached.
    assert np.abs(y - dop853(forced_rhs, Y0, T0, t)).max() < (5e-3 if method == "gonzalez" else 5e-2)


def test_initial_state_and_physical_state(modules):
    mod = modules("forced", "midpoint")
    Y = mod.initial_state(Y0, T0)
    assert list(mod.STATE_NAMES) == ["x", "t", "p", "e"] and Y[1] == T0
    assert Y[3] == pytest.approx(-(0.5 * 1.0 - 0.5 * math.cos(1.3 * T0)))   # e0 = −H(y0, t0)
    y, t = mod.physical_state(Y)
    assert np.array_equal(y, Y0) and t == T0
    assert mod.TIME_TRANSFORM["g"] == "1" and mod.TIME_TRANSFORM["time"] == "t"


def test_time_transform_of_a_time_dependent_H(systems, tmp_path):
    """K = g(q)(H(q, p, t) + e) falls out: the declared t is the new coordinate."""
    K = mg.time_transform(systems["forced"], "1/(1 + x**2)")
    assert K.state_names == ("x", "t", "p", "e") and not K.time_transform.autonomised
    assert [c.status for c in time_transform_certificates(K)] == [PROVED] * 3
    mod = mg.build(K, "avf", path=tmp_path / "forced_tt_avf.py")
    tr = mod.integrate(mod.initial_state(Y0, T0), 0.02, 250)
    y, t = mod.physical_state(tr[-1])
    assert t > T0 + 0.02 * 250 * 0.4                           # dt = g dτ, g = 1/(1 + x²)
    assert np.abs(y - dop853(forced_rhs, Y0, T0, t)).max() < 1e-3
    assert np.abs(mod.invariants(tr)["H"]).max() < 1e-13      # K = 0 kept (AVF: polynomial in e)


# --- certificates ----------------------------------------------------------------------------

def test_certificates_prove_the_extension(systems):
    certs = time_transform_certificates(mg.autonomise(systems["parametric"]))
    assert [c.status for c in certs] == [PROVED, PROVED, PROVED]
    assert "autonomous extension" in certs[0].claim and "autonomous on the extended" in certs[1].claim
    assert "flow of H(q, p, t)" in certs[2].claim


def _wrong(K, expr):
    """A system claiming to be the extension of K's H, with Hamiltonian ``expr`` instead."""
    bad = mg.Hamiltonian(sp.Integer(0) * K.symbol("x") + K.symbol("p"), q=list(K.q), p=list(K.p),
                         params=K.param_values, name="bad")
    object.__setattr__(bad, "H", expr)
    object.__setattr__(bad, "time_transform", K.time_transform)
    return bad


def test_certificates_refute_wrong_extensions(systems):
    """Negative controls: time frozen at t = 0 in K (what declaring t as a parameter did), a
    wrong momentum term (H + 2e), and a K with a time of its own (not autonomous)."""
    K = mg.autonomise(systems["forced"])
    t, e = K.time_transform.time, K.time_transform.energy
    H = systems["forced"].H
    frozen = [c.status for c in time_transform_certificates(_wrong(K, H.xreplace({t: 0}) + e))]
    assert frozen == [REFUTED, PROVED, REFUTED]
    doubled = [c.status for c in time_transform_certificates(_wrong(K, H + 2 * e))]
    assert doubled == [REFUTED, PROVED, REFUTED]
    tau = sp.Symbol("tau", real=True)
    clock = [c for c in time_transform_certificates(_wrong(K, H.xreplace({t: tau}) + e))]
    assert [c.status for c in clock] == [REFUTED, REFUTED, REFUTED]
    assert clock[1].details["nonzero"] == ["tau"]


def test_verify_proves_the_claims_of_a_discrete_gradient(systems):
    rep = mg.verify(mg.discretize(systems["forced"], "itoh-abe"))
    assert rep.ok
    mine = [c for c in rep.certificates if "autonomous" in c.claim or "flow of H(q, p, t)" in c.claim]
    assert len(mine) == 3 and all(c.status == PROVED for c in mine)


def test_time_dependent_first_integral_is_proved_or_refuted():
    """On (q, t; p, e), {I, K} = {I, H} + ∂I/∂t: p − sin t is a first integral of H = p²/2 − x cos t,
    p + sin t is not."""
    H = mg.Hamiltonian("p**2/2 - x*cos(t)", q=["x"], p=["p"], time="t",
                       invariants={"I": "p - sin(t)", "J": "p + sin(t)"})
    found = {inv.name: inv.exact for inv in declared(mg.autonomise(H))}
    assert found == {"I": True, "J": False}


# --- errors ----------------------------------------------------------------------------------

def test_t_without_declaring_it_keeps_its_error_with_a_hint():
    with pytest.raises(ParseError, match="unknown symbol 't'") as exc:
        mg.Hamiltonian(FORCED, q=["x"], p=["p"], params=FORCED_PARAMS)
    assert 'time = "t" in [system]' in str(exc.value) and 'time="t" in the API' in str(exc.value)
    x, p, t = sp.symbols("x p t")
    with pytest.raises(InputError, match='time="t"'):
        mg.Hamiltonian(p**2 / 2 - x * sp.cos(t), q=["x"], p=["p"])
    with pytest.raises(ParseError) as other:           # other unknown names get no time hint
        mg.Hamiltonian("p**2/2 + k*x**2", q=["x"], p=["p"])
    assert "time" not in str(other.value)


def test_a_parameter_named_like_the_time_is_an_error():
    with pytest.raises(InputError, match="parameter 't' has the name of the declared time"):
        mg.Hamiltonian(FORCED, q=["x"], p=["p"], params={**FORCED_PARAMS, "t": 0.0}, time="t")
    with pytest.raises(InputError, match="also a coordinate"):
        mg.Hamiltonian("p**2/2 + x**2", q=["x"], p=["p"], time="x")
    with pytest.raises(InputError, match="depends on the time"):
        mg.Hamiltonian("(px**2 + py**2)/2", q=["x", "y"], p=["px", "py"], time="t",
                       constraints=["x**2 + y**2 - 1 - t"])


# --- scenes and the command line -----------------------------------------------------------------

SCENE = """name = "forced"
[system]
H = "{H}"
q = ["x"]
p = ["p"]
{time}
[params]
w = 1.0
F = 0.5
W = 1.3
{extra_params}
[run]
method = ["midpoint", "avf", "stormer-verlet"]
h = 0.05
steps = 200
y0 = [1.0, 0.0]
{run}
"""


def _scene(tmp_path, time='time = "t"', run="t0 = 0.5", extra_params="", H=FORCED):
    path = tmp_path / "forced.toml"
    path.write_text(SCENE.format(H=H, time=time, run=run, extra_params=extra_params), encoding="utf-8")
    return path


def _main(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _strict_json(text):
    def no_nan(token):
        raise AssertionError(f"{token} in the JSON output")
    return json.loads(text, parse_constant=no_nan)


def test_scene_declares_the_time(tmp_path):
    sc = mg.load_scene(_scene(tmp_path))
    assert sc.system.time.name == "t" and sc.t0 == 0.5 and len(sc.y0) == 2
    assert sc.run_system.state_names == ("x", "t", "p", "e") and sc.run_system is mg.autonomise(sc.system)


@pytest.mark.parametrize("method", ["midpoint", "stormer-verlet"])
def test_run_json_reports_the_original_variables_and_t(tmp_path, capsys, method):
    code, out, err = _main(capsys, "run", str(_scene(tmp_path)), "--method", method, "--json")
    assert code == 0, err
    rep = _strict_json(out)
    assert rep["t0"] == 0.5 and rep["t_final"] == pytest.approx(10.5, abs=1e-12)
    assert rep["state_names"] == ["x", "p"] and len(rep["y_final"]) == 2
    td = rep["time_dependent"]
    assert td["time"] == "t" and td["state_names"] == ["x", "t", "p", "e"] and td["t_final"] == rep["t_final"]
    assert rep["time_transform"] is None
    ref = dop853(forced_rhs, Y0, 0.5, rep["t_final"])
    assert np.abs(np.array(rep["y_final"]) - ref).max() < 5e-3   # order 2 at h = 0.05 (3.6e-3, 1.3e-3)
    inv = rep["invariants"]
    assert inv["H"]["initial"] == 0.0 and inv["H_phys"]["claim"] == "monitored"
    assert inv["H_phys"]["initial"] == pytest.approx(0.5 - 0.5 * math.cos(1.3 * 0.5))


def test_run_text_and_t_final(tmp_path, capsys):
    path = str(_scene(tmp_path))
    code, out, err = _main(capsys, "run", path, "--t-final", "2.5")
    assert code == 0, err
    lines = out.splitlines()
    assert "(t = 0.5 .. 2.5)" in lines[0] and "steps = 40" in lines[0]
    assert lines[1].startswith("time-dependent H: integrates K = H + e")
    assert lines[-1].startswith("y_final: x=") and lines[-1].endswith("; t=2.5")
    code, out, err = _main(capsys, "run", path, "--t-final", "0.2")
    assert code == cli.EXIT_INPUT and "from t0 = 0.5" in err and "Traceback" not in err   # before t0: h < 0 needed


def test_verify_scene(tmp_path, capsys):
    code, out, err = _main(capsys, "verify", str(_scene(tmp_path)), "--method", "midpoint", "--json")
    assert code == 0, err
    certs = _strict_json(out)["certificates"]
    mine = [c for c in certs if "autonomous" in c["claim"] or "flow of H(q, p, t)" in c["claim"]]
    assert [c["status"] for c in mine] == ["proved"] * 3


@pytest.mark.slow
def test_bench_scene(tmp_path, capsys):
    code, out, err = _main(capsys, "bench", str(_scene(tmp_path)), "--quick", "--methods", "midpoint", "--json")
    assert code == 0, err
    rows = _strict_json(out)["work_precision"]["rows"]     # on (x, t; p, e), from (x0, t0, p0, −H0)
    mid = [r for r in rows if r["method"] == "midpoint"]
    assert len(mid) == 3 and mid[-1]["error"] < 1e-3


@pytest.mark.parametrize("time, run, extra, H, fragments", [
    ("", "", "", FORCED, ["unknown symbol 't'", 'time = "t" in [system]']),
    ('time = "t"', "", "t = 0.0", FORCED, ["parameter 't' has the name of the declared time"]),
    ("", "t0 = 1.0", "", "p**2/2 + x**2/2", ["[run].t0", "time-dependent"]),
    ('time = 1', "", "", FORCED, ["[system].time must be a str"]),
])
def test_bad_scenes_are_one_line_errors(tmp_path, capsys, time, run, extra, H, fragments):
    path = _scene(tmp_path, time=time, run=run, extra_params=extra, H=H)
    with pytest.raises(SceneError) as exc:
        mg.load_scene(path)
    assert all(f in str(exc.value) for f in fragments), str(exc.value)
    code, out, err = _main(capsys, "run", str(path))
    assert code == cli.EXIT_INPUT and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert all(f in err for f in fragments), err


def test_a_sweep_refuses_a_time_dependent_scene(tmp_path):
    from methodgen.app.sweep import SpecError, parse_spec

    with pytest.raises(SpecError, match=r"time-dependent H \(\[system\] time\)"):
        parse_spec({"scene": str(_scene(tmp_path))})
