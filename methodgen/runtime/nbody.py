"""The run of a Wisdom–Holman splitting of an ``[nbody]`` problem: :func:`wisdom_holman`, :class:`WisdomHolman`.

The splittings themselves -- their coefficients and the exact and numerical certificates of
their claims -- are :mod:`methodgen.symbolic.nbody`; the compiled Kepler flows and kicks a
:class:`WisdomHolman` runs are :mod:`methodgen.runtime.kepler_flow`.
"""

from __future__ import annotations

import numpy as np

from ..codegen.progress import phase
from ..errors import InputError, MethodNotApplicable, NumericalError
from ..symbolic.nbody import DPS, JACOBI_PROOF, Splitting, certify, numerical_certificate, splitting

__all__ = ["PROJECTIONS", "WisdomHolman", "wisdom_holman", "claims", "nbody_energy", "nbody_momenta",
           "KeplerConvergenceError", "NonFiniteError", "ProjectionError", "ResolutionError", "MAX_STEP_FRACTION"]

#: ``wisdom_holman(..., project=)``: None; "energy-output" (every returned state projected onto the
#: run's H and angular momentum by moving its Jacobi momenta, :func:`methodgen.runtime.kepler_flow.project`;
#: the run continues unprojected); "energy-standard" (every step projected and fed back).
PROJECTIONS = (None, "energy-output", "energy-standard")


class KeplerConvergenceError(NumericalError):
    """A Kepler drift's universal-variable solve did not reach round-off.

    ``.step`` is the step that failed, ``.body`` the Jacobi body, ``.trajectory`` the rows
    returned before it (row 0 is y0)."""


class NonFiniteError(NumericalError):
    """The state became inf or NaN (bodies collided: an interaction or a Kepler radius of 0)."""


class ProjectionError(NumericalError):
    """The energy projection (``project="energy-output"`` or ``"energy-standard"``) did not bring
    H and L to round-off within
    its iteration limit; ``.step``, ``.trajectory`` (the rows before it), ``.residual`` (the
    largest residual relative to its first-order size)."""


class ResolutionError(NumericalError):
    """The step is too long for the shortest Kepler period at the initial state (see
    :data:`MAX_STEP_FRACTION`); ``check_resolution=False`` runs it anyway."""


#: A kick that changes a Jacobi momentum by more than this fraction of itself (or of a circular
#: orbit's momentum at the body's distance, when larger) stops the run
#: (a close encounter: H_I is no longer a small perturbation of the Kepler motion, and the
#: splitting's error estimates no longer hold).  Measured on the outer solar system over 2·10⁵
#: days: at most 1.1e-3 (wisdom-holman at h = 541 days, the resolution limit), 1.0e-4 (sbab4 at
#: h = 135 days).
MAX_KICK = 0.05

#: Above this ε (the largest planet/star mass ratio) a RuntimeWarning says that the splitting's
#: accuracy, which rests on ε being small, is not to be expected (a triple star, equal masses).
MAX_EPSILON = 0.1

#: A step longer than this fraction of the shortest osculating Kepler period of a Jacobi body
#: (bound orbits, at the initial state) is refused: beyond it the splitting resonates with the
#: orbit (on the outer solar system over 2·10⁵ days, sbab4 at h = 541 days = P_Jupiter/8 is 7e-6
#: off, at 271 days 4e-9).
MAX_STEP_FRACTION = 1 / 8


# --- the integrator ------------------------------------------------------------------------

def _split_bodies(Y, n: int):
    Y = np.asarray(Y, dtype=float)
    shape = Y.shape[:-1] + (n, 3)
    return Y[..., :3 * n].reshape(shape), Y[..., 3 * n:].reshape(shape)


def nbody_energy(Y, G: float, masses, centre: float | None = None) -> np.ndarray:
    """The ``[nbody]`` Hamiltonian at the states ``Y`` (any leading shape, last axis q then p).

    ``Σ|p_b|²/(2m_b) − Σ_{a<b} G m_a m_b/|q_a − q_b|`` and, with a fixed centre of mass
    ``centre``, ``− Σ_b G·centre·m_b/|q_b|``.
    """
    m = np.asarray(masses, dtype=float)
    n = len(m)
    q, p = _split_bodies(Y, n)
    H = np.sum(np.sum(p * p, axis=-1) / (2 * m), axis=-1)
    for a in range(n):
        for b in range(a + 1, n):
            H = H - G * m[a] * m[b] / np.linalg.norm(q[..., a, :] - q[..., b, :], axis=-1)
    if centre is not None:
        H = H - np.sum(G * centre * m / np.linalg.norm(q, axis=-1), axis=-1)
    return H


