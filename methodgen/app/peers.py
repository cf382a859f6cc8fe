"""Peers on the same problem: heyoka (Taylor series) and REBOUND (IAS15, WHFast).

``methodgen bench SCENE --peers`` runs them next to methodgen's own methods and
puts them in the same work-precision table and plot (:func:`methodgen.app.bench.work_precision`).
Both are optional (``pip install "methodgen[peers]"``); a missing one is a note
in the report, never an error.

* **heyoka** [1]_ integrates the scene's own vector field ``f = J∇H``:
  :func:`heyoka_system` walks the SymPy tree of every component of ``f`` and
  rebuilds it from heyoka expressions (``+ * **``, ``sqrt exp log sin cos tan
  sinh cosh tanh atan``, ``pi``; the grammar of :mod:`methodgen.problem.parse`), with the
  parameters as constants of the integrator's floating-point type.  Nothing is
  written by hand per scene.  Rows over a tolerance ladder (:data:`HEYOKA_TOLERANCES`).
  heyoka in long double at ``tol = 1e-18`` (:func:`heyoka_reference`) is also the
  reference solution of ``--peers`` where no exact solution is known.
* **REBOUND** [2]_ (IAS15 [3]_ over :data:`IAS15_EPSILONS`; WHFast [4]_ with
  symplectic correctors of order 11 over a step-size ladder) integrates particles,
  so it applies only to scenes that *declare* that they are N-body problems with
  an ``[nbody]`` table (:class:`methodgen.symbolic.scene.NBody`): body ``b`` is
  ``q[3b:3b+3]`` with velocity ``p[3b:3b+3]/m_b``.  The declaration is checked
  against H at random states before use (:func:`nbody_mismatch`); a scene
  without one, or whose declaration does not match H, is skipped with a note.

Every peer row carries the keys of methodgen's rows (``method``, ``kind``, ``tol``
or ``h``, ``steps``, ``seconds``, ``error``, ``energy_error``,
``energy_rel_error``, ``invariant_errors``): the CPU time (``time.process_time``)
of the integration call alone, the minimum over :data:`REPEATS` runs (integrator
construction, heyoka's JIT compilation and particle set-up excluded, reported as
``setup_seconds``); the error at the final time against the same reference as
every other row; energy and invariant errors from the scene's generated module
(``module.invariants``) over *every* step of a separate, untimed run of the same
integrator (a step callback / REBOUND heartbeat), so they measure the peer's
trajectory exactly as methodgen's rows measure theirs.

.. [1] F. Biscani, D. Izzo, "Revisiting high-order Taylor methods for astrodynamics and
   celestial mechanics", MNRAS 504 (2021) 2614-2628.
.. [2] H. Rein, S.-F. Liu, "REBOUND: an open-source multi-purpose N-body code for
   collisional dynamics", A&A 537 (2012) A128.
.. [3] H. Rein, D. S. Spiegel, "IAS15: a fast, adaptive, high-order integrator for
   gravitational dynamics, accurate to machine precision over a billion orbits",
   MNRAS 446 (2015) 1424-1437.
.. [4] H. Rein, D. Tamayo, "WHFAST: a fast and unbiased implementation of a symplectic
   Wisdom-Holman integrator for long-term gravitational simulations", MNRAS 452 (2015) 376-388.
"""

from __future__ import annotations

import functools
import math
import operator
import time

import numpy as np
import sympy as sp

from ..symbolic.derive import vector_field
from ..errors import MethodgenError
from .stats import max_abs_error

__all__ = ["PeerUnsupported", "HEYOKA_TOLERANCES", "QUICK_HEYOKA_TOLERANCES", "heyoka_nbody", "IAS15_EPSILONS", "WHFAST_FACTORS", "REPEATS",
           "REFERENCE_TOL", "versions", "import_peer", "heyoka_system", "heyoka_rows",
           "heyoka_reference", "nbody_mismatch", "nbody_monitors", "rebound_rows", "min_cpu"]

