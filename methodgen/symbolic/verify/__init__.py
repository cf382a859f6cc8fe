"""Exact verification layer: every claim of the lecture notes, for *your* Hamiltonian.

``verify(scheme)`` returns a :class:`Report` of :class:`Certificate` objects,
one per claim that applies to the scheme and its system:

=====================================  ===============================================
claim                                  module
=====================================  ===============================================
1  q × p first integral (generic V)    :mod:`.invariants`
1b detected total momenta and declared :mod:`.invariants`
   invariants: {I, H} = 0
2, 4  discrete-gradient identity,      :mod:`.discrete_gradients`
      consistency, κ of Ex. 1.1
3  invariants kept by the step         :mod:`.invariants`
5  trapezoidal ~ midpoint (Ex. 2.1)    :mod:`.conjugacy`
6  Kahan forms, modified energy/volume :mod:`.kahan`
7  quadratic H: symplectic, re-timing  :mod:`.maps`, :mod:`.quadratic`
8  RATTLE on T*Q                       :mod:`.constrained`
9  symmetry of symmetric methods       :mod:`.discrete_gradients`, :mod:`.maps`
10 symmetric compositions: order of    :mod:`.compositions`
   the coefficients, float64 ones,
   symmetry, inherited properties
=====================================  ===============================================

A composed scheme (``discretize(..., order=K)``, ``scheme.composition`` set)
keeps the base step's equations: claims 2–9 then concern the base step Φ_h
(their certificates are prefixed "base step Φ_h: "), and the claim-10 groups,
which run last, certify the composition ``Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}`` —
deriving its symmetry, invariants, constraints and symplecticity from the base
certificates only where their proofs hold for every real (also negative) step.

Statuses: ``proved`` (exact reduction to 0, no floats), ``refuted`` (a
counterexample point), ``numerical`` (sample points and tolerance; never a
proof), ``undecided`` (the reduction raised an exception or exceeded its time
budget; ``details["reason"]`` says which).

Never a crash, bounded time: each claim group (one row of the table above, for
one scheme) runs as a deferred thunk under a per-claim time budget
(:data:`DEFAULT_TIMEOUT` = 60 s unless ``verify(..., timeout=...)``), see
:mod:`.budget`.  An exception or an overrun — also while deciding whether the
claim applies (``radial_profile``, ``is_quadratic_field``, ...) — becomes one
``undecided`` certificate named after the group; no exception escapes
:func:`verify` (``KeyboardInterrupt`` still does).  The budget is enforced
with ``SIGALRM`` and so only in the main thread on POSIX; elsewhere the claims
run without a limit.  The worst case is thus about ten budgets per scheme (four more
for a composition).
"""

from __future__ import annotations

import math
import sys
import threading
import time
from typing import Callable, NamedTuple

from ..derive import angular_momenta, radial_profile, separable_split
from ...problem.poisson import is_poisson
from ..schemes.base import is_linear_field, is_quadratic_field
from .budget import BudgetExceeded, budget
from .common import REF_KAHAN, REF_NOTES
from .conjugacy import conjugacy_certificate
from .compositions import (BASE_PREFIX, REF_HLW, BaseResults, float_coefficients_certificate,
                           inherited_certificates, order_certificate, symmetry_certificate)
from .collocation import REF as COLLOCATION_REF, REF_ENERGY as ENERGY_COLLOCATION_REF
from .collocation import energy_collocation_certificates, energy_collocation_claims, gauss_certificates
from .timetransform import REF as TIME_TRANSFORM_REF, time_transform_certificates
from .constrained import constrained_certificates, constrained_items
from .discrete_gradients import dg_certificates, dg_items, dg_symmetry
from .invariants import (REF_FIRST_INTEGRALS, angular_momentum_generic, angular_momentum_user,
                         first_integral_certificates, invariant_certificates, invariant_items)
from .kahan import (forms_agree_generic, forms_agree_user, modified_energy, modified_energy_fast,
                    modified_energy_structural, modified_volume, modified_volume_structural)
from .maps import explicit_symmetry, residual_symmetry, symplectic_certificate
from .poisson import REF_POISSON as POISSON_REF
from .poisson import (casimir_certificates, jacobi_certificate, kahan_poisson_certificates, skew_certificate,
                      structure_symmetry)
