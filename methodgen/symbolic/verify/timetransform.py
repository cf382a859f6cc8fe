"""Exact certificates for a Poincaré time-transformed system ``K = g(q)(H + e)``.

Three identities, each reduced to 0 by ``expand``/``cancel`` (no floats):

1. ``K − g (H + e) ≡ 0`` — the system is the transformation it claims to be;
2. ``∂K/∂t ≡ 0`` — so ``e`` is a first integral of K, and every method whose
   discrete gradient has a zero t-component (AVF, Itoh–Abe, the midpoint-type
   gradients of a t-free K) keeps it exactly;
3. ``J∇K − g·(J∇H, g⁻¹·t', 0) − (H + e)·J∇g ≡ 0``, written componentwise: the
   extended vector field equals ``g`` times the original one plus a term with
   the factor ``(H + e)``, which vanishes on ``K = 0`` where ``g ≠ 0``.  So on the
   level set K = 0 the q, p motion is the original flow re-timed by
   ``dt/dτ = g`` and ``H = −e`` [HLW06, §VIII.2].

For a time-dependent ``H(q, p, t)`` (``time="t"``: the autonomous extension ``K = H + e``,
g = 1, or a time transformation of it, ``K = g(q)(H + e)``) identity 2 is replaced by

2'. ``K`` is autonomous: its free symbols are the extended state ``(q, t; p, e)`` and
   the parameters, so every method for autonomous systems applies to it;

and identity 3 gets the row of ``e``: ``−∂K/∂t + g ∂H/∂t ≡ 0``, i.e. ``de/dτ = −g ∂H/∂t``.
With g = 1 the rows say: ``dq/dτ = ∂H/∂p``, ``dp/dτ = −∂H/∂q``, ``dt/dτ = 1``: on (q, p)
the flow of K is the flow of H(q, p, t) with ``t = t0 + τ``, and K = H + e is a first
integral (so ``H = −e`` along the motion from ``e0 = −H(q0, p0, t0)``).

For the logarithmic Hamiltonian (``form="log"``: ``K = log(−U) − log(T + e)`` = −Λ on the
exchanged state ``(p, e; q, t)``, :mod:`methodgen.symbolic.timetransform`) the three are

1L. ``K − (log(−U) − log(T + e)) ≡ 0``, ``T + U − H ≡ 0`` and
    ``(T + e)/(−U) − (1 + g(H + e)) ≡ 0`` with ``g = −1/U``: K = 0 exactly where H + e = 0
    (K = −log(1 + g(H + e)) where −U > 0 and T + e > 0);
2. ``∂K/∂t ≡ 0``;
3L. on ``e = −H``, the flow of K on the exchanged state (``dp/dτ = ∂K/∂q``,
    ``dq/dτ = −∂K/∂p``, ``dt/dτ = −∂K/∂e``) equals g times the original field:
    ``−∂K/∂p − g ∂H/∂p``, ``∂K/∂q + g ∂H/∂q`` and ``−∂K/∂e − g`` reduce to 0 there
    [Mikkola & Tanikawa 1999; Preto & Tremaine 1999].

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §VIII.2.
"""

from __future__ import annotations

import time

import sympy as sp

from .report import PROVED, REFUTED, UNDECIDED, Certificate

REF = "HLW06 §VIII.2 (Poincaré transformation)"


def _zero(expr) -> bool | None:
    for reduce in (sp.expand, sp.cancel):
        try:
            if reduce(expr) == 0:
                return True
        except Exception:          # a reduction that cannot run decides nothing
            return None
    return False


def _cert(claim, exprs, t0, theta_ok=True):
    verdicts = [_zero(e) for e in exprs]
    if all(v is True for v in verdicts):
        status = PROVED
    elif any(v is None for v in verdicts):
        status = UNDECIDED
    else:
        status = REFUTED
    bad = [str(e) for e, v in zip(exprs, verdicts) if v is not True][:3]
    return Certificate(claim, status, "; ".join(map(str, exprs))[:400], "", "expand, cancel",
                       time.perf_counter() - t0, REF, {"nonzero": bad} if bad else {})


