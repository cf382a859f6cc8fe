"""The logarithmic Hamiltonian (issue 26, item 1): explicit adaptivity that keeps the structure.

``time_transform(system, form="log")`` gives Λ = log(T + e) − log(−U), separable, so
Störmer–Verlet and its compositions are explicit; :func:`methodgen.runtime.physical_time.run_to_time`
reaches a physical time exactly.  Checked: Kepler's orbit kept to round-off at e = 0.99 with
50 steps per orbit (control: the kick–drift–kick leapfrog of Λ is not exact); the orders of the
compositions measured in physical time at a fixed physical T (control: without the last solved
step the error does not fall); refusals and per-step guards where U ≥ 0 (control: the same
motion where U stays negative runs); scene and CLI.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import methodgen as mg
from methodgen.app import cli
from methodgen.errors import InputError
from methodgen.runtime.physical_time import run_to_time

KEPLER = "(px**2 + py**2 + pz**2)/(2*m) - k/sqrt(x**2 + y**2 + z**2)"


def kepler_system(extra=""):
    return mg.Hamiltonian(KEPLER + extra, q=["x", "y", "z"], p=["px", "py", "pz"],
                          params={"m": 1.0, "k": 1.0}, name="kep")


def pericentre(ecc):
    """Pericentre of the orbit a = 1 (period 2π, k = m = 1)."""
    return np.array([1 - ecc, 0.0, 0.0, 0.0, math.sqrt((1 + ecc) / (1 - ecc)), 0.0])


def kepler_exact(ecc, t):
    """The exact state at time t of the orbit through :func:`pericentre` (Kepler's equation)."""
    Ea = t
    for _ in range(60):
        Ea = Ea - (Ea - ecc * math.sin(Ea) - t) / (1 - ecc * math.cos(Ea))
    Ed = 1 / (1 - ecc * math.cos(Ea))
    b = math.sqrt(1 - ecc * ecc)
    return np.array([math.cos(Ea) - ecc, b * math.sin(Ea), 0.0, -math.sin(Ea) * Ed, b * math.cos(Ea) * Ed, 0.0])


def energy(y):
    return 0.5 * np.sum(y[..., 3:] ** 2, axis=-1) - 1 / np.linalg.norm(y[..., :3], axis=-1)


def eccentricity_vector(y):
    q, p = y[..., :3], y[..., 3:]
    r = np.linalg.norm(q, axis=-1)[..., None]
    return np.cross(p, np.cross(q, p)) - q / r


@pytest.fixture(scope="module")
def logh():
    return mg.time_transform(kepler_system(), form="log")


@pytest.fixture(scope="module")
def build(logh, tmp_path_factory):
    root = tmp_path_factory.mktemp("logh")
    cache = {}

    def get(order=2, system=None):
        system = logh if system is None else system
        key = (order, id(system))
        if key not in cache:
            scheme = mg.discretize(system, "stormer-verlet", order=order)
            cache[key] = mg.generate(scheme, root / f"logh_{scheme.key}_{len(cache)}.py".replace("-", "_"))
        return cache[key]

    return get


# --- the system ------------------------------------------------------------------------------

def test_extended_system_is_separable_and_exchanged(logh):
    assert logh.state_names == ("px", "py", "pz", "e", "x", "y", "z", "t")
    tt = logh.time_transform
    assert tt.form == "log" and tt.exchanged and tt.original.name == "kep"
    assert "stormer-verlet" in mg.applicable_methods(logh)
    # the Poincaré form of the same system is not separable: no explicit method
    poincare = mg.time_transform(kepler_system(), "sqrt(x**2 + y**2 + z**2)")
    assert "stormer-verlet" not in mg.applicable_methods(poincare)
    assert logh.fingerprint() != poincare.fingerprint()


def test_initial_state_is_on_the_level_set(build):
    mod = build()
    Y = mod.initial_state(pericentre(0.6), 3.0)
    assert mod.STATE_NAMES[3] == "e" and Y[3] == 0.5 and Y[7] == 3.0      # e = -H(y0), t = t0
    y, t = mod.physical_state(Y)
    assert np.array_equal(y, pericentre(0.6)) and t == 3.0
    assert abs(mod.invariants(Y)["H"]) < 1e-15 and mod.invariants(Y)["H_phys"] == -0.5   # -Λ = 0


# --- Kepler's orbit to round-off ---------------------------------------------------------------

def _orbit_errors(mod, ecc, steps_per_orbit, orbits):
    """Max relative energy error and max eccentricity-vector error along a run of a log-form module
    (the fictive time of one orbit is ∮ (k/r) dt = 2π for a = 1)."""
    Y = mod.integrate(mod.initial_state(pericentre(ecc)), 2 * math.pi / steps_per_orbit,
                      steps_per_orbit * orbits, check_resolution=False)
    y, t = mod.physical_state(Y)
    dE = np.max(np.abs(energy(y) + 0.5)) / 0.5
    dA = np.max(np.abs(eccentricity_vector(y) - np.array([ecc, 0, 0])))
    return dE, dA, t


def test_log_leapfrog_keeps_kepler_orbit_at_e099_with_50_steps_per_orbit(build):
    # check_resolution=False: at 50 steps per orbit the local error guard refuses the pericentre
    # passage (the error of the *phase* per step is large there); the orbit itself is the claim.
    dE, dA, t = _orbit_errors(build(), 0.99, 50, 20)
    assert dE < 1e-12 and dA < 1e-12, (dE, dA)
    assert 0.9 * 40 * math.pi < t[-1] < 1.1 * 40 * math.pi      # twenty orbits of physical time


def test_compositions_keep_the_orbit_splittings_do_not(logh, tmp_path):
    # The README's scope of the exact orbit: a composition of the leapfrog keeps it (each substep
    # does); a splitting family is not a composition of leapfrog steps (b_1 != a_1/2) and does
    # not (measured, e = 0.99, 100 steps per orbit: relative energy error ~1e-2)
    def dE(family):
        mod = mg.generate(mg.discretize(logh, "stormer-verlet", order=4, composition=family),
                          tmp_path / f"logh_{family.replace('-', '_')}.py")
        return _orbit_errors(mod, 0.99, 100, 5)[0]

    assert dE("suzuki") < 1e-12
    assert dE("blanes-moan") > 1e-4


def test_level_defect_error_of_the_log_form_says_smaller_h(logh, tmp_path):
    # S10 at 100 steps per orbit (e = 0.99) is refused at the pericentre; the message told the
    # user to "choose a g that is positive along the whole motion" -- the log form's g = -1/U is
    # not the user's to choose.  Control: the Poincaré form keeps that advice
    mod = mg.generate(mg.discretize(logh, "stormer-verlet", order=6, composition="blanes-moan"),
                      tmp_path / "logh_s10.py")
    with pytest.raises(mod.ResolutionError, match="smaller h") as exc:
        mod.integrate(mod.initial_state(pericentre(0.99)), 2 * math.pi / 100, 500)
    assert exc.value.check == "time_scale" and "choose a g" not in str(exc.value)
    assert "logarithmic Hamiltonian" in str(exc.value)
    mg.generate(mg.discretize(mg.time_transform(kepler_system(), "sqrt(x**2 + y**2 + z**2)"), "midpoint"),
                tmp_path / "kep_tt.py")
    advice = "reaches g = 0, no step size helps); choose a g that is positive along the whole motion"
    assert advice in (tmp_path / "kep_tt.py").read_text()
    assert advice not in (tmp_path / "logh_s10.py").read_text()


def test_control_kick_drift_kick_leapfrog_of_lambda_is_not_exact(build):
    # The same Λ on the unexchanged state (q, t; p, e): Störmer–Verlet is then the kick–drift–kick
    # leapfrog of Λ, which does not keep the orbit (measured: relative energy error 0.2).
    kdk = mg.Hamiltonian("log(e + (px**2 + py**2 + pz**2)/(2*m)) - log(k/sqrt(x**2 + y**2 + z**2))",
                         q=["x", "y", "z", "t"], p=["px", "py", "pz", "e"], params={"m": 1.0, "k": 1.0},
                         name="kdk")
    mod = build(system=kdk)
    Y0 = np.concatenate([pericentre(0.99)[:3], [0.0], pericentre(0.99)[3:], [0.5]])
    Y = mod.integrate(Y0, 2 * math.pi / 50, 50 * 20, check_resolution=False)
    y = np.concatenate([Y[:, :3], Y[:, 4:7]], axis=1)
    dE = np.max(np.abs(energy(y) + 0.5)) / 0.5
    assert dE > 1e-3, dE


# --- orders in physical time -------------------------------------------------------------------

T_ORDER = 4 * math.pi + 1.0    # two orbits and a bit: T falls inside a step
ORDER_STEPS = {2: (64, 128), 4: (32, 64), 6: (16, 32), 8: (12, 24), 10: (8, 16)}


def _error_at_T(mod, n, last_step=True):
    info = {}
    Y = run_to_time(mod, mod.initial_state(pericentre(0.6)), T_ORDER, 2 * math.pi / n, info=info,
                    check_resolution=False)
    if not last_step:
        # the control: the state of the last whole step (t <= T), compared with the solution at T
        Y = mod.integrate(mod.initial_state(pericentre(0.6)), 2 * math.pi / n, info["steps"],
                          save_every=max(1, info["steps"]), check_resolution=False)[-1]
    y, t = mod.physical_state(Y)
    if last_step:
        assert abs(t - T_ORDER) <= 2 * np.spacing(T_ORDER), t - T_ORDER
    return float(np.max(np.abs(y - kepler_exact(0.6, T_ORDER))))


@pytest.mark.parametrize("order", sorted(ORDER_STEPS))
def test_measured_order_in_physical_time(build, order):
    # measured: 2.00, 4.00, 5.96, 7.95, 9.92 (errors 1e-2 … 1e-13)
    mod = build(order)
    n1, n2 = ORDER_STEPS[order]
    e1, e2 = _error_at_T(mod, n1), _error_at_T(mod, n2)
    assert e2 > 1e-14, "the finer error is at round-off: the ratio would not measure the order"
    assert abs(math.log2(e1 / e2) - order) < 0.3, (order, e1, e2, math.log2(e1 / e2))


def test_control_without_the_last_step_the_order_is_lost(build):
    mod = build(4)
    n1, n2 = ORDER_STEPS[4]
    e1, e2 = _error_at_T(mod, n1, last_step=False), _error_at_T(mod, n2, last_step=False)
    assert abs(math.log2(e1 / e2)) < 2.0, (e1, e2)   # an O(h) time mismatch, not O(h^4)


def test_run_to_time_reports_and_refuses(build):
    mod = build()
    Y0 = mod.initial_state(pericentre(0.6))
    info = {}
    Y = run_to_time(mod, Y0, 10.0, 2 * math.pi / 200, info=info)
    assert Y[7] == pytest.approx(10.0, abs=4e-15) and info["t_error"] == Y[7] - 10.0
    assert 0 < info["sigma"] < 2 * math.pi / 200 and info["tau"] > 0
    with pytest.raises(InputError, match="after the initial time"):
        run_to_time(mod, Y0, -1.0, 0.1)
    with pytest.raises(InputError, match="fictive step > 0"):
        run_to_time(mod, Y0, 1.0, -0.1)
    with pytest.raises(InputError, match="time-transformed"):
        run_to_time(build(system=kepler_system()), pericentre(0.6), 1.0, 0.1)


def test_run_to_time_refuses_a_far_T_before_running_past_max_steps(build, monkeypatch):
    # A T far out is refused after at most max_steps + 1 whole steps of work (the chunks grow
    # up to 3x the steps so far, so without the cap up to 4x max_steps ran before the refusal)
    import methodgen.runtime.physical_time as pt

    mod = build()
    Y0 = mod.initial_state(pericentre(0.6))

    class Counting:
        def __init__(self, m):
            self.m, self.n = m, 0
            self.STATE_NAMES, self.TIME_TRANSFORM = m.STATE_NAMES, m.TIME_TRANSFORM

        def integrate(self, Y, h, n, **kw):
            self.n += n
            return self.m.integrate(Y, h, n, **kw)

    counted = Counting(mod)
    with pytest.raises(InputError, match="max_steps = 1100"):
        run_to_time(counted, Y0, 1e15, 0.1, max_steps=1100)
    assert counted.n <= 1101, counted.n
    with pytest.raises(InputError, match="max_steps must be an integer >= 1"):
        run_to_time(mod, Y0, 1.0, 0.1, max_steps=0)
    # control: the cap disabled, the chunks overshoot max_steps before the refusal
    monkeypatch.setattr(pt, "_cap", lambda chunk, steps, max_steps: chunk)
    counted = Counting(mod)
    with pytest.raises(InputError, match="max_steps = 1100"):
        run_to_time(counted, Y0, 1e15, 0.1, max_steps=1100)
    assert counted.n > 2200, counted.n   # 4096 whole steps run


def test_run_to_time_refuses_a_last_step_that_misses_T(build, monkeypatch):
    # A module whose t(σ) is coarse (t rounded to 1e-3 on single steps) cannot land on T: the
    # miss is an error naming the distance, not a returned state off T.  Control: the check
    # disabled (tolerance inf), the same run returns a state 1e-4 or more away from T
    import methodgen.runtime.physical_time as pt

    mod = build()
    Y0 = mod.initial_state(pericentre(0.6))

    class Coarse:
        STATE_NAMES, TIME_TRANSFORM = mod.STATE_NAMES, mod.TIME_TRANSFORM

        def integrate(self, Y, h, n, **kw):
            out = mod.integrate(Y, h, n, **kw)
            if n == 1:
                out[-1, 7] = round(out[-1, 7], 3)
            return out

    T = 1.23456
    with pytest.raises(RuntimeError, match=r"from t_final = 1.23456 \(tolerance"):
        run_to_time(Coarse(), Y0, T, 0.05)
    monkeypatch.setattr(pt, "_t_tolerance", lambda T: math.inf)
    info = {}
    run_to_time(Coarse(), Y0, T, 0.05, info=info)
    assert abs(info["t_error"]) >= 1e-4, info


def test_run_to_time_in_calls_is_the_run_in_one_piece(build, monkeypatch):
    # T = t after n whole steps of one integrate() call: run_to_time reaches it in its calls
    # (chunks, discarded crossings, halvings) bitwise; control: without handing the
    # compensation (and force) from call to call the states differ
    import methodgen.runtime.physical_time as pt

    mod = build(4)
    Y0, h, n = mod.initial_state(pericentre(0.6)), 2 * math.pi / 40, 3000
    Yn = mod.integrate(Y0, h, n, save_every=n)[-1]
    info = {}
    Y = run_to_time(mod, Y0, float(Yn[7]), h, info=info)
    assert info["steps"] == n and info["sigma"] == 0.0 and info["calls"] > 3
    assert np.array_equal(Y, Yn)
    monkeypatch.setattr(pt, "_CARRIED", ())
    assert not np.array_equal(run_to_time(mod, Y0, float(Yn[7]), h), Yn)


def test_run_to_time_lands_a_poincare_module_too(tmp_path):
    # the Poincaré form with g = r and AVF (implicit): t = T exactly, second order in h
    # (measured: 4.3e-5 and 1.1e-5 at h = 0.01, 0.005)
    K = mg.time_transform(kepler_system(), "sqrt(x**2 + y**2 + z**2)")
    mod = mg.generate(mg.discretize(K, "avf"), tmp_path / "kep_tt_avf.py")
    errs = []
    for h in (0.01, 0.005):
        Y = run_to_time(mod, mod.initial_state(pericentre(0.6)), 10.0, h)
        y, t = mod.physical_state(Y)
        assert t == pytest.approx(10.0, abs=2 * np.spacing(10.0))
        errs.append(float(np.max(np.abs(y - kepler_exact(0.6, 10.0)))))
    assert abs(math.log2(errs[0] / errs[1]) - 2) < 0.3, errs


# --- where the form does not apply -------------------------------------------------------------

@pytest.mark.parametrize("H, q, p, kw, fragment", [
    ("p**2/2 + q**2/2", ["q"], ["p"], {}, "≥ 0 everywhere"),
    ("p**2/2 + exp(q)", ["q"], ["p"], {}, "≥ 0 everywhere"),
    ("p**2*q**2/2 - 1/q", ["q"], ["p"], {}, "separable"),
    ("p**2/2 - 1/q - t", ["q"], ["p"], {"time": "t"}, "autonomous"),
])
def test_log_form_refuses(H, q, p, kw, fragment):
    with pytest.raises(InputError, match=fragment):
        mg.time_transform(mg.Hamiltonian(H, q=q, p=p, **kw), form="log")


def test_log_form_refuses_g_constraints_and_unknown_forms():
    pend = mg.Hamiltonian("(px**2 + py**2)/2 - 1/sqrt(x**2 + y**2)", q=["x", "y"], p=["px", "py"],
                          constraints=["x**2 + y**2 - 1"])
    with pytest.raises(InputError, match="constraints"):
        mg.time_transform(pend, form="log")
    with pytest.raises(InputError, match="takes no g"):
        mg.time_transform(kepler_system(), "x", form="log")
    with pytest.raises(InputError, match="valid forms: poincare, log"):
        mg.time_transform(kepler_system(), form="sundman")
    with pytest.raises(InputError, match="needs g"):
        mg.time_transform(kepler_system())


# U = -k/r + c x changes sign: on an escaping motion (H > 0) from x = 1 towards +x it reaches
# U = 0 at r ≈ 1.4 (c = 0.5).  A bound motion (H < 0) never reaches it (U = H - T ≤ H < 0).
ESCAPE = [1.0, 0.0, 0.0, 2.0, 0.3, 0.0]


def _field_module(build, c):
    return build(system=mg.time_transform(kepler_system(f" + {c}*x"), form="log"))


def test_run_into_U_zero_is_refused_at_the_step(build):
    mod = _field_module(build, 0.5)
    Y0 = mod.initial_state(ESCAPE)
    # with the resolution guards (default): refused as the fictive flow steepens towards U = 0
    with pytest.raises((mod.ResolutionError, mod.NonFiniteError)) as exc:
        mod.integrate(Y0, 0.01, 20000)
    assert exc.value.step > 0
    # without them, the domain check of log(T + e) refuses the step that crosses, naming the form
    with pytest.raises(mod.NonFiniteError, match="log form") as exc:
        mod.integrate(Y0, 0.001, 20000, check_resolution=False)
    state = dict(zip(mod.STATE_NAMES, exc.value.state))
    U = -1 / math.sqrt(state["x"] ** 2 + state["y"] ** 2 + state["z"] ** 2) + 0.5 * state["x"]
    assert exc.value.step > 0 and -0.1 < U, (exc.value.step, U)   # it stopped at U ≈ 0, not before


def test_hyperbolic_escape_names_the_log_form(build):
    # H = 1 > 0: as r grows T + e -> 0 cancels to 0 (r ~ 1e15 after 49 steps of h = 0.5) and the
    # step divides by it; the error said only "try a smaller step size h".  Control: the bound
    # orbit (H = -0.5) with the same h and steps runs to the end
    mod = build()
    with pytest.raises(mod.NonFiniteError, match="log form divides by T . e") as exc:
        mod.integrate(mod.initial_state(np.array([1.0, 0, 0, 0, 2.0, 0])), 0.5, 200, check_resolution=False)
    assert exc.value.step > 0 and "a smaller h does not help there" in str(exc.value)
    Y = mod.integrate(mod.initial_state(pericentre(0.6)), 0.5, 200, check_resolution=False)
    assert np.all(np.isfinite(Y))
    # a batch (the vectorised loop's non-finite check) says it too
    with pytest.raises(mod.NonFiniteError, match="log form divides by T . e"):
        mod.integrate(mod.initial_state(np.array([[1.0, 0, 0, 0, 2.0, 0], list(pericentre(0.6))])), 0.5, 200,
                      check_resolution=False)


@pytest.mark.slow
def test_numba_hyperbolic_escape_names_the_log_form(logh, tmp_path):
    # the numba runtime said only "state became non-finite at step 49" (the fast sibling:
    # test_hyperbolic_escape_names_the_log_form, numpy)
    mod = mg.build(logh, "stormer-verlet", backend="numba", path=tmp_path / "logh_nb.py")
    with pytest.raises(mod.NonFiniteError, match="log form divides by T . e") as exc:
        mod.integrate(mod.initial_state(np.array([1.0, 0, 0, 0, 2.0, 0])), 0.5, 200, check_resolution=False)
    assert exc.value.step == 49


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=pytest.mark.slow)])
def test_projected_escape_names_the_log_form(logh, tmp_path, backend):
    """The standard projection of the log form on the same escape: the numpy loop let Python's
    ZeroDivisionError out (no step, no word of the log form), the numba one said only "state
    became non-finite".  Now both raise NonFiniteError at step 49 with the hint and the rows
    before it.  Control: the bound orbit runs to the end."""
    mod = mg.build(logh, "stormer-verlet", backend=backend, project="energy-standard",
                   path=tmp_path / f"logh_proj_{backend}.py")
    with pytest.raises(mod.NonFiniteError, match="log form divides by T . e") as exc:
        mod.integrate(mod.initial_state(np.array([1.0, 0, 0, 0, 2.0, 0])), 0.5, 200, check_resolution=False)
    assert exc.value.step == 49 and exc.value.trajectory.shape == (50, 8)
    Y = mod.integrate(mod.initial_state(pericentre(0.6)), 0.5, 200, check_resolution=False)
    assert np.all(np.isfinite(Y))