from .quadratic import retiming_certificate
from .loops import REF_LOOPS, loop_certificates
from .report import NUMERICAL, PROVED, REFUTED, STATUSES, UNDECIDED, Certificate, Report

__all__ = ["verify", "Report", "Certificate", "PROVED", "REFUTED", "NUMERICAL", "UNDECIDED",
           "STATUSES", "DEFAULT_TIMEOUT", "BudgetExceeded", "budget"]

#: Default time budget, in seconds, of each claim group (``verify(timeout=None)``).
DEFAULT_TIMEOUT = 60.0
#: With ``progress=True``, progress lines appear on stderr once a verification
#: has run this many seconds (so fast runs print nothing).
PROGRESS_AFTER = 2.0

_REASON_CHARS = 300
#: Compositions with at most this many stages list their coefficients in the report.
_LIST_STAGES = 35


def _gauss(stages: int) -> list[Certificate]:
    from ..schemes.gauss import coefficients

    co = coefficients(stages)
    return gauss_certificates(stages, A=[[float(a) for a in row] for row in co["A"]],
                              b=[float(v) for v in co["b"]])


def _symmetry(scheme) -> list[Certificate]:
    if scheme.discrete_gradient is not None:
        return [dg_symmetry(scheme.system, scheme.discrete_gradient, scheme.method, scheme=scheme)]
    if not scheme.unknowns:
        return [explicit_symmetry(scheme)]
    if scheme.traits.solve == "linear":
        return [residual_symmetry(scheme)]
    return []   # constrained methods: see constrained_certificates


# --- claim groups -------------------------------------------------------------------

class _Claim(NamedTuple):
    """One claim group: a label, its reference and a thunk returning certificates."""

    label: str
    ref: str
    run: Callable[[], object]     # -> Certificate | list[Certificate] | None


class _Undecidable(Exception):
    """Whether a claim applies could not be decided (the message is the reason)."""


def _one_line(exc: BaseException) -> str:
    msg = str(exc).strip().splitlines()
    text = f"{type(exc).__name__}: {msg[0]}" if msg and msg[0] else type(exc).__name__
    return text if len(text) <= _REASON_CHARS else text[:_REASON_CHARS - 1] + "…"


class _Lazy:
    """A property of the system, computed on first use and shared by claim groups.

    A failure is remembered, so the next group that needs it is undecided at
    once instead of spending its own budget on the same computation.
    """

    def __init__(self, what: str, fn: Callable[[], object]):
        self.what, self.fn = what, fn
        self.value, self.done, self.failure = None, False, None

    def __call__(self):
        if self.done:
            return self.value
        if self.failure is not None:
            raise self.failure
        try:
            self.value = self.fn()
        except BudgetExceeded:
            self.failure = _Undecidable(f"could not decide whether the claim applies: {self.what} "
                                        "ran out of time in an earlier claim")
            raise
        except Exception as exc:
            self.failure = _Undecidable(f"could not decide whether the claim applies: {self.what} "
                                        f"failed: {_one_line(exc)}")
            raise self.failure from exc
        self.done = True
        return self.value


#: Methods whose step on a linear vector field is the Cayley transform (midpoint rule).
CAYLEY_ON_LINEAR = frozenset({"midpoint", "trapezoidal", "kahan", "energy-momentum", "avf", "gonzalez"})