def time_transform_certificates(system) -> list[Certificate]:
    """Certificates 1–3 (2' for a time-dependent H) of the module docstring for a
    time-transformed or autonomised ``system``."""
    tt = system.time_transform
    if tt is None:
        return []
    if tt.form == "log":
        return _log_certificates(system)
    g, H, t, e = tt.g, tt.original.H, tt.time, tt.energy
    K = system.H
    timed = tt.original.time is not None
    out = []
    t0 = time.perf_counter()
    if tt.autonomised:
        out.append(_cert(f"K = H(q, p, {t}) + {e}: the autonomous extension of the time-dependent H",
                         [K - (H + e)], t0))
    else:
        out.append(_cert(f"K = g(q)·(H + {e}) with g = {tt.g_source}", [K - g * (H + e)], t0))
    t0 = time.perf_counter()
    if timed:
        out.append(_autonomous(system, t0))
    else:
        out.append(_cert(f"∂K/∂{t} = 0, so {e} is constant along the flow of K", [sp.diff(K, t)], t0))
    t0 = time.perf_counter()
    rows = []
    for qi, pi in zip(tt.original.q, tt.original.p):
        rows.append(sp.diff(K, pi) - g * sp.diff(H, pi) - (H + e) * sp.diff(g, pi))
        rows.append(-sp.diff(K, qi) + g * sp.diff(H, qi) + (H + e) * sp.diff(g, qi))
    rows.append(sp.diff(K, e) - g)
    if timed:
        rows.append(-sp.diff(K, t) + g * sp.diff(H, t) + (H + e) * sp.diff(g, t))
    if tt.autonomised:
        claim = (f"the flow of K is the flow of H(q, p, {t}): dq/dτ = ∂H/∂p, dp/dτ = −∂H/∂q, "
                 f"d{t}/dτ = 1 ({t} = {t}0 + τ), d{e}/dτ = −∂H/∂{t}, so H = −{e} on K = 0 "
                 f"(J∇K − (J∇H, 1, −∂H/∂{t}) ≡ 0)")
    else:
        claim = (f"on K = 0 (g ≠ 0): dq/dτ = g ∂H/∂p, dp/dτ = −g ∂H/∂q, d{t}/dτ = g and H = −{e} "
                 f"(J∇K − g·J∇H − (H + {e}) J∇g ≡ 0, ∂K/∂{e} = g"
                 + (f", ∂K/∂{t} = g ∂H/∂{t})" if timed else ")"))
    out.append(_cert(claim, rows, t0))
    return out


def _autonomous(system, t0) -> Certificate:
    """2': K depends on the extended state and the parameters only (no time of its own)."""
    allowed = set(system.y) | set(system.params)
    extra = sorted((s.name for s in system.H.free_symbols if s not in allowed))
    tt = system.time_transform
    claim = (f"K is autonomous on the extended phase space: a function of "
             f"({', '.join(s.name for s in system.q)}; {', '.join(s.name for s in system.p)}) "
             f"and the parameters only, with the declared time {tt.time} as a coordinate")
    return Certificate(claim, REFUTED if extra else PROVED,
                       f"free symbols of K outside the state and parameters: {extra}" if extra else
                       f"free symbols of K ⊆ {{{', '.join(s.name for s in (*system.y, *system.params))}}}",
                       "", "free symbols", time.perf_counter() - t0, REF,
                       {"nonzero": extra} if extra else {})


def _log_certificates(system) -> list[Certificate]:
    """Certificates 1L, 2 and 3L of the module docstring (the log form)."""
    from ..derive import separable_split

    tt = system.time_transform
    g, H, t, e = tt.g, tt.original.H, tt.time, tt.energy
    sep = separable_split(tt.original)
    T, U = sep.T, sep.U
    K = system.H
    out = []
    t0 = time.perf_counter()
    out.append(_cert(f"K = log(−U) − log(T + {e}) (= −Λ) with H = T + U, and (T + {e})/(−U) = 1 + g(H + {e}), "
                     f"g = {tt.g_source}: K = 0 exactly where H + {e} = 0",
                     [K - (sp.log(-U) - sp.log(T + e)), T + U - H, (T + e) / (-U) - (1 + g * (H + e))], t0))
    t0 = time.perf_counter()
    out.append(_cert(f"∂K/∂{t} = 0, so {e} is constant along the flow of K", [sp.diff(K, t)], t0))
    t0 = time.perf_counter()
    on = {e: -H}
    rows = []
    for qi, pi in zip(tt.original.q, tt.original.p):
        rows.append((-sp.diff(K, pi) - g * sp.diff(H, pi)).xreplace(on))
        rows.append((sp.diff(K, qi) + g * sp.diff(H, qi)).xreplace(on))
    rows.append((-sp.diff(K, e) - g).xreplace(on))
    out.append(_cert(f"on K = 0 ({e} = −H): dq/dτ = g ∂H/∂p, dp/dτ = −g ∂H/∂q, d{t}/dτ = g (the flow of K on the "
                     f"exchanged state (p, {e}; q, {t}) is the original flow re-timed by g = {tt.g_source})",
                     rows, t0))
    return out