#: heyoka's tolerance ladder, a decade apart (its order follows from the tolerance): a
#: coarser ladder left gaps where heyoka reaches a level between its points (tol 1e-14 reaches
#: 1.5e-12 on the outer solar system, where 1e-12 and 1e-15 bracket it).
HEYOKA_TOLERANCES = (1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14, 1e-15)
#: ``bench --peers --quick``: every other decade (the table says which were left out).
QUICK_HEYOKA_TOLERANCES = (1e-9, 1e-11, 1e-13, 1e-15)
#: The reference solution: heyoka in long double (64-bit mantissa), high-accuracy mode.
REFERENCE_TOL = 1e-18
#: IAS15's ε (1e-9 is REBOUND's default, "machine precision").
IAS15_EPSILONS = (1e-5, 1e-7, 1e-9)
#: WHFast step sizes as multiples of the scene's h.
WHFAST_FACTORS = (4.0, 2.0, 1.0, 0.5)
#: Timed runs per row; the row reports the minimum CPU time.
REPEATS = 3

INSTALL_HINT = 'pip install "methodgen[peers]"'


class PeerUnsupported(MethodgenError):
    """A peer cannot run this scene (a function heyoka lacks, constraints, no ``[nbody]``)."""


def import_peer(name: str):
    """The module ``name`` (``"heyoka"`` or ``"rebound"``), or None when it is not installed."""
    try:
        if name == "heyoka":
            import heyoka as mod
        elif name == "rebound":
            import rebound as mod
        else:  # pragma: no cover - internal
            raise ValueError(name)
    except ImportError:
        return None
    return mod


def versions() -> dict:
    """``{"heyoka": version or None, "rebound": version or None}``."""
    out = {}
    for name in ("heyoka", "rebound"):
        mod = import_peer(name)
        out[name] = None if mod is None else str(getattr(mod, "__version__", "unknown"))
    return out


def min_cpu(run, repeats: int = REPEATS, long_run: float = 5.0):
    """``(min CPU seconds, result of the last call)`` over ``repeats`` calls of ``run()``.

    A call longer than ``long_run`` seconds is not repeated (one long run is already a
    stable measurement; three would triple a bench that is long anyway).
    """
    best, out = math.inf, None
    for _ in range(max(1, repeats)):
        t0 = time.process_time()
        out = run()
        sec = time.process_time() - t0
        best = min(best, sec)
        if sec > long_run:
            break
    return best, out


# --- heyoka ---------------------------------------------------------------------------

_HY_FUNCTIONS = {sp.exp: "exp", sp.log: "log", sp.sin: "sin", sp.cos: "cos", sp.tan: "tan",
                 sp.sinh: "sinh", sp.cosh: "cosh", sp.tanh: "tanh", sp.atan: "atan"}


def _to_heyoka(expr, env: dict, const, hy):
    """The heyoka expression of the SymPy expression ``expr`` (a walk of its tree).

    ``env`` maps SymPy symbols to heyoka expressions; ``const(x)`` makes a numeric
    constant of the integrator's floating-point type from a SymPy number.
    """
    rec = functools.partial(_to_heyoka, env=env, const=const, hy=hy)
    if expr.is_Symbol:
        if expr not in env:
            raise PeerUnsupported(f"heyoka: unknown symbol {expr}")
        return env[expr]
    if expr.is_Number or expr.is_NumberSymbol:  # integers, rationals, floats, pi, E
        return const(expr)
    if expr.is_Add:
        return hy.sum([rec(a) for a in expr.args])
    if expr.is_Mul:
        return functools.reduce(operator.mul, [rec(a) for a in expr.args])
    if expr.is_Pow:
        base, e = expr.args
        if e == sp.Rational(1, 2):
            return hy.sqrt(rec(base))
        if e.is_Integer or e.is_Rational:
            # Integral and dyadic exponents are exact in every floating-point type.
            return rec(base) ** const(e)
        return rec(base) ** rec(e)
    for cls, name in _HY_FUNCTIONS.items():
        if isinstance(expr, cls):
            return getattr(hy, name)(rec(expr.args[0]))
    raise PeerUnsupported(f"heyoka: no translation for {type(expr).__name__} ({expr}); the grammar is "
                          "+ * ** sqrt exp log sin cos tan sinh cosh tanh atan")


