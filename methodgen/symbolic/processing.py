"""Processed compositions: a cheap kernel between a pre- and a post-processor.

A processed method [BCR99]_, [BCM06]_ runs

    y_n = π(K_h^n(π⁻¹(y0))),

where the kernel ``K_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}`` is a symmetric composition of a
symmetric order-2 base step Φ_h (energy–momentum, midpoint, Störmer–Verlet, …) and the
processor ``π`` is another composition of the base step whose coefficients add up to 0
(a near-identity change of variables).  ``π ∘ K_h ∘ π⁻¹`` has a higher order than ``K_h``
itself: the kernel need only satisfy the *effective-order* conditions, fewer than the order
conditions, so it has fewer stages or smaller error terms for the same order.  The processor
is applied once at the start and once per *output* row (not fed back), so a run that keeps
few rows (``save_every``, or only the end state) pays for it almost nothing; a run that keeps
every row pays the processor's stages once more per row.

What it keeps, because every stage (kernel and processors, also those with negative steps)
is the base map: the base method's exact invariants (energy–momentum: H and the momenta, to
round-off, at every returned row), its symplecticity (compositions of symplectic maps).  Not
claimed: symmetry (the processed map is *conjugate* to the symmetric kernel, which gives it
the same long-time behaviour, but is not itself symmetric in general).

The order is decided here, not assumed: the base step is ``exp(h X1 + h³ X3 + …)`` with free
generators (as in :mod:`methodgen.symbolic.compositions`) and ``log`` of the whole sequence
pre-processor, kernel, post-processor (the order of application) must be ``h X1 + O(h^{K+1})``.
The published coefficients have 15–16 digits; the conditions hold to that many (60-digit
evaluation, :func:`order_defects`).

Families (``PROCESSED``):

``"blanes-casas-murua"``
    [BCM06]_ Table 5.x: order 6 with an 11-stage kernel and a 12-stage processor; order 8
    with a 13-stage kernel (the unprocessed order-8 default, Kahan–Li, has 17) and a
    20-stage processor.  Their order-10 method (23-stage kernel) is not offered: the
    16-digit processor available to us satisfies the weight-5 condition only to 3.7e-11;
    refitted at 60 digits to the 143 conditions up to weight 10 (Gauss–Newton from those
    values, which moved by ≤ 4e-9; residual 1.8e-15, the kernel's 15 digits) it is still less
    accurate at equal cost than Sofroniou–Spaletta's unprocessed 35 stages on Kepler e = 0.6
    (Störmer–Verlet, 50 orbits, 8000 kernel steps: 3.5e-8 against 4.9e-10).

References
----------
.. [BCR99] S. Blanes, F. Casas, J. Ros, Symplectic integrators with processing: a general
   study, SIAM J. Sci. Comput. 21 (1999) 711–727.
.. [BCM06] S. Blanes, F. Casas, A. Murua, Composition methods for differential equations with
   processing, SIAM J. Sci. Comput. 27 (2006) 1817–1843.
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §V.3.3 (effective order, processing).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mpmath as mp
import numpy as np

from .compositions import DPS, PROCESSED_FAMILIES, Composition, order_of_defects, sequence_defects

__all__ = ["PROCESSED", "Processed", "processed_composition", "order_defects", "achieved_order",
           "ProcessedIntegrator"]


def _mirror(half):
    return tuple(half) + tuple(reversed(half[:-1]))


def _processor(first_half):
    """The BCM06 processor ``(g_1 … g_m, −g_1 … −g_m)`` with ``g_1 = −(g_2 + … + g_m)``,
    from ``(g_2, …, g_m)`` as decimal strings; returned in the order of application to y0
    (the pre-processor), as 30-digit strings of the exact arithmetic on the published ones."""
    with mp.workdps(DPS):
        rest = [mp.mpf(g) for g in first_half]
        g = [-mp.fsum(rest)] + rest
        seq = g + [-x for x in g]
        return tuple(mp.nstr(-x, 30) for x in seq)


def _kernel(parts):
    """A symmetric kernel from its first-half coefficients; the middle one makes Σ γ = 1."""
    with mp.workdps(DPS):
        half = [mp.mpf(a) for a in parts]
        mid = 1 - 2 * mp.fsum(half)
        return _mirror([mp.nstr(x, 30) for x in half] + [mp.nstr(mid, 30)])


# [BCM06] (the coefficients as published, 15–19 digits; the middle kernel coefficient and the
# first processor coefficient follow from the consistency conditions Σ = 1 and Σ = 0).
_BCM06 = {
    6: (_kernel(["0.1705768865009222157"] * 4 + ["-0.423366140892658048"]),
        _processor(["-0.20621953139126", "0.23651387483203", "0.09086982276241", "0.24687306977659", "-0.1"])),
    8: (_kernel(["0.168", "0.168", "0.585550530805562", "-0.460090457516872", "0.172863148729731",
                 "0.179664539695039"]),
        _processor(["-0.008488123494574411", "-0.337188967354338", "0.333987768164597", "0.588351189003849",
                    "0.162324207599241", "-0.511744926116413", "0.236885952363384", "0.598212975943381",
                    "-0.543415765371656"])),
}

#: Processed families and their orders.
PROCESSED = PROCESSED_FAMILIES


@dataclass(frozen=True)
class Processed:
    """A processed composition: symmetric ``kernel`` (Σ = 1) and ``pre`` processor (Σ = 0),
    both as decimal strings in the order of application; ``post`` is ``pre``'s inverse."""

    family: str
    order: int
    kernel: tuple
    pre: tuple
    source: str

    @property
    def post(self) -> tuple:
        """The post-processor π: the pre-processor's steps reversed and negated (for a symmetric
        base step Φ_{−h} = Φ_h⁻¹, so this is exactly the inverse map)."""
        return tuple(s[1:] if s.startswith("-") else "-" + s for s in reversed(self.pre))

    @property
    def stages(self) -> int:
        """Base steps per step of the kernel (the cost per step)."""
        return len(self.kernel)

    @property
    def processor_stages(self) -> int:
        return len(self.pre)

    def composition(self, role: str) -> Composition:
        """The piece ``role`` ("kernel", "pre-processor", "post-processor") as a
        :class:`~methodgen.symbolic.compositions.Composition` to compose the base scheme with.  Its
        ``order`` is 4 for the kernel (its order alone: :func:`achieved_order` of the kernel)
        and a placeholder for the processors (not methods; their module says so)."""
        gam = {"kernel": self.kernel, "pre-processor": self.pre, "post-processor": self.post}[role]
        tag = {"kernel": "kernel", "pre-processor": "pre", "post-processor": "post"}[role]
        return Composition(f"{self.family}-{self.order}-{tag}", 4, tuple(gam), False, self.source, role,
                           digits_tol=1e-14)