def _plan(scheme, conjugacy_dim: int | None) -> list[_Claim]:
    """The claim groups that apply, as deferred thunks.

    Only cheap attribute tests are made here; the checks that compute
    (``radial_profile``, ``is_quadratic_field``...) run inside the thunks.
    """
    system, traits, m = scheme.system, scheme.traits, scheme.method
    d = len(system.y) // 2       # degrees of freedom of a canonical system
    radial = _Lazy("the radial-potential test (radial_profile, angular_momenta)",
                   lambda: radial_profile(system) is not None and bool(angular_momenta(system)))

    def _isotropic():
        sep = separable_split(system)
        return sep is not None and bool(sep.isotropic)

    isotropic = _Lazy("the separable split (separable_split)", _isotropic)
    quadratic = _Lazy("the quadratic-field test (is_quadratic_field)", lambda: is_quadratic_field(system))
    linear = _Lazy("the linear-field test (is_linear_field)", lambda: is_linear_field(system))
    claims: list[_Claim] = []
    comp = scheme.composition
    # A composition's other claim groups are about its base step Φ_h: say so, and keep their
    # certificates for the composition's derived claims (claim 10, appended last).
    base = BaseResults() if comp is not None else None
    step = m if comp is None else f"{m}, base step Φ_h of {scheme.key}"

    def add(label, ref, run):
        claims.append(_Claim(label, ref, run))

    def add_step(label, ref, items, certificates=None):
        """A claim group about the step map.

        ``items() -> [(property, certificate)]`` or None; ``certificates()``, when given, is
        what a base method runs instead (the plain certificate functions, looked up at call
        time so tests can replace them).
        """
        if base is None:
            add(label, ref, certificates or (lambda: [c for _, c in (items() or []) if c is not None]))
        else:
            add(label, ref, base.recorder(label, items, BASE_PREFIX))

    def tagged(tag, run):
        """``run() -> Certificate | list | None`` as items tagged ``tag``."""
        return lambda: [(tag, c) for c in _as_certificates(run())]

    # Claim 10 (first the coefficients: they do not depend on the base step).
    split = comp is not None and getattr(comp, "kind", None) == "splitting"
    if split:
        from .splittings import (REF_SPLIT, splitting_float_certificate, splitting_order_certificate)
        add(f"splitting coefficients: order {comp.order}{' (RKN)' if comp.rkn else ''} "
            f"({comp.family}, {scheme.key})", REF_SPLIT, lambda: splitting_order_certificate(comp))
        add(f"float64 stage fractions of the generated module ({scheme.key})", REF_SPLIT,
            lambda: splitting_float_certificate(comp, key=scheme.key))
    elif comp is not None:
        add(f"composition coefficients: order {comp.order} ({comp.family}, {scheme.key})", REF_HLW,
            lambda: order_certificate(comp))
        add(f"float64 coefficients of the generated module ({scheme.key})", REF_HLW,
            lambda: float_coefficients_certificate(comp, key=scheme.key))

    if is_poisson(system):
        _poisson_claims(scheme, add, add_step, tagged, step, quadratic)
        if comp is not None:
            if traits.symmetric:
                add(f"the composition is symmetric ({scheme.key})", REF_HLW,
                    lambda: symmetry_certificate(scheme, base))
            add(f"invariants kept by the composition ({scheme.key})", REF_HLW,
                lambda: inherited_certificates(scheme, base))
        return claims
    # Gauss collocation: the coefficients' order conditions and symplecticity, exactly.
    if (scheme.structure or {}).get("kind") == "collocation":
        stages = scheme.structure["stages"]
        add(f"Gauss–Legendre coefficients, s = {stages}: B({2 * stages}), D({stages}), order "
            f"{2 * stages}, symplectic, symmetric", COLLOCATION_REF, lambda: _gauss(stages))
    # Energy collocation: basis, nodes, order, symmetry and the module's float64 rule (H itself
    # is the invariants group's claim: proved for polynomial H, else stated as approximate here).
    if (scheme.structure or {}).get("kind") == "energy-collocation":
        add(f"energy-preserving collocation: basis, nodes, order, symmetry, float64 rule ({step})",
            ENERGY_COLLOCATION_REF, lambda: energy_collocation_claims(scheme))
    # The Poincaré time transformation K = g(q)(H + e), when the system is one.
    if system.time_transform is not None and system.time_transform.autonomised:
        tt = system.time_transform
        add(f"time-dependent H: autonomous extension K = H(q, p, {tt.time}) + {tt.energy}", TIME_TRANSFORM_REF,
            lambda: time_transform_certificates(system))
    elif system.time_transform is not None:
        add(f"time transformation K = g(q)(H + e), g = {system.time_transform.g_source}", TIME_TRANSFORM_REF,
            lambda: time_transform_certificates(system))
    # Claim 1: first integrals of the flow (system-level).
    if d >= 2 and not system.constraints:
        add(f"q × p first integrals for every radial potential V ({d}D)", f"{REF_NOTES}, Ex. 1.1.1",
            lambda: angular_momentum_generic(d) if radial() and isotropic() else [])
        add("q × p first integrals of this H", f"{REF_NOTES}, Ex. 1.1.1",
            lambda: angular_momentum_user(system) if radial() else [])
    # Detected total momenta and declared invariants: {I, H} = 0 proved or refuted.  (One degree
    # of freedom has no momentum to detect: a linear c·p commutes with H only if H is free of q.)
    if system.declared_invariants or d >= 2:
        add("detected and declared invariants are first integrals of this H: {I, H} = 0", REF_FIRST_INTEGRALS,
            lambda: first_integral_certificates(system))
    # Sums of like terms: what a looped module evaluates is the scheme's ∇̄U (lower_loops);
    # claimed where the module loops (a one-instance "family" is the unrolled term itself).
    if getattr(scheme, "loops", None) is not None and scheme.loops.looped:
        add(f"loops over like terms evaluate the scheme's discrete gradient ({step})", REF_LOOPS,
            lambda: loop_certificates(scheme))
    # Claims 2, 4: discrete gradients.
    if traits.discrete_gradient and scheme.discrete_gradient is not None:
        what = "identity, consistency and κ" if m == "energy-momentum" else "identity and consistency"
        add_step(f"discrete-gradient {what} ({step})", f"{REF_NOTES}, Ex. 1.1.2",
                 lambda: dg_items(scheme), lambda: dg_certificates(scheme))
    # Claim 3 and every other invariant the traits promise.
    if not system.constraints:
        add_step(f"invariants kept by the step ({step})", f"{REF_NOTES}, Ex. 1.1.3",
                 lambda: invariant_items(scheme), lambda: invariant_certificates(scheme))
    # Claim 5: Exercise 2.1 (the conjugating map depends on h: a base-step statement only).
    if m == "trapezoidal":
        n = conjugacy_dim or 2 * d
        add_step(f"trapezoidal rule conjugate to the midpoint rule (n = {n})", f"{REF_NOTES}, Ex. 2.1",
                 tagged("conjugacy", lambda: conjugacy_certificate(n)))
    # Claim 6: Kahan on quadratic vector fields.
    if m == "kahan":
        def _energy():
            cert = modified_energy_structural(system)
            if cert is None and d == 1:
                cert = modified_energy_fast(system)
            return cert if cert is not None else modified_energy(system)

        def _volume():
            cert = modified_volume_structural(system)
            return cert if cert is not None else modified_volume(system)

        # The modified energy and volume form depend on h: the stages of a composition use
        # different steps, so these are claims about the base step only (none is inherited).
        where = "" if comp is None else f" ({step})"
        for label, run in ((f"Kahan's two forms agree (generic quadratic field, n = {2 * d})",
                            lambda: forms_agree_generic(2 * d)),
                           ("Kahan's two forms agree on this field", lambda: forms_agree_user(system)),
                           ("Kahan preserves a modified energy", _energy),
                           ("Kahan preserves a modified volume form", _volume)):
            add_step(label + where, REF_KAHAN,
                     tagged("kahan", lambda run=run: run() if quadratic() else []))
    # Claims 7, 8: symplecticity.
    if system.constraints:
        add_step(f"constraints, symmetry and symplecticity on T*Q ({step})",
                 f"{REF_NOTES}, section 1.3 (RATTLE)", lambda: constrained_items(scheme),
                 lambda: constrained_certificates(scheme))
    elif traits.symplectic:
        add_step(f"the step map is symplectic ({step})", "symplecticity (section 1.2)",
                 tagged("symplectic", lambda: symplectic_certificate(scheme)))
        # Theorem 1.1 is about the Cayley transform (midpoint rule), which these methods
        # reduce to on a linear field; Störmer–Verlet does not (it is the exact flow of a
        # *modified* quadratic H, not of H at another time), so it makes no such claim.
        # For a composition this is the base step's re-timing; the composed step's own
        # (τ_Ψ = Σ τ(γ_i h)) is derived in claim 10.
        if m in CAYLEY_ON_LINEAR:
            add_step(f"quadratic H: the step is the exact flow at a re-timed step ({step})",
                     f"{REF_NOTES}, section 1.2 (Theorem 1.1)",
                     tagged("retiming", lambda: retiming_certificate(scheme) if linear() else None))
    # Claim 9: symmetry.
    if traits.symmetric and not system.constraints:
        add_step(f"the step is symmetric ({step})", "symmetry (claim 9)",
                 tagged("symmetry", lambda: _symmetry(scheme)))
    # Claim 10, derived from the base step's certificates above (so it runs after them).
    if split:
        from .splittings import splitting_inherited_certificates, splitting_symmetry_certificate
        add(f"the splitting is symmetric ({scheme.key})", REF_SPLIT,
            lambda: splitting_symmetry_certificate(comp, scheme.key))
        add(f"invariants and symplecticity kept by the splitting ({scheme.key})", REF_SPLIT,
            lambda: splitting_inherited_certificates(scheme, base))
    elif comp is not None:
        if traits.symmetric:
            add(f"the composition is symmetric ({scheme.key})", REF_HLW,
                lambda: symmetry_certificate(scheme, base))
        add(f"invariants, constraints and symplecticity kept by the composition ({scheme.key})", REF_HLW,
            lambda: inherited_certificates(scheme, base))
    return claims


