"""A family module's run continued in chunks is bitwise the run in one piece (``integrate(...,
info=...)``, the ``info["carried"]`` record), and ``solve(..., events=...)``'s rows are bitwise the
rows of the run without events.

Each kind (1-D lattice at order 4: a predictor history per stage; 2-D lattice; particles:
the Kahan compensation, energy-momentum and a Störmer–Verlet composition), numpy and compiled.
Controls: the same chunks without the record (each started afresh, as before) differ from the
run in one piece; the event run without the carried record differs from the plain run.  A
record of another module, state, h, parameters or arrays is not used (the run is the fresh
one); a malformed, inconsistent, edited or hand-built record is refused, naming what is valid.
"""

from __future__ import annotations

import copy
import functools

import numpy as np
import pytest

from methodgen.app.lattice_scene import load_lattice_scene
from methodgen.app.particles_scene import load_particles_scene
from methodgen.codegen.lattice_emit import build_lattice
from methodgen.codegen.particle_emit import build_particles
from methodgen.runtime.events import solve_family

BACKENDS = ("numpy", "compiled")
#: the chunks of a 20-step run (1 and 2: a chunk ends inside the predictor's start-up)
CHUNKS = (1, 2, 5, 12)


@pytest.fixture(scope="module")
def cases():
    """name -> (module, y0, h, options) for every kind and backend (the modules from the cache)."""
    sg, kg = load_lattice_scene("sine-gordon"), load_lattice_scene("klein-gordon-2d")
    ring = load_particles_scene("nbody-ring")
    y0r, arrays = ring.state(3)
    out = {}
    for b in BACKENDS:
        out[f"lattice-1d-o4-{b}"] = (build_lattice(sg.lattice, "avf", order=4, backend=b), sg.y0(12), 0.05, {})
        out[f"lattice-2d-{b}"] = (build_lattice(kg.lattice, "avf", backend=b), kg.y0((6, 5)), 0.1, {})
        out[f"particles-em-{b}"] = (build_particles(ring.family, "energy-momentum", backend=b), y0r, 0.02,
                                    {"arrays": arrays})
        out[f"particles-sv4-{b}"] = (build_particles(ring.family, "stormer-verlet", order=4, backend=b), y0r, 0.02,
                                     {"arrays": arrays})
    return out


NAMES = [f"{k}-{b}" for b in BACKENDS for k in ("lattice-1d-o4", "lattice-2d", "particles-em", "particles-sv4")]


def _chunked(mod, y0, h, kw, carry=True):
    """The rows of the run in CHUNKS, one info through them (carry) or a fresh one per chunk."""
    info, y, rows = {}, y0, [np.asarray(y0, dtype=float)]
    for m in CHUNKS:
        if not carry:
            info = {}
        part = mod.integrate(y, h, m, info=info, **kw)
        rows += list(part[1:])
        y = part[-1]
    return np.array(rows)


@pytest.mark.parametrize("name", NAMES)
def test_a_run_in_chunks_is_bitwise_the_run_in_one_piece(cases, name):
    mod, y0, h, kw = cases[name]
    one = mod.integrate(y0, h, sum(CHUNKS), **kw)
    assert _chunked(mod, y0, h, kw).tobytes() == one.tobytes()
    # control: started afresh at every chunk (the carried state dropped) the run differs
    assert _chunked(mod, y0, h, kw, carry=False).tobytes() != one.tobytes()


@pytest.mark.parametrize("name", ["lattice-1d-o4-numpy", "lattice-1d-o4-compiled"])
def test_the_record_holds_each_stage_history(cases, name):
    """The 1-D record carries per stage its last two increments (NaN before a step is taken), and
    a zero-step call leaves the record it was given as it is."""
    mod, y0, h, kw = cases[name]
    info = {}
    mod.integrate(y0, h, 1, info=info)
    key, y, hh, p, arrays, c = info["carried"]
    assert c.shape == (2, len(mod.GAMMAS), 2, 12) and hh == h and arrays is None
    assert np.all(np.isfinite(c[0])) and np.all(np.isnan(c[1]))
    y1 = mod.integrate(y0, h, 1)[-1]
    assert y.tobytes() == y1.tobytes()
    before = info["carried"][5].copy()
    mod.integrate(y, h, 0, info=info)
    assert info["carried"][5].tobytes() == before.tobytes()


def _with(fn, **attrs):
    def g(t, y):
        return fn(t, y)
    for k, v in attrs.items():
        setattr(g, k, v)
    return g


@pytest.mark.parametrize("name", ["lattice-1d-o4-compiled", "lattice-2d-numpy", "particles-em-numpy",
                                  "particles-sv4-compiled"])