def _constant_maker(fp_type, hy):
    """SymPy number -> heyoka constant, correctly rounded to ``fp_type`` (float or longdouble)."""
    def const(x):
        if fp_type is float:
            return hy.expression(float(sp.N(x, 40)))
        # 40 significant digits parse to the nearest long double (64-bit mantissa).
        return hy.expression(np.longdouble(str(sp.N(x, 40))))
    return const


def heyoka_system(system, fp_type=float, params: dict | None = None):
    """``(variables, [(var, rhs), ...])``: heyoka's form of ``y' = J∇H(y)`` for ``system``.

    Built from :func:`methodgen.symbolic.derive.vector_field` by walking each component's
    SymPy tree; parameters (default: ``system.param_values``) become constants of
    ``fp_type`` (``float`` or ``numpy.longdouble``).

    Raises
    ------
    PeerUnsupported
        Constrained systems (a DAE: heyoka integrates ODEs), or an expression
        outside the grammar.
    """
    hy = import_peer("heyoka")
    if hy is None:
        raise PeerUnsupported(f"heyoka is not installed ({INSTALL_HINT})")
    if system.constraints:
        raise PeerUnsupported("heyoka: constrained scenes are DAEs; heyoka integrates ODEs (skipped)")
    values = dict(system.param_values, **(params or {}))
    const = _constant_maker(fp_type, hy)
    names = [s.name for s in system.y]
    variables = hy.make_vars(*names)
    if len(names) == 1:  # make_vars returns a bare expression for one name
        variables = [variables]
    env = dict(zip(system.y, variables))
    env.update({s: const(sp.Float(values[s.name], 40)) for s in system.params})
    f = vector_field(system)
    return list(variables), [(v, _to_heyoka(fi, env, const, hy)) for v, fi in zip(variables, f)]


def _heyoka_integrator(system, y0, tol, fp_type=float, high_accuracy=False):
    hy = import_peer("heyoka")
    _, sys_ = heyoka_system(system, fp_type)
    if fp_type is float:
        return hy.taylor_adaptive(sys_, [float(v) for v in y0], tol=float(tol), high_accuracy=high_accuracy)
    return hy.taylor_adaptive(sys_, [np.longdouble(v) for v in y0], tol=np.longdouble(tol),
                              fp_type=np.longdouble, high_accuracy=high_accuracy)


def heyoka_reference(system, y0, T: float, tol: float = REFERENCE_TOL) -> np.ndarray:
    """Final state at ``T`` from heyoka in long double, ``high_accuracy=True``, tolerance ``tol``.

    Returned rounded to float64.  Measured: Kepler e = 0.6, T = 2000: 7e-15 from the exact
    solution (Kepler's equation at 40 digits), DOP853 at rtol 1e-13 is 3e-8 off; outer solar
    system, T = 2·10⁵ days, and Hénon–Heiles 2-DOF, T = 10⁴: within 1e-14 and 5e-15 of heyoka
    in quadruple precision (tol 1e-28), DOP853 1e-9 and 2e-8 off (``tests/test_bench_peers.py``
    checks the Kepler case on a shorter interval).
    """
    if np.finfo(np.longdouble).nmant <= 52:
        raise PeerUnsupported("numpy.longdouble is plain double here: no long-double heyoka reference")
    ta = _heyoka_integrator(system, y0, tol, np.longdouble, high_accuracy=True)
    out = ta.propagate_until(np.longdouble(T))
    _check_outcome(out[0], "heyoka reference")
    return np.array(ta.state, dtype=np.float64)


def _check_outcome(outcome, what):
    name = getattr(outcome, "name", str(outcome))
    if "time_limit" not in str(name):
        raise RuntimeError(f"{what}: integration stopped with outcome {name}")