def _poisson_claims(scheme, add, add_step, tagged, step: str, quadratic) -> None:
    """The claim groups of a scheme for a Poisson system y' = S(y)∇H (:mod:`.poisson`)."""
    system, traits, m = scheme.system, scheme.traits, scheme.method
    add("the structure matrix S is skew-symmetric", POISSON_REF, lambda: skew_certificate(system))
    add("the Jacobi identity of S (Poisson bracket)", POISSON_REF, lambda: jacobi_certificate(system))
    add("Casimirs of S: S∇C ≡ 0", POISSON_REF, lambda: casimir_certificates(system))
    if system.declared_invariants:
        add("declared invariants are first integrals of this H: {I, H} = ∇IᵀS∇H = 0", REF_FIRST_INTEGRALS,
            lambda: first_integral_certificates(system))
    if traits.discrete_gradient and scheme.discrete_gradient is not None:
        add_step(f"discrete-gradient identity and consistency ({step})", POISSON_REF,
                 lambda: dg_items(scheme), lambda: dg_certificates(scheme))
    add_step(f"invariants kept by the step ({step})", POISSON_REF,
             lambda: invariant_items(scheme), lambda: invariant_certificates(scheme))
    if m == "kahan":
        n = len(system.y)
        where = "" if scheme.composition is None else f" ({step})"
        for label, run in ((f"Kahan's two forms agree (generic quadratic field, n = {n})",
                            lambda: forms_agree_generic(n)),
                           ("Kahan's two forms agree on this field", lambda: forms_agree_user(system)),
                           ("Kahan preserves a modified energy and measure (CMOQ 2013: constant S)",
                            lambda: kahan_poisson_certificates(system))):
            add_step(label + where, REF_KAHAN, tagged("kahan", lambda run=run: run() if quadratic() else []))
    if traits.symmetric:
        def _sym():
            if scheme.structure_matrix is not None and scheme.discrete_gradient is not None:
                return [dg_symmetry(system, scheme.discrete_gradient, m, scheme=scheme),
                        structure_symmetry(scheme)]
            return _symmetry(scheme)
        add_step(f"the step is symmetric ({step})", "symmetry (claim 9)", tagged("symmetry", _sym))