def test_control_the_same_escape_without_the_field_runs_to_the_end(build):
    # c = 0: U = -k/r < 0 everywhere; the same escaping motion runs through, energy kept
    mod = _field_module(build, 0.0)
    Y = mod.integrate(mod.initial_state(ESCAPE), 0.001, 20000, check_resolution=False)
    y, t = mod.physical_state(Y)
    assert np.all(np.isfinite(Y)) and t[-1] > 1.0
    assert np.max(np.abs(energy(y) - energy(np.array(ESCAPE)))) < 1e-13


def test_initial_U_nonnegative_is_refused(build):
    mod = _field_module(build, 0.5)
    with pytest.raises(ValueError, match="must be > 0 at the initial state"):
        mod.initial_state(np.array([3.0, 0.0, 0.0, 0.0, 0.1, 0.0]))   # U = -1/3 + 1.5 > 0


def test_initial_state_with_a_zero_mass_is_a_domain_error(build):
    # 1/m with m = 0 raised a bare ZeroDivisionError from initial_state (a traceback on the
    # CLI); now the module's domain error naming the parameters.  Control: m = 1 gives the state
    mod = build()
    with pytest.raises(mod.NonFiniteError, match=r"H is not defined .*parameters \{'m': 0.0"):
        mod.initial_state(pericentre(0.6), 0.0, {"m": 0.0})
    Y = mod.initial_state(pericentre(0.6), 0.0, {"m": 1.0})
    assert Y[3] == pytest.approx(-energy(pericentre(0.6)))