def heyoka_nbody(scene, module):
    """heyoka's own N-body model for an ``[nbody]`` scene of free bodies, or None.

    ``model.nbody`` writes the pair accelerations as heyoka's authors do (one ``r⁻³`` per
    pair, shared by both bodies): 1.2–2.4× faster than heyoka integrating our translation of
    H's vector field, so on N-body scenes it is the peer's best formulation and the one
    compared against.  Its state is per body ``(x, y, z, vx, vy, vz)``; ours is
    ``(q, p)`` with ``p = m v``.

    Returns
    -------
    (sys, to_heyoka, from_heyoka) or None
        None where it does not apply: no ``[nbody]`` table, a fixed centre, or a declaration
        that does not match H (:func:`nbody_mismatch` ≥ 1e-12).
    """
    hy = import_peer("heyoka")
    if hy is None or scene.nbody is None or scene.nbody.centre_mass is not None:
        return None
    if not nbody_mismatch(scene, module) < 1e-12:
        return None
    G, m, _ = _nbody_numbers(scene)
    n = len(m)
    sys_ = hy.model.nbody(n, masses=[float(v) for v in m], Gconst=float(G))

    def to_heyoka(y):
        y = np.asarray(y, dtype=float)
        q, p = y[:3 * n].reshape(n, 3), y[3 * n:].reshape(n, 3)
        return np.concatenate([q, p / m[:, None]], axis=1).ravel()

    def from_heyoka(s):
        s = np.asarray(s, dtype=float).reshape(n, 6)
        return np.concatenate([s[:, :3].ravel(), (s[:, 3:] * m[:, None]).ravel()])

    return sys_, to_heyoka, from_heyoka


def heyoka_rows(scene, module, y0, T: float, y_ref, errors, *, tolerances=HEYOKA_TOLERANCES,
                repeats: int = REPEATS, say=None) -> list[dict]:
    """heyoka (double precision) at each tolerance: one row each (see the module docstring).

    ``errors(traj)`` is the bench's error function (final error against the reference,
    energy and invariant errors) applied to the trajectory of every step.  On an ``[nbody]``
    scene heyoka runs its own N-body model (:func:`heyoka_nbody`; the row's method says so),
    elsewhere our translation of the scene's vector field.  ``say(text)``: progress lines.
    """
    rows = []
    y0 = np.asarray(y0, dtype=float)
    nbody = heyoka_nbody(scene, module)
    label = "heyoka (Taylor) model.nbody" if nbody is not None else "heyoka (Taylor)"
    to_h, from_h = (nbody[1], nbody[2]) if nbody is not None else ((lambda y: y), (lambda s: np.array(s)))
    s0 = to_h(y0)
    hy = import_peer("heyoka")
    for k, tol in enumerate(tolerances):
        if say is not None:
            say(f"{label} tol {tol:g} ({k + 1} of {len(tolerances)})")
        t0 = time.perf_counter()
        if nbody is not None:
            ta = hy.taylor_adaptive(nbody[0], [float(v) for v in s0], tol=float(tol))
        else:
            ta = _heyoka_integrator(scene.system, y0, tol)
        setup = time.perf_counter() - t0

        def run():
            ta.time = 0.0
            ta.state[:] = s0
            return ta.propagate_until(float(T))

        sec, out = min_cpu(run, repeats)
        try:
            _check_outcome(out[0], f"heyoka tol={tol:g}")
        except RuntimeError as exc:
            rows.append({"method": label, "kind": "heyoka", "tol": tol, "failed": str(exc)})
            continue
        final = from_h(ta.state)
        states = [y0.copy()]

        def record(integrator):
            states.append(from_h(integrator.state))
            return True

        ta.time = 0.0
        ta.state[:] = s0
        ta.propagate_until(float(T), callback=record)
        traj = np.array(states)
        row = {"method": label, "kind": "heyoka", "tol": tol, "steps": int(out[3]),
               "order": int(ta.order), "seconds": sec, "setup_seconds": setup, **errors(traj)}
        # The timed run and the recorded run are the same computation; keep the timed final state.
        row["error"] = max_abs_error(final, y_ref)
        rows.append(row)
    return rows