@lru_cache(maxsize=None)
def processed_composition(order: int, family: str = "blanes-casas-murua") -> Processed:
    """The processed composition of ``family`` and ``order``.

    Raises
    ------
    ValueError
        An unknown family or an order it does not have (the message lists what is valid).
    """
    if family not in PROCESSED:
        raise ValueError(f"unknown processed family {family!r}; valid: {sorted(PROCESSED)}")
    if order not in PROCESSED[family]:
        raise ValueError(f"the {family} processed family has orders {PROCESSED[family]}, not {order!r}")
    kernel, pre = _BCM06[order]
    src = (f"Blanes, Casas & Murua 2006, order {order}: {len(kernel)}-stage kernel, "
           f"{len(pre)}-stage processor (15-19 digits)")
    return Processed(family, order, kernel, pre, src)


def order_defects(seq, upto: int) -> dict[int, float]:
    """Largest |coefficient| of ``log(Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}) − h X1`` at each weight
    1 … ``upto`` for the steps ``seq`` in the order of application (60 digits)."""
    return sequence_defects(seq, upto)


def achieved_order(proc: Processed, tol: float = 1e-14, upto: int | None = None) -> dict:
    """Decide the effective order of ``proc`` (and, for comparison, the kernel's own order).

    Returns ``{"order", "kernel_order", "defects", "kernel_defects", "tol"}``: ``order`` is
    the largest K with every defect of weight ≤ K of the whole sequence (pre, kernel, post)
    below ``tol`` (numerical: the published constants have 15–19 digits).
    """
    upto = upto or proc.order + 1
    whole = order_defects(proc.pre + proc.kernel + proc.post, upto)
    kern = order_defects(proc.kernel, upto)
    return {"order": order_of_defects(whole, tol), "kernel_order": order_of_defects(kern, tol),
            "defects": whole, "kernel_defects": kern, "tol": tol}