def _undecided(label: str, ref: str, seconds: float, reason: str, **details) -> Certificate:
    return Certificate(label, UNDECIDED, seconds=seconds, ref=ref, details={"reason": reason, **details})


def _as_certificates(out) -> list[Certificate]:
    if out is None:
        return []
    items = [out] if isinstance(out, Certificate) else list(out)
    bad = [c for c in items if c is not None and not isinstance(c, Certificate)]
    if bad:
        raise TypeError(f"a claim returned {type(bad[0]).__name__}, not a Certificate")
    return [c for c in items if c is not None]


def _run_claim(claim: _Claim, seconds: float) -> list[Certificate]:
    """Run one claim group under a budget; an exception or an overrun is one undecided certificate."""
    t0 = time.perf_counter()
    b = budget(seconds)
    try:
        with b:
            out = claim.run()
        return _as_certificates(out)
    except BudgetExceeded as exc:
        if exc.budget is not b:          # an enclosing budget ran out: not ours to report
            raise
        return [_undecided(claim.label, claim.ref, time.perf_counter() - t0,
                           f"time budget of {seconds:g} s exceeded", timeout=seconds)]
    except _Undecidable as exc:
        return [_undecided(claim.label, claim.ref, time.perf_counter() - t0, str(exc))]
    except Exception as exc:
        return [_undecided(claim.label, claim.ref, time.perf_counter() - t0,
                           f"reduction failed: {_one_line(exc)}", exception=type(exc).__name__)]


