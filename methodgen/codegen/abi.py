"""The one contract between generated kernels and the runtime that runs them.

Everything a generated module and a runtime must agree on is defined here, once, as plain
data with names; both sides read it from here instead of recomputing it:

* :class:`PostLayout` -- where each value sits in the output of a step's ``post`` kernel
  (the increment Δy, the first-same-as-last end force, the local-error terms, the domain
  conditions, the time-transformation guard, H and its size for the energy-jump test);
* :data:`CFG`, :data:`FCFG` -- the names of the compiled runtime's configuration arrays, and
  :func:`int_config_values` / :func:`float_config_sources`, their values for one module;
* :data:`STATUS` -- the status codes a compiled loop returns instead of raising;
* :data:`KERNEL_TYPES` -- the kernels' signatures (in :mod:`methodgen.codegen.ktypes`' vocabulary).

The code generator (:mod:`methodgen.codegen.lower`, the templates) and the runtimes
(:mod:`methodgen.runtime.stepper`, :mod:`methodgen.runtime.fused`, :mod:`methodgen.runtime.nbabi`, the numpy
modules' loops) import it; it imports the standard library and :mod:`methodgen.codegen.ktypes` only.
A change here changes the runtime's source digest (:data:`methodgen.runtime.nbabi.SOURCE_SHA256`), so
machine code and modules generated for another contract are rebuilt, never mixed.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass

from . import ktypes as _t

__all__ = ["PostLayout", "post_layout", "CFG", "FCFG", "STATUS", "KERNEL_TYPES", "int_config_values", "float_config_sources",
           "EPS", "TOL_ROUNDOFF", "TOL_PLATEAU", "RUNTIME_SHA256"]

# --- the post kernel's output ------------------------------------------------------------------


@dataclass(frozen=True)
class PostLayout:
    """Where each value sits in the output of a step's ``post`` kernel (a vector of
    :attr:`length` floats for one step ``y0 → y1``).

    In order: Δy (``n_state``); the first-same-as-last end force ∇U(q1) (``n_force``,
    :mod:`methodgen.symbolic.fsal`); the local-error terms (:func:`methodgen.codegen.lower.local_error_plan`:
    ``"direct"``: |E|², |Δy|²; ``"carry"``: |Δy|², a (``n_lerr``), b (``n_lerr``) with
    E = a - b of the previous step); the domain conditions (``n_domain``); for a time
    transformation's guard g, the level-set defect and its scale (3); for the energy-jump test
    H and Σ|terms of H| at y1 (2).

    Parameters
    ----------
    n_state : int
        Length of the state vector.
    n_force : int
        Components of the carried end force (0 unless first-same-as-last).
    local_error : {None, "direct", "carry"}
        The step's local-error estimate.
    n_lerr : int
        Components of a carried estimate (``"carry"``).
    n_domain : int
        Real-domain conditions checked at y1.
    tt_guard : bool
        A time transformation's guard is checked.
    energy_jump : bool
        The post kernel gives the energy-jump test's values (H and its size at y1): the test is
        made per stage.  A composition makes it per composed step instead, from the ``hs``
        kernel (``EJUMP = 2`` in the configuration), and its post kernel does not give them.
    """

    n_state: int
    n_force: int = 0
    local_error: str | None = None
    n_lerr: int = 0
    n_domain: int = 0
    tt_guard: bool = False
    energy_jump: bool = False

    def __post_init__(self):
        if self.local_error not in (None, "direct", "carry"):
            raise ValueError(f"local_error {self.local_error!r}: expected None, 'direct' or 'carry'")

    @property
    def force(self) -> int:
        """Start of the end force (right after Δy)."""
        return self.n_state

    @property
    def lerr(self) -> int:
        """Start of the local-error terms: |E|² ("direct") or |Δy|² ("carry")."""
        return self.n_state + self.n_force

    @property
    def lerr_norm(self) -> int:
        """|Δy|² (the size the estimate is measured against)."""
        return self.lerr + 1 if self.local_error == "direct" else self.lerr

    @property
    def lerr_a(self) -> int:
        """Start of a ("carry": E = a - b of the previous step)."""
        return self.lerr + 1

    @property
    def lerr_b(self) -> int:
        """Start of b ("carry"), carried to the next step."""
        return self.lerr + 1 + self.n_lerr

    @property
    def domain(self) -> int:
        """Start of the domain conditions."""
        if self.local_error == "direct":
            return self.lerr + 2
        if self.local_error == "carry":
            return self.lerr + 1 + 2 * self.n_lerr
        return self.lerr

    @property
    def tt(self) -> int:
        """Start of the time-transformation guard: g, the level-set defect, its scale."""
        return self.domain + self.n_domain

    @property
    def ej(self) -> int:
        """Start of the energy-jump values: H and its size at y1."""
        return self.tt + (3 if self.tt_guard else 0)

    @property
    def length(self) -> int:
        """Length of the output."""
        return self.ej + (2 if self.energy_jump else 0)


def post_layout(ir) -> PostLayout:
    """The :class:`PostLayout` of a module's post kernel, from its
    :class:`methodgen.codegen.lower.ModuleIR`."""
    tt = ir.time_transform
    return PostLayout(n_state=ir.n_state, n_force=len(ir.fsal_vars), local_error=ir.local_error,
                      n_lerr=len(ir.lerr_index), n_domain=len(ir.domain), tt_guard=bool(tt and tt.get("guard")),
                      energy_jump=bool(ir.energy_jump) and not ir.energy_jump_step)


# --- the compiled runtime's configuration ------------------------------------------------------

#: Positions in the int configuration array ``cfg`` of the compiled runtime.
CFG = {name: i for i, name in enumerate((
    "N",            # unknowns of the step equations (0: explicit)
    "DIM",          # state length
    "STAGES",       # stages of the composition (1: the base method)
    "NF",           # first-same-as-last force components following Δy in post
    "LERR",         # local error estimate: 0 none, 1 "direct", 2 "carry"
    "KLERR",        # components of a carried estimate
    "POST_EXTRA",   # where the local-error values start in post
    "POST_DOMAIN",  # where the domain conditions start
    "NDOMAIN",      # how many domain conditions
    "POST_TT",      # where g, the level-set defect and its scale start
    "TT_GUARD",     # 1: time-transformation guard
    "POST_EJ",      # where H and its size at y1 start
    "EJUMP",        # energy-jump test: 0 none, 1 per stage (post kernel), 2 per composed step (hs kernel)
    "POST_LEN",     # length of post's output
    "HAS_SCALE",    # 1: the module has a scale kernel (floor of the unknowns' size)
    "RESOLUTION",   # 0 none, 1 "full", 2 "reduced"
    "KIND",         # 0 Newton, 1 linearly implicit, 2 explicit
    "KL", "KU",     # bandwidths of the Newton matrix
    "PROJ",         # invariants projected on (methodgen.symbolic.projection): 0 none
    "PROJ_SYM",     # 1: symmetric projection, 0: standard
    "MERGED",       # 1: composed Störmer–Verlet stages with merged kicks (ModuleIR.merged_kicks)
))}

#: Positions in the float configuration array ``fcfg`` of the compiled runtime.
FCFG = {name: i for i, name in enumerate((
    "LERR2", "LERR_SCALE", "MAX_LEVEL_DEFECT", "MAX_ENERGY_JUMP", "MAX_RESOLUTION",
    "NEWTON_FAILURE_RESOLUTION", "MAX_PREDICTOR_DISAGREEMENT", "REUSE_RATE", "AUTO_RATE",
    "AUTO_HOLD", "PROJ_TOL", "PROJ_PLATEAU", "PROJ_NOISE",
))}

_LERR_CODES = {None: 0, "direct": 1, "carry": 2}
_RESOLUTION_CODES = {None: 0, "full": 1, "reduced": 2}


def _ejump_code(ir) -> int:
    """``EJUMP``: 0 no energy-jump test, 1 per stage (the post kernel's values), 2 per composed
    step (the ``hs`` kernel at the step's end)."""
    if not ir.energy_jump:
        return 0
    return 2 if ir.energy_jump_step else 1


def int_config_values(ir) -> dict:
    """The values of :data:`CFG` for a module, by name, from its
    :class:`methodgen.codegen.lower.ModuleIR` (every name of :data:`CFG`, in its order)."""
    post = post_layout(ir)
    n = ir.n_unknowns
    values = dict(
        N=n, DIM=ir.n_state, STAGES=ir.stages, NF=post.n_force, LERR=_LERR_CODES[ir.local_error], KLERR=post.n_lerr,
        POST_EXTRA=post.lerr, POST_DOMAIN=post.domain, NDOMAIN=post.n_domain, POST_TT=post.tt,
        TT_GUARD=int(post.tt_guard), POST_EJ=post.ej, EJUMP=_ejump_code(ir), POST_LEN=post.length,
        HAS_SCALE=int("scale" in ir.scalar), RESOLUTION=_RESOLUTION_CODES[ir.resolution] if n else 0,
        KIND=2 if not n else (1 if ir.kind == "linear" else 0),
        KL=ir.band[0] if n else 0, KU=ir.band[1] if n else 0,
        PROJ=len(ir.projection), PROJ_SYM=int(bool(ir.projection and ir.projection_symmetric)),
        MERGED=int(ir.merged_kicks))
    return {name: values[name] for name in CFG}


def float_config_sources(ir) -> dict:
    """The values of :data:`FCFG` for a module, by name, as the Python source that names them
    in the generated module (its constants; ``"0.0"`` where the check is absent)."""
    post = post_layout(ir)
    newton = ir.kind == "newton"
    values = dict(
        LERR2="_LERR2" if ir.local_error else "0.0", LERR_SCALE="_LERR_SCALE" if ir.local_error else "0.0",
        MAX_LEVEL_DEFECT="MAX_LEVEL_DEFECT" if post.tt_guard else "0.0",
        MAX_ENERGY_JUMP="MAX_ENERGY_JUMP" if ir.energy_jump else "0.0",
        MAX_RESOLUTION="MAX_RESOLUTION" if ir.resolution else "0.0",
        NEWTON_FAILURE_RESOLUTION="_NEWTON_FAILURE_RESOLUTION" if ir.resolution else "0.0",
        MAX_PREDICTOR_DISAGREEMENT="MAX_PREDICTOR_DISAGREEMENT" if ir.resolution else "0.0",
        REUSE_RATE="_REUSE_RATE" if newton else "0.0", AUTO_RATE="_AUTO_RATE" if newton else "0.0",
        AUTO_HOLD="_AUTO_HOLD" if newton else "0",
        PROJ_TOL="_PROJ_TOL" if ir.projection else "0.0",
        PROJ_PLATEAU="_PROJ_PLATEAU" if ir.projection else "0.0",
        PROJ_NOISE="_PROJ_NOISE" if ir.projection else "0.0")
    return {name: values[name] for name in FCFG}


# --- status codes ------------------------------------------------------------------------------

#: Status codes of a compiled loop, which cannot raise an exception carrying a payload: it
#: returns one of these (with the step, the iteration count and a value) and the Python
#: wrapper raises the exception.  A generated module defines ``_<NAME>`` with these values.
STATUS = {name: i for i, name in enumerate((
    "OK", "DIVERGED", "NOT_CONVERGED", "UNRESOLVED", "MISPREDICTED", "LINEAR_FAILED", "NON_FINITE",
    "OUT_OF_DOMAIN", "LOCAL_ERROR", "SLOW", "UNRESOLVED_START", "TIME_SCALE", "ENERGY_JUMP"))}

# --- Newton's stopping rule --------------------------------------------------------------------

EPS = 2.220446049250313e-16
#: Newton stops when the increment is at round-off level relative to the unknown, or when
#: increments stop decreasing once below sqrt(eps) (the generated modules' _TOL_*).
TOL_ROUNDOFF = 4.0 * EPS
TOL_PLATEAU = 1.4901161193847656e-08

# --- kernel signatures -------------------------------------------------------------------------

_f8 = _t.float64
_V = _t.float64[::1]
_M = _t.float64[:, ::1]

#: Signatures of the kernels (:mod:`methodgen.runtime.fused` inlines them), as plain data.
KERNEL_TYPES = {
    "guess": _t.void(_V, _f8, _V, _V),
    "res": _t.void(_V, _V, _V, _f8, _V, _V),
    "resjac": _t.void(_V, _V, _V, _f8, _V, _V, _M),
    "scale": _f8(_V, _f8, _V),
    "post": _t.void(_V, _V, _V, _V, _f8, _f8, _f8, _V, _V),
    "hs": _t.void(_V, _V, _V),
    "check": _t.void(_V, _V, _V),
    # a projected step (methodgen.symbolic.projection): the first-same-as-last force at (y, c), and
    # g, G = ∂g/∂y (row by row) and the metric w at y
    "force": _t.void(_V, _V, _V, _V),
    "proj": _t.void(_V, _V, _V),
    # an explicit stage for a block of lanes in lock-step (methodgen.runtime.stepper.lockstep):
    # Y, C, G, h·KICK_A, h·DRIFT, h·KICK_B, p, OUT, lanes used, compensated -> non-finite count
    # (a float: the compiled kernels return float64 or nothing)
    "post_block": _f8(_V, _V, _V, _f8, _f8, _f8, _V, _V, _t.int64, _t.int64),
}


# --- the runtime's stamp -----------------------------------------------------------------------

def _runtime_digest() -> str:
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    h = hashlib.sha256()
    for name in ("codegen/abi.py", "runtime/nbabi.py"):
        with open(os.path.join(package, *name.split("/")), "rb") as f:
            h.update(hashlib.sha256(f.read()).digest())
    return h.hexdigest()


#: SHA-256 over this file and ``runtime/nbabi.py`` (read, not imported): the runtime a generated
#: compiled module names (a module generated for another refuses to load).
RUNTIME_SHA256 = _runtime_digest()