# --- scene and CLI -----------------------------------------------------------------------------

def _main(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_builtin_scene_runs_and_keeps_the_energy(capsys):
    scene = mg.load_scene("kepler-logh")
    assert scene.run_system.time_transform.form == "log" and scene.run_system.name == "kepler-logh-log"
    code, out, err = _main(capsys, "run", "kepler-logh", "--steps", "300", "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert rep["time_transform"]["form"] == "log"
    assert rep["time_transform"]["t_final"] > 0
    assert rep["time_transform"]["H_phys_max_abs_error"] < 1e-12


def test_cli_zero_mass_is_one_line_without_traceback(capsys):
    code, out, err = _main(capsys, "run", "kepler-logh", "--param", "m=0", "--steps", "10")
    assert code != 0 and "H is not defined" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_cli_t_final_names_the_log_form(capsys):
    # the refusal read "with the time transformation g = log h and steps are ..."
    code, out, err = _main(capsys, "run", "kepler-logh", "--t-final", "10")
    assert code == 2 and "logarithmic Hamiltonian" in err and "g = log" not in err and "run_to_time" in err


def test_plot_pairs_of_the_exchanged_state(build, tmp_path):
    # The log form's state is (p..., e, q..., t): the default pairs by column order drew the
    # momentum plane px-py (the hodograph) and px-x; now the orbit x-y and x-px, y-py.
    # Control: the Poincaré form's (q..., t, p..., e) keeps the column-order pairs
    from methodgen.app.plots import default_pairs, module_pairs

    mod = build()
    names = mod.STATE_NAMES
    assert [(names[i], names[j]) for i, j in module_pairs(mod)] == [("x", "y"), ("x", "px"), ("y", "py")]
    assert (names[0], names[1]) == ("px", "py") and default_pairs(4)[0] == (0, 1)   # what was drawn
    tt = mg.generate(mg.discretize(mg.time_transform(kepler_system(), "sqrt(x**2 + y**2 + z**2)"), "midpoint"),
                     tmp_path / "kep_tt.py")
    assert module_pairs(tt) == default_pairs(4)
    assert [(tt.STATE_NAMES[i], tt.STATE_NAMES[j]) for i, j in module_pairs(tt)] == [("x", "y"), ("x", "px"),
                                                                                      ("y", "py")]


def test_cli_time_transform_log_on_kepler(capsys):
    code, out, err = _main(capsys, "run", "kepler", "--time-transform", "log", "--method", "stormer-verlet",
                           "--steps", "200", "--json")
    assert code == 0, err
    assert json.loads(out)["time_transform"]["form"] == "log"


@pytest.mark.parametrize("scene, fragment", [("harmonic", "≥ 0 everywhere"),
                                             ("henon-heiles-2d", "needs U(q) < 0")])
def test_cli_refuses_where_the_log_form_does_not_apply(capsys, scene, fragment):
    code, out, err = _main(capsys, "run", scene, "--time-transform", "log", "--method", "stormer-verlet")
    assert code == cli.EXIT_INPUT, (code, out, err)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and fragment in err, err


# --- exact certificates --------------------------------------------------------------------------

def test_log_form_certificates_are_proved(logh):
    from methodgen.symbolic.verify.report import PROVED
    from methodgen.symbolic.verify.timetransform import time_transform_certificates

    certs = time_transform_certificates(logh)
    assert len(certs) == 3 and all(c.status == PROVED for c in certs), [(c.claim, c.status) for c in certs]


def test_control_certificates_refute_the_sign_flipped_lambda(logh):
    # Λ itself (not −Λ) on the exchanged state runs the flow backwards: 1L and 3L are refuted.
    from methodgen.symbolic.verify.report import PROVED, REFUTED
    from methodgen.symbolic.verify.timetransform import time_transform_certificates

    wrong = mg.Hamiltonian(-logh.H, q=[s.name for s in logh.q], p=[s.name for s in logh.p],
                           params=logh.param_values, name="wrong")
    object.__setattr__(wrong, "time_transform", logh.time_transform)
    status = [c.status for c in time_transform_certificates(wrong)]
    assert status == [REFUTED, PROVED, REFUTED], status


@pytest.mark.slow
def test_numba_order_10_reaches_T_to_1e10_with_energy_to_round_off(logh, tmp_path):
    # The benchmark's configuration on a shorter T (numba compile ~20 s: slow; the numpy runs
    # above cover the same generated step).  Measured: T = 2000, 16 steps per orbit: 7.7e-12.
    pytest.importorskip("llvmlite")
    scheme = mg.discretize(logh, "stormer-verlet", order=10)
    mod = mg.generate(scheme, tmp_path / "logh_o10_numba.py", backend="numba")
    info = {}
    Y = run_to_time(mod, mod.initial_state(pericentre(0.6)), 200.0, 2 * math.pi / 16, info=info)
    y, t = mod.physical_state(Y)
    assert t == pytest.approx(200.0, abs=2 * np.spacing(200.0))
    assert np.max(np.abs(y - kepler_exact(0.6, 200.0))) < 1e-10
    assert abs(energy(y) + 0.5) / 0.5 < 1e-14


def test_cli_method_not_applicable_to_the_log_form_says_so(capsys):
    code, out, err = _main(capsys, "run", "kepler-logh", "--method", "energy-momentum")
    assert code == cli.EXIT_INPUT, (code, out, err)
    assert "logarithmic Hamiltonian" in err and "stormer-verlet" in err and "Traceback" not in err, err


def test_bench_peers_has_log_form_rows_at_the_physical_T():
    from methodgen.app import bench

    out = bench.work_precision(mg.load_scene("kepler-logh"), peers=True, quick=True, orders=(2,), T=2 * math.pi)
    log = [r for r in out["rows"] if r["method"].endswith("[log]")]
    plain = [r for r in out["rows"] if r["method"] == "stormer-verlet"]
    assert len(log) == 2 and all(r["errors_at_T_only"] and abs(r["t_error"]) <= 1e-14 for r in log), log
    assert all(r["energy_rel_error"] < 1e-13 for r in log), log
    # control: the same method on H in physical time at the same h does not resolve e = 0.99
    assert min(r["error"] for r in plain if "error" in r) > 100 * max(r["error"] for r in log), (plain, log)


def test_bench_peers_log_rows_use_the_family():
    # --composition F chose the family of the rows on H but the [log] rows kept the order's
    # default (suzuki at order 4): both now use F
    from methodgen.app import bench

    out = bench.work_precision(mg.load_scene("kepler-logh"), peers=True, quick=True, orders=(4,),
                               T=2 * math.pi, composition="mclachlan")
    log = [r for r in out["rows"] if r["method"].endswith("[log]")]
    assert log and all(r["composition"] == "mclachlan" and "mclachlan" in r["method"] for r in log), log
    plain = [r for r in out["rows"] if r["kind"] == "methodgen" and not r["method"].endswith("[log]")]
    assert plain and all(r["composition"] == "mclachlan" for r in plain), plain


@pytest.mark.parametrize("form", ["log", "poincare"])
def test_angular_momenta_keep_their_original_names_and_signs(form):
    """The monitored L of a transformed Kepler system are the original's (Lx, Ly, Lz of q × p)."""
    from methodgen.symbolic import derive
    sy = kepler_system()
    tt = (mg.time_transform(sy, form="log") if form == "log"
          else mg.time_transform(sy, "sqrt(x**2 + y**2 + z**2)"))
    got = {inv.name: inv.expr for inv in derive.angular_momenta(tt)}
    want = {inv.name: inv.expr for inv in derive.angular_momenta(sy)}
    assert set(want) == {"Lx", "Ly", "Lz"} and got == want
    # control: the extended system's own coordinate planes name (and, in the log form, sign) them otherwise
    plain = mg.Hamiltonian(tt.H, q=[s.name for s in tt.q], p=[s.name for s in tt.p], params=tt.param_values)
    own = {inv.name for inv in derive.angular_momenta(plain)}
    assert own and own.isdisjoint(want)