def _claim_seconds(timeout) -> float:
    """The per-claim budget: ``None``/0 → :data:`DEFAULT_TIMEOUT`; negative or non-finite → ValueError."""
    default = float(DEFAULT_TIMEOUT)
    if timeout is None:
        return default
    try:
        t = float(timeout)
    except (TypeError, ValueError):
        raise ValueError(f"timeout must be a number of seconds (or None), got {timeout!r}") from None
    if not math.isfinite(t) or t < 0:
        raise ValueError(f"timeout must be a finite number of seconds >= 0 (0 or None: the default "
                         f"{default:g} s), got {timeout!r}")
    return t if t > 0 else default


# --- progress -------------------------------------------------------------------------

class _Progress:
    """Claim-by-claim progress on stderr, shown only once :data:`PROGRESS_AFTER` seconds passed.

    A watcher thread switches it on, so a long first claim is reported too.
    On a terminal it is a ``tqdm`` line updated in place (plain lines without
    tqdm); on a pipe or file, one plain line per claim group.  Never stdout.
    """

    def __init__(self, total: int, enabled: bool):
        self.total, self.enabled = total, enabled and total > 0
        self.file = sys.stderr
        self.t0 = time.monotonic()
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.current: tuple[int, str] | None = None
        self.active = False
        self.bar = None
        self.thread = None
        if self.enabled:
            self.thread = threading.Thread(target=self._watch, name="methodgen-verify-progress",
                                           daemon=True)
            self.thread.start()

    def _tty(self) -> bool:
        try:
            return bool(self.file.isatty())
        except Exception:
            return False

    def _watch(self):
        if self.stop.wait(max(float(PROGRESS_AFTER), 0.0)):
            return
        with self.lock:
            if self.stop.is_set():
                return
            if not self.active:
                self.active = True
                if self.current is not None:
                    self._show(*self.current)
        while not self.stop.wait(1.0):   # keep the elapsed time of a long claim fresh
            with self.lock:
                if self.bar is not None and not self.stop.is_set():
                    self.bar.refresh()

    def step(self, i: int, label: str) -> None:
        if not self.enabled:
            return
        with self.lock:
            self.current = (i, label)
            if not self.active and time.monotonic() - self.t0 >= float(PROGRESS_AFTER):
                self.active = True       # do not depend on the watcher thread at group boundaries
            if self.active:
                self._show(i, label)

    def _show(self, i: int, label: str) -> None:
        try:
            if self.bar is None and self._tty():
                try:
                    from tqdm import tqdm
                except ImportError:
                    tqdm = None
                if tqdm is not None:
                    self.bar = tqdm(total=self.total, initial=i, desc=label, file=self.file,
                                    leave=False, dynamic_ncols=True,
                                    bar_format="verify: [{n}/{total}] {desc} … {elapsed}")
                    self.bar.start_t -= time.monotonic() - self.t0   # elapsed since verify() began
                    self.bar.refresh()
                    return
            if self.bar is not None:
                self.bar.n = i
                self.bar.set_description_str(label, refresh=False)
                self.bar.refresh()
            else:
                print(f"verify: [{i}/{self.total}] {label} … ({time.monotonic() - self.t0:.1f} s)",
                      file=self.file, flush=True)
        except Exception:            # progress must never break a verification
            self.enabled = False

    def close(self) -> None:
        if not self.enabled and self.thread is None:
            return
        self.stop.set()
        with self.lock:
            if self.bar is not None:
                try:
                    self.bar.close()
                except Exception:
                    pass
                self.bar = None


# --- verify -----------------------------------------------------------------------------

def _key(scheme) -> str:
    """The composed method's name (``method-order<K>-<family>``), or the method's."""
    try:
        return str(scheme.key)
    except Exception:
        return str(getattr(scheme, "method", "?"))


def _title(scheme) -> str:
    try:
        system = scheme.system
        # the user's text: H itself may hold internal names (sinc_u for sin(u)/u)
        return f"{_key(scheme)} on {system.name or 'H = ' + str(getattr(system, 'source', system.H))}"
    except Exception:
        return f"{_key(scheme)} on an unprintable system"