def test_event_rows_are_bitwise_the_plain_run(cases, name):
    mod, y0, h, kw = cases[name]
    span = (0.0, 150 * h)          # more than the first chunk (64 steps): three chunks
    g = _with(lambda t, y: float(np.asarray(y).reshape(-1)[0]) - float(np.asarray(y0).reshape(-1)[0]))
    plain = mod.solve(y0, span, h, **kw)
    ev = mod.solve(y0, span, h, events=g, **kw)
    assert ev.status == 0 and ev.y.shape == plain.y.shape
    assert ev.y.tobytes() == plain.y.tobytes()

    # control: the same location with each chunk started afresh (the record dropped, as before)
    @functools.wraps(mod.integrate)         # (its options, for solve_family's check of them)
    def afresh(y, hh, m, params=None, *, info=None, **options):
        if info is not None:
            info.pop("carried", None)
        return mod.integrate(y, hh, m, params, info=info, **options)

    opts = dict(kw)
    arrays = opts.pop("arrays", None)
    inv = (lambda y: mod.invariants(y, None, arrays)) if arrays is not None else (lambda y: mod.invariants(y))
    if arrays is not None:
        opts["arrays"] = arrays
    ctl = solve_family(afresh, y0, 0.0, plain.h, 150, None, g, options=opts, invariants=inv,
                       solution=mod.Solution, failures=(mod.ConvergenceError, mod.NonFiniteError))
    assert ctl.y.shape == plain.y.shape and ctl.y.tobytes() != plain.y.tobytes()


def _fresh(mod, y0, h, kw, m=6):
    return mod.integrate(y0, h, m, **kw)


@pytest.mark.parametrize("name", ["lattice-1d-o4-numpy", "lattice-2d-compiled", "particles-em-compiled",
                                  "particles-sv4-numpy"])
def test_a_record_of_another_run_is_not_used(cases, name):
    """Another module's (the other backend's), another state's, h's, parameters' or arrays' record:
    the run is the fresh one, bitwise; control: the honest record is used (the run differs)."""
    mod, y0, h, kw = cases[name]
    info = {}
    y1 = mod.integrate(y0, h, 4, info=info, **kw)[-1]
    fresh = _fresh(mod, y1, h, kw)
    assert _fresh(mod, y1, h, dict(kw, info=dict(info))).tobytes() != fresh.tobytes()     # (control)
    # another module (the other backend's): this record is not its own
    other = cases[name.replace("numpy", "X").replace("compiled", "numpy").replace("X", "compiled")][0]
    assert _fresh(other, y1, h, dict(kw, info=dict(info))).tobytes() == _fresh(other, y1, h, kw).tobytes()
    y1b = np.array(y1, dtype=float)
    y1b.reshape(-1)[0] += 1e-9
    assert _fresh(mod, y1b, h, dict(kw, info=dict(info))).tobytes() == _fresh(mod, y1b, h, kw).tobytes()
    assert _fresh(mod, y1, 0.5 * h, dict(kw, info=dict(info))).tobytes() == _fresh(mod, y1, 0.5 * h, kw).tobytes()
    if mod.PARAM_NAMES:
        p = {mod.PARAM_NAMES[0]: 1.01 * mod.DEFAULT_PARAMS[mod.PARAM_NAMES[0]]}
        assert (_fresh(mod, y1, h, dict(kw, params=p, info=dict(info))).tobytes()
                == _fresh(mod, y1, h, dict(kw, params=p)).tobytes())
    if "arrays" in kw:
        arr = {k: np.asarray(v, dtype=float) * 1.001 for k, v in kw["arrays"].items()}
        assert (_fresh(mod, y1, h, dict(kw, arrays=arr, info=dict(info))).tobytes()
                == _fresh(mod, y1, h, dict(kw, arrays=arr)).tobytes())


@pytest.mark.parametrize("name", ["lattice-1d-o4-compiled", "lattice-2d-numpy", "particles-em-numpy",
                                  "particles-sv4-compiled"])
def test_a_malformed_edited_or_hand_built_record_is_refused(cases, name):
    mod, y0, h, kw = cases[name]
    info = {}
    y1 = mod.integrate(y0, h, 4, info=info, **kw)[-1]
    rec = info["carried"]
    for bad in ("x", rec[:5], (rec[0], list(rec[1]), *rec[2:]), (*rec[:5], "c")):
        with pytest.raises(ValueError, match=r"module key, state, h, parameters, arrays, carried state"):
            mod.integrate(y1, h, 2, info={"carried": bad}, **kw)
    with pytest.raises(ValueError, match="inconsistent.*carries"):
        mod.integrate(y1, h, 2, info={"carried": (*rec[:5], rec[5][..., :-1])}, **kw)
    # built by hand (a copy), pickled alike: refused, its carried state cannot be checked
    with pytest.raises(ValueError, match="did not leave as it is"):
        mod.integrate(y1, h, 2, info={"carried": copy.deepcopy(rec)}, **kw)
    # edited in place
    held = rec[5].copy()
    rec[5][...] = held * 1.5 + 1e-17      # (NaN, a step not taken, stays NaN)
    with pytest.raises(ValueError, match="did not leave as it is"):
        mod.integrate(y1, h, 2, info={"carried": rec}, **kw)
    # control: the record as it was left is used
    rec[5][...] = held
    mod.integrate(y1, h, 2, info={"carried": rec}, **kw)