def nbody_momenta(Y, n: int) -> dict:
    """Total angular momentum ``Lx, Ly, Lz`` (Σ q_b × p_b) and momentum ``Px, Py, Pz`` of n bodies."""
    q, p = _split_bodies(Y, n)
    L = np.sum(np.cross(q, p), axis=-2)
    P = np.sum(p, axis=-2)
    return {"Lx": L[..., 0], "Ly": L[..., 1], "Lz": L[..., 2], "Px": P[..., 0], "Py": P[..., 1], "Pz": P[..., 2]}


def _check_int(value, what: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise InputError(f"{what} must be an integer ≥ {low}, got {value!r}")
    return int(value)


class WisdomHolman:
    """A Wisdom–Holman splitting of an ``[nbody]`` problem, run by :mod:`methodgen.runtime.kepler_flow`.

    Built by :func:`wisdom_holman`.  The state is the system's: ``y = (q, p)`` with body b at
    ``q[3b:3b+3]``, momentum ``p[3b:3b+3] = m_b v_b``.

    Attributes
    ----------
    splitting : Splitting
    corrector : bool
    G : float
    masses : ndarray, shape (N,)
    centre_mass : float or None
    epsilon : float
        ``max_{i≥1} m_i / m_0`` (Jacobi; about a fixed centre ``max m_i / M``): the size of
        ``H_I`` relative to ``H_K``, on which the splitting's accuracy rests.
    certificate : dict
        :func:`certify` (exact) and ``"numerical"``: :func:`numerical_certificate`.
    TRAITS : dict
        What the method keeps (symplectic, symmetric, momenta) and its error terms.
    METHOD : str
    STATE_NAMES : tuple of str
    """

    KeplerConvergenceError = KeplerConvergenceError
    NonFiniteError = NonFiniteError
    ResolutionError = ResolutionError
    ProjectionError = ProjectionError
    ConvergenceError = KeplerConvergenceError
    #: What a generated module's ``integrate`` callers read (``methodgen run``): the monitored
    #: quantities, the step's order in h, no composition, no Newton solver.
    ORDER = 2
    COMPOSITION = None
    DEFAULT_SOLVER = None
    EXTENDED_BITS = 53

    def __init__(self, system, nbody, split: Splitting, corrector: bool, certificate: dict,
                 params: dict | None = None, compensated: bool = True, project: str | None = None):
        from ..runtime import kepler_flow as kf

        self._kf = kf
        self.system, self.nbody, self.splitting, self.corrector = system, nbody, split, bool(corrector)
        self.compensated = bool(compensated)
        self.project = project
        self.certificate = certificate
        self.params = dict(system.param_values if params is None else params)
        G, masses, centre = nbody.values(self.params)
        m = np.array(masses, dtype=float)
        self.G, self.masses, self.centre_mass = G, m, centre
        n = len(m)
        self.jacobi = centre is None
        if self.jacobi:
            M = np.cumsum(m)
            mj = np.empty(n)
            mj[0] = M[-1]
            mj[1:] = m[1:] * M[:-1] / M[1:]
            mu = G * M
            KM = np.zeros(n)
            KM[1:] = G * m[1:] * M[:-1]
            self.epsilon = float(np.max(m[1:]) / m[0]) if n > 1 else 0.0
        else:
            M, mj, mu, KM = m.copy(), m.copy(), np.full(n, G * centre), np.zeros(n)
            # one body about a fixed centre: H_I = 0, the splitting is the exact flow
            self.epsilon = float(np.max(m) / centre) if n > 1 else 0.0
        self._const = (m, M, mj, mu, KM)
        if self.epsilon > MAX_EPSILON:
            import warnings
            heaviest = int(np.argmax(m))
            order = ("" if heaviest == 0 or not self.jacobi else
                     f" Body {heaviest} is the heaviest: list it first in [nbody].masses (and the state).")
            warnings.warn(f"{split.name}: the largest mass ratio to body 0 is ε = {self.epsilon:.3g}; the "
                          "Wisdom–Holman splitting's accuracy rests on ε being small (a star and its planets, the "
                          "star first). Its error terms ε h^k are not small here: prefer energy-momentum or "
                          f"Störmer–Verlet compositions.{order}", RuntimeWarning, stacklevel=3)
        self._c, self._d = split.c(), split.d()
        self._g = float(split.g) if corrector else 0.0
        self.n_bodies = n
        self.METHOD = split.name + ("-corrected" if corrector else "") + {
            None: "", "energy-output": "-projected-output", "energy-standard": "-projected"}[project]
        # "numba": the compiled backend's name (as a generated module's), though compiled through
        # LLVM IR (methodgen.codegen.llvmkernels), not by numba
        self.BACKEND = "numba" if kf.COMPILED else "python"
        if not kf.COMPILED:
            import warnings
            warnings.warn("llvmlite is not installed: the Wisdom–Holman runtime runs as Python, the same numbers "
                          "about 100x slower (pip install 'methodgen[compiled]')", RuntimeWarning, stacklevel=3)
        self.__file__ = kf.__file__
        self.STATE_NAMES = tuple(s.name for s in system.q) + tuple(s.name for s in system.p)
        self.INVARIANT_NAMES = ("H", "Lx", "Ly", "Lz", "Px", "Py", "Pz")
        err = f"O(ε h^{2 * split.n} + ε² h^{4 if corrector else 2})"
        # about a fixed centre only the angular momentum about it is a first integral
        kept = (("total linear momentum", "total angular momentum") if self.jacobi
                else ("total angular momentum about the centre",))
        notes = [f"{split.source}; " + ("with the corrector of [LR01] (g = %.6g)" % self._g
                                        if corrector else "without corrector")]
        if project:
            notes.append(("every returned state" if project == "energy-output" else "every step (fed back)")
                         + " projected onto the run's H and L: its Jacobi momenta scaled and rotated "
                         "(positions and total momentum untouched); symplecticity and symmetry are not kept"
                         + (" by the returned states (the run itself is the splitting's)"
                            if project == "energy-output" else ""))
        self.TRAITS = {"symplectic": not project, "symmetric": not project, "explicit": True, "order": 2,
                       "kept": (("energy",) if project else ()) + kept,
                       # methodgen run's claims: kept to round-off / bounded error
                       "preserved": (("H",) if project else ()) + ("Lx", "Ly", "Lz")
                       + (("Px", "Py", "Pz") if self.jacobi else ()),
                       "approximate": () if project else ("H",),
                       "energy": ({"energy-output": "kept to round-off in every returned state (projection)",
                                   "energy-standard": "kept to round-off (projection, fed back)"}[project]
                                  if project else "not kept (bounded error)"),
                       "error": err, "drifts_per_step": split.stages, "notes": notes}
        self._key = (id(self), split.name, self.corrector, self.compensated, self.project)

    # -- functions of the state --

    def _bodies(self, Y):
        return _split_bodies(Y, self.n_bodies)

    def hamiltonian(self, Y) -> np.ndarray:
        """H at the states ``Y`` (any leading shape, last axis the 6N state)."""
        return nbody_energy(Y, self.G, self.masses, self.centre_mass)

    def linear_momentum(self, Y) -> np.ndarray:
        """Total momentum Σ p_b, shape (..., 3)."""
        return self._bodies(Y)[1].sum(axis=-2)

    def angular_momentum(self, Y) -> np.ndarray:
        """Total angular momentum Σ q_b × p_b, shape (..., 3)."""
        q, p = self._bodies(Y)
        return np.cross(q, p).sum(axis=-2)

    def invariants(self, Y, params=None) -> dict:
        """The monitored quantities at the states ``Y``: H, total angular momentum (Lx, Ly, Lz) and
        total momentum (Px, Py, Pz) (as :data:`INVARIANT_NAMES`)."""
        self._check_params(params)
        return {"H": self.hamiltonian(Y), **nbody_momenta(Y, self.n_bodies)}

    def periods(self, y) -> np.ndarray:
        """Osculating Kepler periods of the Jacobi bodies at the state ``y`` (inf: unbound)."""
        q, p = self._bodies(np.asarray(y, dtype=float))
        m, M, mj, mu, KM = self._const
        qj, pj = np.empty_like(q), np.empty_like(p)
        self._kf.to_jacobi(np.ascontiguousarray(q), np.ascontiguousarray(p), m, M, self.jacobi, qj, pj)
        first = 1 if self.jacobi else 0
        out = []
        for i in range(first, self.n_bodies):
            r = float(np.linalg.norm(qj[i]))
            v2 = float(np.sum((pj[i] / mj[i]) ** 2))
            beta = 2 * mu[i] / r - v2
            out.append(2 * np.pi * mu[i] / beta ** 1.5 if beta > 0 else np.inf)
        return np.array(out)

    def _check_positions(self, y0):
        """Refuse (InputError) a y0 with two bodies at one place, or a body at the fixed centre."""
        q = self._bodies(y0)[0]
        for a in range(self.n_bodies):
            if not self.jacobi and not np.any(q[a]):
                raise InputError(f"y0 puts body {a} at the fixed centre (the origin), where H is not defined")
            for b in range(a + 1, self.n_bodies):
                if np.array_equal(q[a], q[b]):
                    raise InputError(f"y0 puts bodies {a} and {b} at the same place ({', '.join(f'{float(v):g}' for v in q[a])}), "
                                     "where H is not defined")
        if self.jacobi:
            m, M = self._const[:2]
            qj, pj = np.empty_like(q), np.empty_like(q)
            self._kf.to_jacobi(np.ascontiguousarray(q), np.zeros_like(q), m, M, True, qj, pj)
            for i in range(1, self.n_bodies):
                if not np.any(qj[i]):
                    raise InputError(f"y0 puts body {i} at the centre of mass of bodies 0…{i - 1}: its Jacobi "
                                     "Kepler term is singular there (the splitting does not apply)")

    def _check_params(self, params):
        if params is not None and dict(params) != self.params:
            raise InputError("this Wisdom–Holman integrator was built for the parameter values "
                             f"{self.params}; build another (wisdom_holman(..., params=...)) for others")

    # -- integration --

    def _kick(self, qj, pj, a, b):
        m, M, mj, mu, KM = self._const
        work = np.empty((7, self.n_bodies, 3))
        self._kf.kick(qj, pj, np.zeros_like(pj), a, b, m, M, mj, KM, self.G, self.jacobi, work)

    def _carried(self, y0, h, kappa):
        """Jacobi state of ``y0`` with the output's lagged kick undone."""
        q, p = self._bodies(y0)
        qj, pj = np.empty_like(q), np.empty_like(p)
        m, M = self._const[:2]
        self._kf.to_jacobi(np.ascontiguousarray(q), np.ascontiguousarray(p), m, M, self.jacobi, qj, pj)
        a, b = self._d[-1] * h, kappa
        if a != 0.0 or b != 0.0:
            self._kick(qj, pj, -a, -b)
        return qj, pj

    def _target(self, y0) -> np.ndarray:
        """``(H, Lx, Ly, Lz)`` of the state ``y0`` as the projection evaluates them (Jacobi kinetic
        energy and angular momentum, Cartesian potential): the level it keeps."""
        q, p = self._bodies(y0)
        q, p = np.ascontiguousarray(q), np.ascontiguousarray(p)
        m, M, mj, mu, KM = self._const
        qj, pj = np.empty_like(q), np.empty_like(p)
        self._kf.to_jacobi(q, p, m, M, self.jacobi, qj, pj)
        U = self._kf.potential(q, m, mu, self.G, self.jacobi)
        inv = np.empty(9)
        self._kf.invariants(qj, pj, np.zeros_like(pj), U, mj, inv, 0, np.empty((4, 4)))
        return inv[:4].copy()

    def step(self, y0, h, params=None):
        """One step from ``y0`` (the state after it)."""
        return self.integrate(y0, h, 1, params)[-1]

    def integrate(self, y0, h, steps, params=None, *, save_every: int = 1, info: dict | None = None,
                  check_resolution: bool = True, extended: bool = False, maxiter: int | None = None) -> np.ndarray:
        """``steps`` steps of size ``h`` from ``y0``: rows 0, save_every, 2·save_every, … (and the last).

        Parameters
        ----------
        y0 : array_like, shape (6N,)
        h : float
            Finite and nonzero (negative: backwards in time).
        steps : int ≥ 0
        save_every : int ≥ 1
            Keep every ``save_every``-th state; the final state is always the last row
            (``steps`` need not be a multiple).
        params : dict, optional
            Must be None or the values it was built with (the masses are constants of the run).
        info : dict, optional
            Carries the integrator's own state between calls: a call whose ``y0`` is
            bitwise the last row of the previous call (same ``h``) continues from it, so a
            run in chunks equals the run in one piece bitwise.
        check_resolution : bool
            Refuse (:class:`ResolutionError`) a step longer than :data:`MAX_STEP_FRACTION` of the
            shortest osculating period at ``y0``, and stop at a close encounter: a kick that
            changes a Jacobi momentum by more than :data:`MAX_KICK` of itself.
        extended : bool
            Must be False (no long-double refinement).
        maxiter : int ≥ 1, optional
            The energy projection's iteration limit (default
            :data:`methodgen.runtime.kepler_flow.PROJ_MAXITER`; it takes 2 at resolved steps).

        Returns
        -------
        ndarray, shape (rows, 6N)

        Raises
        ------
        KeplerConvergenceError, NonFiniteError, ProjectionError
            With ``.step``, ``.trajectory`` (the rows up to the last good state).
        InputError
            A state of the wrong size or not finite, h zero or not finite, bad counts.
        """
        y0 = np.asarray(y0, dtype=float)
        N = self.n_bodies
        if y0.shape != (6 * N,):
            raise InputError(f"y0 must have shape ({6 * N},) (q then p of {N} bodies), got {y0.shape}")
        if not np.all(np.isfinite(y0)):
            j = int(np.flatnonzero(~np.isfinite(y0))[0])
            raise InputError(f"y0 has a non-finite entry: {self.STATE_NAMES[j]} = {float(y0[j])!r}")
        self._check_positions(y0)
        if isinstance(h, bool) or not isinstance(h, (int, float, np.floating, np.integer)) \
                or not np.isfinite(h) or h == 0:
            raise InputError(f"h must be a finite nonzero number, got {h!r}")
        h = float(h)
        steps = _check_int(steps, "steps", 0)
        save_every = _check_int(save_every, "save_every", 1)
        maxiter = self._kf.PROJ_MAXITER if maxiter is None else _check_int(maxiter, "maxiter", 1)
        self._check_params(params)
        if extended:
            raise InputError(f"{self.METHOD}: extended=True (long double) is not available for the "
                             "Wisdom–Holman splittings")
        if check_resolution and steps:
            P = float(np.min(self.periods(y0))) if self.n_bodies > (0 if not self.jacobi else 1) else np.inf
            if abs(h) > MAX_STEP_FRACTION * P:
                exc = ResolutionError(
                    f"{self.METHOD}: h = {h:g} is longer than 1/{round(1 / MAX_STEP_FRACTION)} of the shortest "
                    f"Kepler period at y0 ({P:.6g}); the splitting resonates with the orbit there — take "
                    f"|h| ≤ {MAX_STEP_FRACTION * P:.4g} (or pass check_resolution=False to run it anyway)")
                exc.step, exc.trajectory = 0, y0[None].copy()
                raise exc
        kappa = -0.5 * self._g * h ** 3
        rec = info.get("wisdom_holman") if isinstance(info, dict) else None
        if rec is not None and rec["key"] == self._key and rec["h"] == h and np.array_equal(rec["output"], y0):
            qj, pj, cq, cp, tgt = (rec[k].copy() for k in ("qj", "pj", "cq", "cp", "target"))
        else:
            qj, pj = self._carried(y0, h, kappa)
            cq, cp = np.zeros_like(qj), np.zeros_like(pj)
            # the level the projection keeps: the run's first state's (chunks carry it in info)
            tgt = self._target(y0) if self.project else np.zeros(4)
        m, M, mj, mu, KM = self._const
        full, rest = divmod(steps, save_every)
        rows = 1 + full + (1 if rest else 0)
        out = np.empty((rows, 6 * N))
        out[0] = y0
        fail = np.zeros(2, dtype=np.int64)
        limit = MAX_KICK if check_resolution else np.inf
        peak = np.zeros(2)
        pstat = np.zeros(4)
        args = (m, M, mj, mu, KM, self.G, self.jacobi, self._c, self._d, h, kappa)
        if self.project:
            proj = ({"energy-output": 1, "energy-standard": 2}[self.project], tgt, pstat, maxiter)
            loop = self._kf.run_projected
        else:
            proj, loop = (), self._kf.run
        done = loop(qj, pj, cq, cp, *args, full * save_every, save_every, out, fail, self.compensated, limit, peak,
                    *proj)
        if done == full * save_every and rest:
            done += loop(qj, pj, cq, cp, *args, rest, rest, out[full:], fail, self.compensated, limit, peak, *proj)
        self.last_peak_kick = float(peak[0])
        if isinstance(info, dict):
            info["peak_kick"] = max(float(peak[0]), info.get("peak_kick", 0.0))
            if self.project:
                # the projection's iterations per projection: mean of this call, largest so far
                info["projection_iterations"] = {"mean": float(pstat[0]) / max(float(pstat[3]), 1.0),
                                                 "max": max(int(pstat[1]),
                                                            info.get("projection_iterations", {}).get("max", 0))}
        if fail[0]:
            kept = 1 + done // save_every
            traj = out[:kept].copy()
            step = done + 1
            if fail[0] == 4:
                body = int(fail[1])
                exc = ResolutionError(
                    f"{self.METHOD}: a close encounter at step {step} (h = {h:g}): one kick changed the momentum "
                    f"of Jacobi body {body} by more than {MAX_KICK:g} of itself, so the interaction is no longer "
                    "a small perturbation of the Kepler motion and the splitting's accuracy is lost; a smaller "
                    "step, or a method for close encounters (energy-momentum, Störmer–Verlet with a time "
                    "transformation), or pass check_resolution=False to run it anyway")
                exc.body = body
            elif fail[0] == 2 and self.project and not np.isfinite(pstat[2]):
                exc = NonFiniteError(f"{self.METHOD}: H or L became non-finite at step {step} (h = {h:g}): two "
                                     "bodies at one place")
                exc.body = -1
            elif fail[0] == 5:
                exc = ProjectionError(
                    f"{self.METHOD}: the energy projection did not converge at step {step} (h = {h:g}): after "
                    f"{maxiter} iterations H and L are {float(pstat[2]):.3g} of their size from the "
                    "run's initial values, above round-off (a step too long for the splitting, or an "
                    "encounter); a smaller step, or project=None")
                exc.residual = float(pstat[2])
            elif fail[0] == 1:
                body = int(fail[1])
                exc = KeplerConvergenceError(
                    f"{self.METHOD}: the Kepler drift of Jacobi body {body} did not converge at step {step} "
                    f"(h = {h:g}); its universal-variable solve took {self._kf.KEPLER_MAXITER} iterations "
                    "without reaching round-off (a near-collision or a radius of 0?)")
                exc.body = body
            else:
                exc = NonFiniteError(f"{self.METHOD}: the state became non-finite at step {step} (h = {h:g}): "
                                     "two bodies collided or a Jacobi radius reached 0")
                exc.body = int(fail[1])
            exc.step, exc.trajectory = step, traj
            raise exc
        if isinstance(info, dict):
            info["wisdom_holman"] = {"key": self._key, "h": h, "output": out[-1].copy(), "qj": qj.copy(),
                                     "pj": pj.copy(), "cq": cq.copy(), "cp": cp.copy(), "target": tgt.copy()}
        return out


def wisdom_holman(scene_or_system, method: str = "saba3", *, corrector: bool = True, nbody=None,
                  params: dict | None = None, compensated: bool = True,
                  project: str | None = None) -> WisdomHolman:
    """The Wisdom–Holman splitting ``method`` of an ``[nbody]`` problem, certified.

    Parameters
    ----------
    scene_or_system : Scene or Hamiltonian
        A scene with an ``[nbody]`` table, or a system together with ``nbody=``.
    method : str
        One of :data:`FAMILIES` (``"wisdom-holman"``, ``"saba1"`` … ``"saba6"``,
        ``"sbab1"`` … ``"sbab6"``).
    corrector : bool
        Apply the corrector of [LR01]_ (error ``O(ε h^{2n} + ε² h⁴)`` instead of ``ε² h²``).
    nbody : methodgen.symbolic.scene.NBody, optional
        With a system: its ``[nbody]`` declaration.
    params : dict, optional
        Parameter values (default: the system's); the masses and G are read from them.
    compensated : bool
        Add every drift's and kick's increment to the state with compensated summation
        (Kahan; the compensations carried from step to step and, with ``info``, chunk to
        chunk).  Measured on the outer solar system (sbab4, T = 2·10⁵ days): the final error
        goes on decreasing like ε² h⁴ to 1.5e-12 at h = 65 days, where plain sums stop at a
        round-off floor of ~2e-11; it costs ~20 % per step.
    project : {None, "energy-output", "energy-standard"}
        Project states onto the run's initial energy H and angular momentum L
        (:func:`methodgen.runtime.kepler_flow.project`, the standard projection [HLW]_ §IV.4.1): the
        Jacobi momenta are scaled and rotated rigidly, ``δp'_i = λ_H p'_i + m'_i λ_L × q'_i``
        (the gradients of H and L in the momenta, in the mass metric), positions and total
        momentum untouched.  ``"energy-output"``: every *returned* state is projected, the run
        itself continues as the splitting's (as the corrector, an output map): the error stays
        the splitting's, and H, L, P are kept to round-off in every row returned.
        ``"energy-standard"``: every step is projected and the run continues from the projected
        state (the correction leaves the positions alone, so it commutes with the lagged kick
        between the carried and the returned state).  Measured on the outer solar system
        (T = 2·10⁵ d) this costs accuracy: the single velocity scaling moves energy between the
        planets' orbits, whose periods then drift (sbab4 at h = 135 d: 8.1e-10 against 2.7e-11
        unprojected).  Either way symplecticity and symmetry are not kept, the order is (the
        correction is of the size of the step's energy error); a projection costs one potential
        evaluation and a few 4×4 solves (the gradients of the step's end are shared with the
        next step's kick).  Continue a run in chunks with ``info=``: it carries the target and the
        carried (unprojected) state; without it each call starts from the state it is given (the
        projected one) with that state's H and L as its target (``step()`` in a loop is then a
        projection fed back, onto a target that moves by round-off).

    Raises
    ------
    MethodNotApplicable
        No ``[nbody]`` declaration, or a Hamiltonian that is not the declared one (the
        message says which).
    InputError
        An unknown ``method`` or ``project``.
    ProjectionError
        (from ``integrate``) The projection did not reach round-off within
        :data:`methodgen.runtime.kepler_flow.PROJ_MAXITER` iterations.

    References
    ----------
    .. [HLW] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
       Springer 2006.
    .. [LR01] J. Laskar, P. Robutel, High order symplectic integrators for perturbed
       Hamiltonian systems, Celest. Mech. Dyn. Astron. 80 (2001) 39–62.
    """
    if project not in PROJECTIONS:
        raise InputError(f"project={project!r} is not a projection of the Wisdom–Holman splittings; valid: "
                         "None, 'energy-output' (every returned state onto the run's H and angular "
                         "momentum), 'energy-standard' (every step, fed back)")
    split = splitting(method)
    system = getattr(scene_or_system, "system", scene_or_system)
    nb = nbody if nbody is not None else getattr(scene_or_system, "nbody", None)
    name = getattr(scene_or_system, "name", None) or getattr(system, "name", None) or "this system"
    if nb is None:
        raise MethodNotApplicable(f"{method}: {name} declares no [nbody] table (G and the masses); the "
                                  "Wisdom–Holman splitting applies to N-body gravitational problems only")
    if getattr(system, "time_transform", None) is not None or getattr(system, "time", None) is not None:
        raise MethodNotApplicable(f"{method}: {name} is time-transformed or time-dependent; the Wisdom–Holman "
                                  "splitting applies to the [nbody] Hamiltonian itself")
    if system.constraints:
        raise MethodNotApplicable(f"{method}: {name} is constrained; the Wisdom–Holman splitting is for free bodies")
    values = dict(system.param_values)
    if params:
        unknown = sorted(set(params) - set(values))
        if unknown:
            raise InputError(f"unknown parameter(s) {', '.join(unknown)}; the system's: {', '.join(values)}")
        values.update({k: float(v) for k, v in params.items()})
    with phase("certify"):      # (reported past the reporter's threshold, as every phase)
        cert = certify(system, nb, values)
    if not cert["hamiltonian"]:
        raise MethodNotApplicable(
            f"{method}: the Hamiltonian of {name} is not the one its [nbody] table declares "
            "(Σ|p_b|²/(2m_b) − Σ G m_a m_b/|q_a − q_b|, and − Σ G M m_b/|q_b| with a fixed centre), "
            "neither symbolically nor at its parameter values")
    if cert["splitting"] != "identity map" and not all(cert["splitting"].values()):   # pragma: no cover
        raise NumericalError(f"{method}: the Jacobi splitting's identities failed: {cert['splitting']}")
    G, masses, centre = nb.values(values)
    if not (np.isfinite(G) and G > 0) or not all(np.isfinite(v) and v > 0 for v in masses) \
            or (centre is not None and not (np.isfinite(centre) and centre > 0)):
        raise MethodNotApplicable(f"{method}: G and every mass must be positive and finite "
                                  f"(G = {G!r}, masses = {masses!r}, centre = {centre!r})")
    cert = dict(cert, numerical=numerical_certificate(split))
    return WisdomHolman(system, nb, split, corrector, cert, values, compensated, project)


def claims(wh: WisdomHolman) -> list[dict]:
    """What ``wh`` claims and how each claim is decided (``methodgen verify SCENE --method saba3``).

    Each entry: ``{"claim", "status": "proved" | "refuted" | "not claimed", "kind": "exact" | "numerical" |
    "argument", "detail"}``.  ``exact``: a SymPy reduction to 0; ``numerical``: at
    :data:`DPS` digits; ``argument``: what follows from the structure, naming what it rests on.
    """
    cert, num, s = wh.certificate, wh.certificate["numerical"], wh.splitting
    out = []
    same = cert["hamiltonian"]
    out.append({"claim": "H is the [nbody] Hamiltonian", "status": "proved" if same else "refuted",
                "kind": "exact", "detail": f"H − H_nbody reduces to 0 ({same})" if same else "it does not reduce to 0"})
    split = cert["splitting"]
    if split == "identity map":
        out.append({"claim": "H = H_K + H_I (Kepler problems about the fixed centre, H_I of positions only)",
                    "status": "proved", "kind": "exact", "detail": "the identity map; H_I = the pair terms"})
    else:
        ok = all(split.values())
        out.append({"claim": "H = H_K(Jacobi) + H_I(q): the Jacobi map is canonical, the kinetic energy is "
                             "|P|²/2M + Σ|p'_i|²/2m'_i, μ_i m'_i = G m_i M_{i−1}",
                    "status": "proved" if ok else "refuted", "kind": "exact",
                    "detail": ", ".join(f"{k}: {'0' if v else 'not 0'}" for k, v in split.items())
                              + f" (symbolic masses; {JACOBI_PROOF})"})
    tol = 1e-40
    order_ok = num["epsilon_order"] == 2 * s.n
    out.append({"claim": f"ε-order {2 * s.n}: the kicks integrate polynomials of degree < {2 * s.n} exactly",
                "status": "proved" if order_ok else "refuted", "kind": "numerical",
                "detail": f"max defect {max(num['quadrature'][:2 * s.n]):.1e} at {DPS} digits; the degree-{2 * s.n} "
                          f"condition fails by {num['quadrature'][2 * s.n]:.1e}"})
    if wh.corrector:
        out.append({"claim": f"corrector coefficient g = {float(s.g):.16g} (the ε² h² term [B,[A,B]] of log Φ_h)",
                    "status": "proved" if num["bch_check"] < tol else "refuted", "kind": "numerical",
                    "detail": f"degree-3 BCH at {DPS} digits; Lie-element check {num['bch_check']:.1e}"})
    pal = (all(abs(a - b) < tol for a, b in zip(s.drifts, reversed(s.drifts)))
           and all(abs(a - b) < tol for a, b in zip(s.kicks, reversed(s.kicks))))
    if wh.project:
        # the projection (methodgen.runtime.kepler_flow.project) keeps H and L, not the structure
        what = "every returned state" if wh.project == "energy-output" else "every step (fed back)"
        out.append({"claim": "symmetric", "status": "not claimed", "kind": "argument",
                    "detail": f"{what} projected onto H and L: the projection is not symmetric"})
        out.append({"claim": "symplectic", "status": "not claimed", "kind": "argument",
                    "detail": f"{what} projected onto H and L: the projection is not symplectic"})
    else:
        out.append({"claim": "symmetric", "status": "proved" if pal else "refuted", "kind": "numerical",
                    "detail": "palindromic coefficients at 50 digits; exact flows; the corrector on both "
                              "sides with an odd power of h"})
        out.append({"claim": "symplectic",
                    "status": "proved" if (split == "identity map" or all(split.values())) else "refuted",
                    "kind": "argument",
                    "detail": "exact flows of H_K and H_I composed, in coordinates related by a linear canonical "
                              "map (rests on the exact certificate above; the Kepler flow is solved to round-off)"})
    if wh.jacobi:
        out.append({"claim": "total linear and angular momentum kept", "status": "proved", "kind": "argument",
                    "detail": "the Kepler flows keep each Jacobi body's q' × p' and the centre of mass moves "
                              "freely; H_I is invariant under translations and rotations"})
    else:
        out.append({"claim": "total angular momentum about the centre kept", "status": "proved",
                    "kind": "argument",
                    "detail": "each Kepler flow about the centre keeps the body's q × p; H_I (the pairs) is "
                              "invariant under rotations about the centre (the total momentum is not kept: "
                              "the centre is fixed)"})
    if wh.project:
        out.append({"claim": "energy", "status": "proved", "kind": "argument",
                    "detail": "each projected state is solved until H and L are within round-off of the run's "
                              "initial values, or the run stops with a ProjectionError (the projection moves "
                              "the momenta only: the total momentum is untouched)"})
    elif wh.epsilon == 0.0:
        out.append({"claim": "energy", "status": "proved", "kind": "argument",
                    "detail": "one body about a fixed centre: H_I = 0 and each step is the exact Kepler flow "
                              "(energy to the Kepler solve's round-off)"})
    else:
        out.append({"claim": "energy", "status": "not claimed", "kind": "argument",
                    "detail": f"not kept: bounded error {wh.TRAITS['error']} (ε = {wh.epsilon:.3g})"})
    return out