def _composition_summary(scheme) -> dict | None:
    """What was composed, for the report (None for a base method)."""
    comp = getattr(scheme, "composition", None)
    if comp is None:
        return None
    try:
        out = {"family": comp.family, "order": comp.order, "stages": comp.stages, "exact": comp.exact,
               "source": comp.source, "base_method": scheme.method}
        if getattr(comp, "kind", None) == "splitting":
            out.update(kicks=[str(g) for g in comp.kicks], drifts=[str(g) for g in comp.drifts],
                       rkn=comp.rkn)
        elif comp.stages <= _LIST_STAGES:   # Suzuki's 625 nested radicals would swamp the report
            out.update(gammas=[str(g) for g in comp.gammas], floats=[repr(x) for x in comp.floats()])
        return out
    except Exception as exc:          # the report must never fail on its header
        return {"error": _one_line(exc)}


def verify(scheme, conjugacy_dim: int | None = None, *, timeout: float | None = None,
           progress: bool = False) -> Report:
    """Certify every claim that applies to ``scheme`` (and its system).

    Parameters
    ----------
    scheme : Scheme
        From :func:`methodgen.discretize`.
    conjugacy_dim : int, optional
        Phase-space dimension for the Exercise 2.1 conjugacy (trapezoidal
        rule); default ``2d`` of the system.
    timeout : float, optional
        Time budget in seconds of *each* claim group; ``None`` or 0 means
        :data:`DEFAULT_TIMEOUT` (60 s).  A claim group that exceeds it is
        ``undecided``.  Enforced in the main thread on POSIX only (SIGALRM).
    progress : bool
        Print claim-by-claim progress on stderr once the verification has run
        for :data:`PROGRESS_AFTER` (2) seconds.  Off by default; the CLI turns it on.

    Returns
    -------
    Report
        ``.ok`` is True iff something was verified and no claim was refuted or left
        ``undecided`` (``.verdict`` says which); ``.decided`` is False if some claim
        is ``undecided``.  No exception escapes (except
        ``KeyboardInterrupt`` and the ``ValueError`` of a bad ``timeout``).
    """
    if getattr(scheme, "projection", ()) and getattr(scheme, "projected_from", None) is not None:
        # a projected method: the base step's claims, then what the projection keeps
        from .projection import projection_certificates

        base = verify(scheme.projected_from, conjugacy_dim, timeout=timeout, progress=progress)
        certs = [_as_base(c, scheme) for c in base.certificates]
        certs += projection_certificates(scheme, base.certificates, _claim_seconds(timeout))
        return Report(_title(scheme), certs, method=_key(scheme), composition=_composition_summary(scheme))
    seconds = _claim_seconds(timeout)
    title = _title(scheme)
    label = f"which claims apply ({getattr(scheme, 'method', '?')})"
    plan = _Claim(label, REF_NOTES, lambda: _plan(scheme, conjugacy_dim))
    claims: list[_Claim] = []
    certs: list[Certificate] = []
    t0 = time.perf_counter()
    b = budget(seconds)
    try:
        with b:
            claims = plan.run()
    except BudgetExceeded as exc:
        if exc.budget is not b:
            raise
        certs.append(_undecided(label, REF_NOTES, time.perf_counter() - t0,
                                f"time budget of {seconds:g} s exceeded", timeout=seconds))
    except Exception as exc:
        certs.append(_undecided(label, REF_NOTES, time.perf_counter() - t0,
                                f"reduction failed: {_one_line(exc)}", exception=type(exc).__name__))
    bar = _Progress(len(claims), progress)
    try:
        for i, claim in enumerate(claims, 1):
            bar.step(i, claim.label)
            certs += _run_claim(claim, seconds)
    finally:
        bar.close()
    return Report(title, certs, method=_key(scheme), composition=_composition_summary(scheme))


def _as_base(c: Certificate, scheme) -> Certificate:
    """A certificate of the unprojected step, named as one (the projected method does not
    inherit it: e.g. symplecticity, or an invariant that is not projected on)."""
    import dataclasses

    return dataclasses.replace(c, claim=f"unprojected step: {c.claim}")