# --- N-body scenes and REBOUND ---------------------------------------------------------

def _nbody_numbers(scene):
    G, masses, centre = scene.nbody.values(scene.system.param_values)
    return G, np.array(masses), centre


def nbody_hamiltonian(scene, Y) -> np.ndarray:
    """The Hamiltonian that the ``[nbody]`` declaration describes, at the states ``Y`` (n, 2d)."""
    from ..runtime.nbody import nbody_energy

    G, m, centre = _nbody_numbers(scene)
    return nbody_energy(np.atleast_2d(np.asarray(Y, dtype=float)), G, m, centre)


def nbody_mismatch(scene, module, samples: int = 8, seed: int = 0) -> float:
    """Largest relative difference between H (the generated module) and the ``[nbody]`` H.

    At ``samples`` states around the scene's y0 (every component perturbed by 1 % of
    its scale, momenta and positions separately).  Round-off level (< 1e-12) means
    the declaration describes this Hamiltonian.
    """
    rng = np.random.default_rng(seed)
    y0 = np.asarray(scene.y0, dtype=float)
    d = len(y0) // 2
    scale = np.concatenate([np.full(d, max(np.max(np.abs(y0[:d])), 1e-300)),
                            np.full(d, max(np.max(np.abs(y0[d:])), 1e-300))])
    Y = y0 + 0.01 * scale * rng.standard_normal((samples, len(y0)))
    H = np.asarray(module.hamiltonian(Y), dtype=float)
    Hn = nbody_hamiltonian(scene, Y)
    return float(np.max(np.abs(H - Hn) / np.maximum(np.abs(H), np.abs(Hn))))


def nbody_monitors(scene):
    """For an ``[nbody]`` scene with several bodies: total angular and linear momentum along a trajectory.

    Returns ``traj -> {"Lx", "Ly", "Lz", "Px", "Py", "Pz": arrays}`` or None (no
    ``[nbody]``, or one body about a fixed centre, where q × p is already monitored
    by the module and linear momentum is not conserved).
    """
    if scene.nbody is None or scene.nbody.centre_mass is not None:
        return None
    nb = len(scene.nbody.masses)

    def monitors(traj):
        from ..runtime.nbody import nbody_momenta

        return nbody_momenta(traj, nb)

    return monitors


def _rebound_sim(rebound, scene, y0, integrator: str, param: float):
    G, m, centre = _nbody_numbers(scene)
    nb = len(m)
    q = np.asarray(y0[:3 * nb], dtype=float).reshape(nb, 3)
    v = (np.asarray(y0[3 * nb:], dtype=float).reshape(nb, 3)) / m[:, None]
    sim = rebound.Simulation()
    sim.G = G
    if centre is not None:
        # A fixed centre: a massive particle at rest at the origin, the body a test
        # particle (it feels the centre and does not move it), as in the scene's H.
        sim.add(m=centre)
        sim.add(m=0.0, x=q[0, 0], y=q[0, 1], z=q[0, 2], vx=v[0, 0], vy=v[0, 1], vz=v[0, 2])
    else:
        for b in range(nb):
            sim.add(m=float(m[b]), x=q[b, 0], y=q[b, 1], z=q[b, 2], vx=v[b, 0], vy=v[b, 1], vz=v[b, 2])
    sim.integrator = integrator
    if integrator == "ias15":
        _configure(sim, "ias15", epsilon=param)
    else:
        sim.dt = param
        _configure(sim, "whfast", corrector=11, safe_mode=0)
    return sim