# --- running it ---------------------------------------------------------------------------------

class ProcessedIntegrator:
    """``y_n = π(K_h^n(π⁻¹(y0)))`` from three generated modules of one base scheme.

    Built by :func:`methodgen.codegen.build.build_processed`.  ``integrate`` takes the arguments of a generated
    module's ``integrate`` (``params``, ``save_every``, ``check_resolution``, ``solver``, …;
    not ``t_eval``, ``out`` or ``extended``) and returns the post-processed rows.

    Attributes
    ----------
    kernel, pre, post : module
        The generated modules (each a composition of the same base step).
    ORDER, COMPOSITION, METHOD, BACKEND, STATE_NAMES, TRAITS
        As a generated module's; ``TRAITS["symmetric"]`` is False (conjugate to a symmetric
        kernel), ``COMPOSITION`` adds ``processor_stages``.
    """

    def __init__(self, proc: Processed, kernel, pre, post):
        self.processed = proc
        self.kernel, self.pre, self.post = kernel, pre, post
        self.ORDER = proc.order
        self.METHOD = kernel.METHOD
        self.BACKEND = getattr(kernel, "BACKEND", "numpy")
        self.STATE_NAMES = kernel.STATE_NAMES
        self.COMPOSITION = {"family": proc.family, "order": proc.order, "stages": proc.stages,
                            "processor_stages": proc.processor_stages, "processed": True}
        traits = dict(kernel.TRAITS)
        traits.update(order=proc.order, symmetric=False,
                      notes=list(traits.get("notes", ())) + [
                          f"order {proc.order}: processed composition ({proc.source}); conjugate to a "
                          "symmetric kernel, not itself symmetric"])
        self.TRAITS = traits
        self.PROCESSED_FAMILY = proc.family
        self._key = (id(self), proc.family, proc.order)

    #: What is the kernel module's and means the same here (the system, its state functions,
    #: the exceptions, the solver's options); everything else a module has is not offered.
    _SHARED = frozenset({"HAMILTONIAN", "CONSTRAINTS", "Q_NAMES", "P_NAMES", "PARAM_NAMES",
                         "DEFAULT_PARAMS", "INVARIANT_NAMES", "TIME_TRANSFORM", "ConvergenceError",
                         "NonFiniteError", "ResolutionError", "ResolutionWarning", "MAX_RESOLUTION",
                         "MAX_LOCAL_ERROR", "DOMAIN_CONDITIONS", "SOLVERS", "DEFAULT_SOLVER",
                         "EXTENDED_BITS", "hamiltonian", "invariants", "initial_state", "physical_state",
                         "__file__"})

    def __getattr__(self, name):
        if name in ProcessedIntegrator._SHARED:
            return getattr(self.kernel, name)
        raise AttributeError(f"a processed composition has no {name!r} (it is three generated modules: "
                             f".kernel, .pre, .post; their own attributes are there)")

    @property
    def GAMMAS(self):
        """The kernel's coefficients (the processors' are ``.pre.GAMMAS``, ``.post.GAMMAS``)."""
        return self.kernel.GAMMAS

    def step(self, y0, h, params=None, **kw):
        """One processed step ``π(K_h(π⁻¹(y0)))`` (a single step pays both processors)."""
        return self.integrate(y0, h, 1, params, **kw)[-1]

    def _apply(self, module, Y, h, params, kw):
        """One step of a processor module on every row of ``Y`` (a state or any leading shape)."""
        Y = np.asarray(Y, dtype=float)
        if Y.ndim == 1:
            return np.array(module.integrate(Y, h, 1, params, **kw)[-1])
        flat = Y.reshape(-1, Y.shape[-1])
        out = module.integrate(flat, h, 1, params, **kw)[-1]
        return np.asarray(out).reshape(Y.shape)

    def _relabel(self, exc, where: str, y0) -> None:
        """Say in ``exc`` (a module's error, re-raised) which of the three modules failed: its own
        message speaks of "the order-4 composition" (the kernel alone) or of a processor's
        stages.  ``.trajectory`` becomes the rows of the processed run that exist (y0 alone
        when a processor failed)."""
        proc = self.processed
        head = (f"in the {where} of the processed composition ({proc.family}, order {proc.order}; "
                f"its kernel has {proc.stages} stages, its processors {proc.processor_stages}): ")
        if exc.args and isinstance(exc.args[0], str):
            msg = exc.args[0].replace("of the order-4 composition", f"of the {where}")
            exc.args = (head + msg,) + tuple(exc.args[1:])
        if where != "kernel" or getattr(exc, "trajectory", None) is None:
            try:
                exc.trajectory = np.asarray(y0, dtype=float)[None].copy()
            except AttributeError:   # pragma: no cover - an exception class without attributes
                pass

    def integrate(self, y0, h, steps, params=None, *, save_every=1, info=None, **kw):
        """Integrate ``steps`` steps of size ``h`` from ``y0``; rows as a module's ``integrate``.

        Row 0 is ``y0`` itself; row k is ``π(x_k)`` with ``x_k`` the kernel state.  With an
        ``info`` dict the kernel state and the kernel's own record (compensation, carried
        force) are kept in ``info["processed"]``, and a later call whose ``y0`` is bitwise the
        last row returned continues from that kernel state: chunked runs equal one piece
        bitwise.  An exception of the kernel (``ConvergenceError``, ``NonFiniteError`` …) is
        re-raised with its ``.trajectory`` post-processed.
        """
        for bad in ("t_eval", "out", "extended"):
            if kw.get(bad) not in (None, False):
                raise ValueError(f"a processed composition does not take {bad}= (its rows are post-processed "
                                 "kernel states); valid: params, save_every, info, check_resolution, solver, "
                                 "maxiter, tol, compensated")
        y0 = np.asarray(y0, dtype=float)
        rec = info.get("processed") if isinstance(info, dict) else None
        if (rec is not None and rec.get("key") == self._key and rec.get("h") == h
                and rec["output"].shape == y0.shape and np.array_equal(rec["output"], y0)
                and rec.get("params") == params):
            x0, kinfo = rec["kernel_state"], rec["kernel_info"]
        else:
            try:
                x0, kinfo = self._apply(self.pre, y0, h, params, kw), {}
            except (RuntimeError, FloatingPointError) as exc:   # the modules' errors
                self._relabel(exc, "pre-processor", y0)
                raise
        try:
            X = self.kernel.integrate(x0, h, steps, params, save_every=save_every, info=kinfo, **kw)
        except (RuntimeError, FloatingPointError) as exc:
            part = getattr(exc, "trajectory", None)
            rows = None
            if part is not None and len(part):
                try:
                    rows = self._apply(self.post, part, h, params, kw)
                    rows[0] = y0
                except (RuntimeError, FloatingPointError):   # the kernel's error is the one to report
                    rows = None
            # the rows of the processed run, never the kernel's own states
            exc.trajectory = rows if rows is not None else np.asarray(y0, dtype=float)[None].copy()
            self._relabel(exc, "kernel", y0)
            raise
        try:
            Y = self._apply(self.post, X, h, params, kw)
        except (RuntimeError, FloatingPointError) as exc:
            self._relabel(exc, "post-processor", y0)
            raise
        Y[0] = y0
        if isinstance(info, dict):
            info["processed"] = {"key": self._key, "h": h, "params": params, "output": Y[-1].copy(),
                                 "kernel_state": np.array(X[-1]), "kernel_info": kinfo}
            if "newton_iterations" in kinfo:   # the kernel's, per kernel step
                info["newton_iterations"] = kinfo["newton_iterations"]
        return Y