def _configure(sim, integrator: str, **fields):
    """Set integrator fields: ``sim.integrator.<field>`` (REBOUND 5), ``sim.ri_<name>.<field>`` (REBOUND 4)."""
    target = sim.integrator
    if isinstance(target, str):  # REBOUND 4: the integrator is a name, its settings live in ri_<name>
        target = getattr(sim, f"ri_{integrator}")
    for key, value in fields.items():
        setattr(target, key, value)


def _rebound_state(scene, sim) -> np.ndarray:
    """The scene's state (q, p = m v) of the particles of ``sim``."""
    _, m, centre = _nbody_numbers(scene)
    N = sim.N
    xyz, vxyz = np.zeros((N, 3)), np.zeros((N, 3))
    sim.serialize_particle_data(xyz=xyz, vxvyvz=vxyz)
    if centre is not None:
        xyz, vxyz = xyz[1:], vxyz[1:]
    return np.concatenate([xyz.ravel(), (vxyz * m[:, None]).ravel()])


def rebound_rows(scene, module, y0, T: float, y_ref, errors, *, epsilons=IAS15_EPSILONS,
                 whfast_steps=None, repeats: int = REPEATS) -> list[dict]:
    """REBOUND rows: IAS15 at each ε, WHFast (Jacobi coordinates, corrector 11) at each step size.

    ``whfast_steps``: WHFast step sizes (default ``scene.h`` × :data:`WHFAST_FACTORS`), each
    rounded to ``T/round(T/h)`` so that the steps end at ``T``.

    Raises
    ------
    PeerUnsupported
        No ``[nbody]`` table, or one that does not describe the scene's H.
    """
    rebound = import_peer("rebound")
    if rebound is None:
        raise PeerUnsupported(f"rebound is not installed ({INSTALL_HINT})")
    if scene.nbody is None:
        raise PeerUnsupported("REBOUND: the scene declares no [nbody] table (masses and G), "
                              "so it is not handed to an N-body code (skipped)")
    mismatch = nbody_mismatch(scene, module)
    if not mismatch < 1e-12:
        raise PeerUnsupported(f"REBOUND: the scene's [nbody] table does not describe its H (relative "
                              f"difference {mismatch:.1e} at states near y0; skipped)")
    y0 = np.asarray(y0, dtype=float)
    runs = [("ias15", eps) for eps in epsilons]
    for h in (whfast_steps if whfast_steps is not None else [scene.h * f for f in WHFAST_FACTORS]):
        n = max(1, round(T / h))
        runs.append(("whfast", T / n))
    rows = []
    for integrator, param in runs:
        sims = []

        def run():
            sim = _rebound_sim(rebound, scene, y0, integrator, param)
            sims.append(sim)
            t0 = time.process_time()
            sim.integrate(T)
            return time.process_time() - t0, sim

        label = "REBOUND IAS15" if integrator == "ias15" else "REBOUND WHFast"
        setting = {"tol": param} if integrator == "ias15" else {"h": param}
        # Particle set-up is excluded: time the integrate call only.
        best = math.inf
        try:
            for _ in range(max(1, repeats)):
                sec, sim = run()
                best = min(best, sec)
                if sec > 5.0:
                    break
            final = _rebound_state(scene, sim)
            steps = int(sim.steps_done)
            # Untimed run of the same integrator, recording every step (heartbeat).
            rec = _rebound_sim(rebound, scene, y0, integrator, param)
            if integrator == "whfast":
                _configure(rec, "whfast", safe_mode=1)  # synchronised particles after every step (same map)
            states = []
            rec.heartbeat = lambda simp: states.append(_rebound_state(scene, simp.contents))
            rec.integrate(T)
        except Exception as exc:  # noqa: BLE001 - REBOUND's own exceptions (Escape, Collision, ...) vary by version
            rows.append({"method": label, "kind": "rebound", **setting,
                         "failed": f"{type(exc).__name__}: {' '.join(str(exc).split())}"})
            continue
        traj = np.array(states)
        row = {"method": label, "kind": "rebound", "steps": steps, "seconds": best, **errors(traj), **setting}
        row["error"] = max_abs_error(final, y_ref)
        rows.append(row)
    return rows
