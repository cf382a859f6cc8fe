"""Emission: IR → Python source through jinja2 templates → file → module.

* The jinja2 environment is strict (``StrictUndefined``: a template variable
  missing from the IR is an error, not an empty string), with ``trim_blocks``
  and ``lstrip_blocks`` so templates can be indented readably.
* Every file starts with a provenance header: generator, SymPy and template
  versions, the source Hamiltonian, the **signature** (a hash of everything
  the output depends on, computable *without* deriving anything) and a
  **content hash** of the body, so an edited or truncated file is detected.
* Files are written atomically (temporary file in the same folder, fsync,
  ``os.replace``): an interrupted write never leaves a half module, and two
  processes generating the same file leave one valid file.
* Modules in the per-user cache carry one more first line, a keyed hash
  (HMAC-SHA256 under a per-user secret in the cache root): a cached file is
  imported only if this user's methodgen wrote it, and only from folders
  nobody else can write to.  Files elsewhere (``generated/``) keep their
  plain, deterministic bytes.
* Generated modules are imported from their file (never ``exec`` of a string),
  from exactly the bytes that were checked.
* Loading and checking a module needs neither SymPy, jinja2 nor the lowering:
  those are imported by the functions that derive and render (a warm start from
  the cache stays light, see :func:`methodgen.codegen.build.build_text`).
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import importlib.machinery
import importlib.util
import os
import re
import sys
import warnings
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from .._version import __version__
from .abi import STATUS
from .kernelsource import GENERATED_ATTR
from ..errors import GenerationError, InputError, UntrustedCacheError
from .progress import phase
from .store import (HEADER_KEYED, KEY_FILE, _cache_key, _check_folder, _keyed_tag, cache_dir,  # noqa: F401
                    cache_root_of, check_cache_folder, untagged, write_atomic, write_module)

if TYPE_CHECKING:  # imported where rendering needs them (never on the loading path)
    from .lower import Kernel, ModuleIR

__all__ = ["template_dir", "template_hash", "signature", "render", "write_atomic", "file_status",
           "load_module", "generate", "module_filename", "cache_dir", "BACKENDS", "compiled_available",
           "resolve_backend", "write_module", "check_cache_folder", "cache_root_of", "untagged",
           "load_if_current"]

#: Code generation backends: plain numpy, or "numba": the compiled backend (kernels and
#: integration loop compiled through llvmlite; the name is historical, kept for the API).
BACKENDS = ("numpy", "numba")
# Top-level template of each backend; numba templates are named numba_*.j2 so
# that the numpy template hash (and with it every numpy signature) ignores them.
_TEMPLATES = {"numpy": "module.py.j2", "numba": "numba_module.py.j2"}

HEADER_SIGNATURE = "# signature: "
HEADER_CONTENT = "# content-sha256: "


def template_dir() -> Path:
    """The templates folder: inside the installed package (``methodgen/codegen/templates``), or the repo's
    top-level ``templates/``."""
    here = Path(__file__).resolve().parent
    for cand in (here / "templates", here.parent.parent / "templates"):
        if (cand / "module.py.j2").is_file():
            return cand
    raise GenerationError(f"methodgen templates not found next to {here}; the installation is incomplete")


def template_hash(backend: str = "numpy") -> str:
    """SHA-256 over the names and bytes of the templates a backend renders from (sorted).

    The numpy backend hashes every template except ``numba_*.j2`` (it never
    reads them, and its signatures must not change when they do); the numba
    backend hashes all of them (its templates import the numpy kernel macros).
    """
    _check_backend(backend)
    h = hashlib.sha256()
    for path in sorted(template_dir().glob("*.j2")):
        if (backend == "numpy" and path.name.startswith("numba_")) or path.name.startswith(("lattice_", "particles_")):
            continue      # (the lattice and particle modules' own templates: their emitters hash them)
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


#: Files of the package (paths relative to it) that never shape what a generated module
#: contains (front ends, runtime I/O, verification, scene data); every other ``.py`` file of
#: the package is part of the generator and enters :func:`generator_hash`.  A file missing
#: from this list only makes signatures change more often — never a stale module believed
#: current.  The app layer is left out whole: code generation never imports it (the layers
#: of tests/test_import_graph.py).
_NOT_GENERATOR = frozenset({
    "__main__.py", "codegen/build.py", "codegen/progress.py", "symbolic/scene.py",
    "runtime/runio.py", "runtime/trajfile.py", "runtime/events.py",
    # the lattice modules of symbolic size: their signatures hash these files themselves
    "problem/lattice.py", "symbolic/lattice_scheme.py", "codegen/lattice_emit.py",
    "runtime/lattice_stepper.py", "runtime/lattice_driver.py",
    # the particle families of symbolic size: likewise (methodgen.codegen.particle_emit)
    "problem/particles.py", "symbolic/particle_scheme.py", "codegen/particle_emit.py",
    "runtime/particle_stepper.py", "runtime/particle_driver.py",
})
_NOT_GENERATOR_DIRS = frozenset({"app", "symbolic/verify", "symbolic/scenes"})


@functools.lru_cache(maxsize=None)
def generator_hash() -> str:
    """SHA-256 over the names and bytes of the package's generator sources (sorted).

    The derivation (schemes, divided differences, special functions), the
    lowering and compensation passes and the emitter decide what a module
    contains, so a change to any of them — even without a version bump, as in
    a source checkout — must make every cached module stale instead of
    importing one derived by older code.  Computed once per process.
    """
    return _generator_tree_hash(Path(__file__).resolve().parent.parent)


def _generator_tree_hash(root: Path) -> str:
    """:func:`generator_hash` of the package tree at ``root``."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.as_posix() in _NOT_GENERATOR:
            continue
        if any("/".join(rel.parts[:k]) in _NOT_GENERATOR_DIRS for k in (1, 2)) or "__pycache__" in rel.parts:
            continue
        h.update(rel.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def signature(system, method: str, backend: str = "numpy") -> str:
    """Hash of everything a generated module depends on.

    Computed from the system's fingerprint, the method name, the backend, the
    versions of methodgen and SymPy, the templates and the generator's own
    sources (:func:`generator_hash`) — no derivation needed, so a cached
    module can be reused without re-deriving the scheme, and a module written
    by a different derivation is never taken for current.  The backend enters
    the hash only when it is not ``"numpy"``; a numpy and a numba module never
    share a signature.
    """
    import sympy  # the signature of a system needs SymPy anyway (its fingerprint)

    parts = [system.fingerprint(), method, __version__, sympy.__version__, template_hash(backend),
             generator_hash()]
    if backend != "numpy":
        parts.append(f"backend={backend}")
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def module_filename(system_name: str, method: str, backend: str = "numpy") -> str:
    """File name of a generated module; non-numpy backends get a ``_<backend>`` suffix."""
    _check_backend(backend)
    suffix = "" if backend == "numpy" else f"_{backend}"
    return f"{system_name}_{method}".replace("-", "_") + suffix + ".py"


def _check_backend(backend: str) -> None:
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; backends are {', '.join(BACKENDS)}")


def compiled_available() -> bool:
    """True when the compiled backend can run: llvmlite is installed (the ``methodgen[fast]``
    extra).  Found on the path, not imported.  Its kernels and its stepper are machine code
    printed through llvmlite."""
    return _findable("llvmlite")



def _findable(name: str) -> bool:
    if name in sys.modules:
        return sys.modules[name] is not None     # (None: imports of it are refused)
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def resolve_backend(backend: str, stacklevel: int = 3) -> str:
    """Validate ``backend``; ``"numba"`` without llvmlite installed falls back to ``"numpy"`` with a warning.

    Raises
    ------
    InputError
        For a name not in :data:`BACKENDS`.
    """
    _check_backend(backend)
    if backend == "numba" and not compiled_available():
        warnings.warn('llvmlite is not installed, so the numpy backend is used instead; install it with '
                      'pip install "methodgen[fast]" for the compiled backend', RuntimeWarning,
                      stacklevel=stacklevel)
        return "numpy"
    return backend


# --- rendering --------------------------------------------------------------

def _environment():
    """The Jinja environment of the templates, made once per templates folder: compiling the
    templates cost ~0.3 s of CPU, the render itself a few ms.  ``auto_reload`` (Jinja's default)
    still re-reads a template edited since, so the text is what a fresh environment renders."""
    return _environment_for(str(template_dir()))


def _tagged_bytecode_cache():
    """Jinja's compiled templates kept in the per-user cache, under the trust rules of the machine
    code (:mod:`methodgen.codegen.llvmcache`: a private folder, the user's HMAC tag, written
    atomically; ``METHODGEN_LLVM_CACHE=0`` turns it off).  Compiling the templates is most of
    ``render`` in a fresh process (0.3 s of a cold Kepler build); a compiled template is keyed by
    its name and its source's checksum, and Jinja's own header names the Python version, so an
    edited template or another interpreter compiles afresh."""
    import io

    import jinja2

    from . import llvmcache

    class TaggedBytecodeCache(jinja2.BytecodeCache):
        @staticmethod
        def _key(bucket):
            return hashlib.sha256(f"jinja\0{bucket.key}\0{bucket.checksum}".encode()).hexdigest()

        def load_bytecode(self, bucket):
            if not llvmcache.enabled():
                return
            data = llvmcache.load(self._key(bucket), "jinja-template")
            if data is not None:
                bucket.load_bytecode(io.BytesIO(data))

        def dump_bytecode(self, bucket):
            if not llvmcache.enabled():
                return
            buf = io.BytesIO()
            bucket.write_bytecode(buf)
            llvmcache.store(self._key(bucket), "jinja-template", buf.getvalue())

    return TaggedBytecodeCache()


@functools.lru_cache(maxsize=None)
def _environment_for(folder: str):
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(folder),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
        bytecode_cache=_tagged_bytecode_cache(),
    )
    env.filters["pyrepr"] = repr
    env.filters["pytuple"] = lambda seq: repr(tuple(seq))
    from .special_helpers import source as helper_source
    from .zeroin import source as zeroin_source
    from .compiled_kernels import block_kernel, kernel_function, kernel_text, stage_kernel

    env.globals["STATUS"] = STATUS     # the runtime's status codes (methodgen.codegen.abi)
    env.globals["helper_source"] = helper_source   # the scalar helpers' one source (a copy per module)
    env.globals["zeroin_source"] = zeroin_source   # event location's root finder, one source (a copy per module)
    env.globals["kernel_function"] = kernel_function   # compiled kernels as kernel IR
    env.globals["kernel_text"] = kernel_text
    env.globals["stage_kernel"] = stage_kernel
    env.globals["block_kernel"] = block_kernel
    return env


def _vector_view(kern: Kernel, groups: list[tuple[str, tuple[int, ...]]], returns: str) -> dict:
    """Map a kernel's flat outputs onto named arrays (``_R[..., i]``, ``_J[..., i, j]``)."""
    targets = []
    bounds = []
    start = 0
    for name, shape in groups:
        size = 1
        for s in shape:
            size *= s
        bounds.append((start, start + size, name, shape))
        start += size
    for (flat,), code in kern.outputs:
        for lo, hi, name, shape in bounds:
            if lo <= flat < hi:
                local = flat - lo
                idx = []
                for dim in reversed(shape):
                    idx.append(local % dim)
                    local //= dim
                idx = ", ".join(str(i) for i in reversed(idx))
                targets.append((f"{name}[..., {idx}]", code))
                break
    allocs = [(name, repr(tuple(shape))) for name, shape in groups]
    return {"temps": kern.temps, "targets": targets, "allocs": allocs, "returns": returns,
            "loops": kern.loops, "accs": kern.accs, "pre": kern.pre, "pre_out": kern.pre_out}


def _docsafe(text: str) -> str:
    return " ".join(text.replace("\\", " ").replace('"""', "'''").split())


def runtime_sha256() -> str:
    """The compiled runtime's ``SOURCE_SHA256`` (:data:`methodgen.runtime.nbabi.SOURCE_SHA256`: over
    ``abi.py`` and ``nbabi.py``).  A compiled module records it and refuses another runtime."""
    from .abi import RUNTIME_SHA256
    return RUNTIME_SHA256


def render(ir: ModuleIR, backend: str = "numpy") -> str:
    """Render the module source for ``ir`` with the templates of ``backend`` (deterministic)."""
    import sympy

    _check_backend(backend)
    template = _TEMPLATES[backend]
    n, d2 = ir.n_unknowns, ir.n_state
    if backend != "numba" and "increment" not in ir.vector:
        raise ValueError("this IR was lowered for the numba backend (lower(..., backend='numba')): "
                         "it has no batch flavour of the step kernels to render a numpy module from")
    # (an IR lowered for numba has no batch flavour of the step kernels: the numba templates
    # do not render them)
    vector = {
        "hamiltonian": _vector_view(ir.vector["hamiltonian"], [("_out", (1,))], "_out[..., 0]"),
        "invariants": _vector_view(ir.vector["invariants"],
                                   [("_out", (len(ir.invariant_names),))], "_out"),
        # the increment with what the per-step checks need, and the initial-state checks
        "check": _vector_view(ir.vector["check"], [("_out", ir.vector["check"].shape)], "_out"),
    }
    if "increment" in ir.vector:
        vector["increment"] = _vector_view(ir.vector["increment"], [("_out", (d2,))], "_out")
        vector["post"] = _vector_view(ir.vector["post"], [("_out", ir.vector["post"].shape)], "_out")
    if "domain" in ir.vector:
        vector["domain"] = _vector_view(ir.vector["domain"], [("_out", ir.vector["domain"].shape)], "_out")
    if "tguard" in ir.vector:
        vector["tguard"] = _vector_view(ir.vector["tguard"], [("_out", ir.vector["tguard"].shape)], "_out")
    if "hs" in ir.vector:
        vector["hs"] = _vector_view(ir.vector["hs"], [("_out", (2,))], "_out")
    if "force" in ir.vector:   # first-same-as-last Störmer–Verlet: ∇U at a run's start
        vector["force"] = _vector_view(ir.vector["force"], [("_out", ir.vector["force"].shape)], "_out")
    if "proj" in ir.vector:   # symmetric projection: g, then G row by row (methodgen.symbolic.projection)
        vector["proj"] = _vector_view(ir.vector["proj"], [("_out", ir.vector["proj"].shape)], "_out")
    if ir.n_constraints:
        m, d = ir.n_constraints, ir.dim
        vector["constraints"] = _vector_view(ir.vector["constraints"], [("_g", (m,)), ("_G", (m, d))], "_g, _G")
        vector["minv"] = _vector_view(ir.vector["minv"], [("_out", (d, d))], "_out")
    if n and "guess" in ir.vector:
        vector["guess"] = _vector_view(ir.vector["guess"], [("_out", (n,))], "_out")
        vector["res"] = _vector_view(ir.vector["res"], [("_R", (n,))], "_R")
        if ir.vector["resjac"].jac_rows:   # J = I + diag(s) _sB (methodgen.codegen.lower_loops)
            vector["resjac"] = _vector_view(ir.vector["resjac"], [("_R", (n,)), ("_JS", (n,))],
                                            f"_R, _JS[..., :, None] * _sB + numpy.eye({n})")
        else:
            vector["resjac"] = _vector_view(ir.vector["resjac"], [("_R", (n,)), ("_J", (n, n))], "_R, _J")
        if "scale" in ir.vector:
            vector["scale"] = _vector_view(ir.vector["scale"], [("_out", (1,))], "_out[..., 0]")
        if ir.stage:   # an s-stage method by structure: f, and f with f''s nonzeros
            d, nnz = ir.n_state, ir.stage["nnz"]
            vector["field"] = _vector_view(ir.vector["field"], [("_out", (d,))], "_out")
            vector["fieldjac"] = _vector_view(ir.vector["fieldjac"], [("_out", (d,)), ("_g", (nnz,))],
                                              "_out, _g")
    defaults = "{" + ", ".join(f"{k!r}: {v}" for k, v in zip(ir.param_names, ir.param_defaults)) + "}"
    clean = ir.__class__(**{**ir.__dict__, "source": _docsafe(ir.source),
                            "constraints": tuple(_docsafe(c) for c in ir.constraints)})
    if ir.poisson:
        clean = clean.__class__(**{**clean.__dict__, "poisson": {
            **ir.poisson, "matrix_text": _docsafe(ir.poisson["matrix_text"])}})
    header = [
        f"Generated by methodgen {__version__} from templates/{template} -- do not edit.",
        f"system: {ir.system_name}; method: {ir.method}",
        f"H = {clean.source}",
        f"methodgen {__version__}; sympy {sympy.__version__}; templates sha256 {template_hash(backend)[:16]}",
        HEADER_SIGNATURE[2:] + ir.signature,
    ]
    body_env = _environment()
    text = body_env.get_template(template).render(
        ir=clean, vector=vector, header=header, defaults_text=defaults,
        traits_text=repr(ir.traits),
        runtime_sha256=runtime_sha256())
    text = re.sub(r"\n{4,}", "\n\n\n", text).rstrip() + "\n"
    digest = hashlib.sha256(text.encode()).hexdigest()
    return HEADER_CONTENT + digest + "\n" + text


def _classify(path: Path, text: str, expected_signature: str | None) -> str:
    """``"ok"``, ``"corrupt"``, ``"untrusted"`` or ``"stale"`` for the file text ``text`` at ``path``."""
    tag = None
    if text.startswith(HEADER_KEYED):
        first, _, text = text.partition("\n")
        tag = first[len(HEADER_KEYED):].strip()
    first, _, body = text.partition("\n")
    if not first.startswith(HEADER_CONTENT):
        return "corrupt"
    if hashlib.sha256(body.encode()).hexdigest() != first[len(HEADER_CONTENT):].strip():
        return "corrupt"
    root = cache_root_of(path)
    if root is not None:
        key = _cache_key(root, create=False)
        if key is None or tag is None or not hmac.compare_digest(tag, _keyed_tag(key, path.name, text)):
            return "untrusted"
    if expected_signature is not None:
        m = re.search(r"^" + re.escape(HEADER_SIGNATURE) + r"([0-9a-f]{64})$", body, re.M)
        if not m or m.group(1) != expected_signature:
            return "stale"
    return "ok"


def file_status(path: Path, expected_signature: str | None = None) -> str:
    """Classify a generated file.

    Returns
    -------
    str
        ``"missing"``; ``"corrupt"`` (no header, or the body does not match
        its content hash: edited or truncated); ``"untrusted"`` (in the
        per-user cache, but without a valid key tag: not written by this
        user's methodgen — planted, edited with a recomputed hash, or from an
        older version); ``"stale"`` (valid, but its signature differs from
        ``expected_signature``); or ``"ok"``.

    Raises
    ------
    UntrustedCacheError
        The cache's key file is not private.
    """
    path = Path(path)
    if not path.is_file():
        return "missing"
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return "corrupt"
    return _classify(path, text, expected_signature)


class _VerifiedSourceLoader(importlib.machinery.SourceFileLoader):
    """Imports exactly the bytes that were checked (no second read, no ``.pyc`` in between)."""

    def __init__(self, fullname: str, path: str, source: bytes):
        super().__init__(fullname, path)
        self._source = source

    def get_data(self, path):
        if path == self.path:
            return self._source
        raise OSError(f"{path}: not read by methodgen's loader")  # i.e. no bytecode cache

    def get_code(self, fullname):
        return self.source_to_code(self._source, self.path)


def _read_checked(path: Path, expected_signature: str | None) -> tuple[str, bytes | None]:
    """Read ``path`` once and classify those bytes: ``(status, bytes)`` (see :func:`file_status`)."""
    check_cache_folder(path)
    try:
        source = path.read_bytes()
        status = _classify(path, source.decode("utf-8"), expected_signature)
    except FileNotFoundError:
        return "missing", None
    except UnicodeDecodeError:
        return "corrupt", None
    except OSError as exc:
        raise GenerationError(f"cannot read generated module {path}: {exc.strerror or exc}") from None
    return status, source


def _exec_source(path: Path, source: bytes) -> ModuleType:
    """Import the module at ``path`` from ``source`` (its checked bytes), never from a second read."""
    digest = hashlib.sha256(str(path).encode()).hexdigest()[:12]
    name = f"methodgen_generated.{path.stem}_{digest}"
    loader = _VerifiedSourceLoader(name, str(path), source)
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    if spec is None:  # pragma: no cover - defensive
        raise GenerationError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    # generated code: the compiled route reads its kernel IR, never its text
    module.__dict__[GENERATED_ATTR] = True
    sys.modules[name] = module
    try:
        loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def load_if_current(path, expected_signature: str) -> tuple[str, ModuleType | None]:
    """Import the module at ``path`` only if it is current: ``(status, module or None)``.

    As :func:`load_module` with ``expected_signature``, but a file that is not
    ``"ok"`` (missing, corrupt, untrusted, stale) is reported instead of raised,
    for callers that then rebuild it (the warm start of
    :func:`methodgen.codegen.build.build_text`).  The checks and the import use the same
    bytes, read once: a file replaced in between is never imported.
    """
    path = Path(path).resolve()
    status, source = _read_checked(path, expected_signature)
    if status != "ok":
        return status, None
    return status, _exec_source(path, source)


def load_module(path: Path, expected_signature: str | None = None) -> ModuleType:
    """Import a generated module from its file.

    The file is read once; its content hash (and, in the per-user cache, the
    folder and the user's key tag; and ``expected_signature`` when given) is
    checked, and exactly those bytes are compiled and run — no second read of
    the file and no ``.pyc``.  So a module checked and then replaced by
    another process before the import is never imported in its place.

    Parameters
    ----------
    path : path-like
    expected_signature : str, optional
        The signature the module must carry (:func:`signature`); a module of
        another signature is refused.

    Raises
    ------
    GenerationError
        The file is missing, corrupt, untrusted, of another signature or
        unreadable (nothing is run).
    UntrustedCacheError
        A cache folder others can write to.
    """
    path = Path(path).resolve()
    status, source = _read_checked(path, expected_signature)
    if status != "ok":
        why = {"untrusted": "not written by this user's methodgen (no valid key tag)",
               "stale": "of another signature than the one just checked or written (another process "
                        "wrote to the same path meanwhile?)"}.get(status, status)
        raise GenerationError(f"generated module {path} is {why}; regenerate it (it was not imported)")
    return _exec_source(path, source)


def warn_regenerating(path, status: str, stacklevel: int = 3) -> None:
    """The warning for a file that is regenerated because it cannot be trusted."""
    if status == "corrupt":
        warnings.warn(f"generated module {path} does not match its content hash (edited or "
                      "truncated); regenerating it", RuntimeWarning, stacklevel=stacklevel)
    elif status == "untrusted":
        warnings.warn(f"cached module {path} was not written by this user's methodgen (no valid key "
                      "tag: planted, edited, or from an older version); it is not imported — "
                      "regenerating it", RuntimeWarning, stacklevel=stacklevel)


def generate(scheme, path: str | os.PathLike | None = None, backend: str = "numpy", *,
             progress=None) -> ModuleType:
    """Emit ``scheme`` as a solver module, write it, import it and return the module.

    Parameters
    ----------
    scheme : Scheme
        From :func:`methodgen.discretize`.
    path : path-like, optional
        File to write.  Default: the per-user cache (:func:`cache_dir`), under a
        name that includes the signature.  A file that is already up to date
        (same signature, intact content) is not rewritten.
    backend : {"numpy", "numba"}
        ``"numba"`` (the compiled backend; the name is historical): kernels,
        Newton's method and the integration loop compiled to machine code through
        llvmlite (same interface and results to round-off).  Without llvmlite
        installed a RuntimeWarning is issued and the numpy module is returned.
    progress : callable, optional
        ``progress(phase, elapsed, done)`` for lower, render, write and load
        (:mod:`methodgen.codegen.progress`); default: the installed reporter.

    Returns
    -------
    module
        The imported generated module.
    """
    backend = resolve_backend(backend)
    sig = signature(scheme.system, scheme.key, backend)
    name = scheme.system.name or "system"
    if path is None:
        path = cache_dir() / module_filename(f"{name}_{sig[:12]}", scheme.key, backend)
    path = Path(path)
    return write_and_load(path, sig, lambda: emit_source(scheme, sig, path.stem, backend, progress=progress),
                          progress)


def write_and_load(path, sig: str, source, progress=None) -> ModuleType:
    """The module of signature ``sig`` at ``path``: written from ``source()`` (called only when
    the file is missing, stale, edited or untrusted; a warning says which where it was not
    ours), then imported from the checked bytes (:func:`load_module`)."""
    path = Path(path)
    check_cache_folder(path)
    status = file_status(path, sig)
    if status != "ok":
        if status == "untrusted":
            warn_regenerating(path, status)
        text = source()
        with phase("write", progress):
            write_module(path, text)
    with phase("load", progress):
        return load_module(path, expected_signature=sig)


def emit_source(scheme, sig: str | None = None, module_name: str | None = None,
                backend: str = "numpy", *, progress=None, expanded: bool = False) -> str:
    """The full source text of the generated module for ``scheme`` (no fallback: any backend renders).

    ``progress``: reporter of the phases lower and render (:mod:`methodgen.codegen.progress`).
    ``expanded``: internal (tests, benchmarks) -- an s-stage method's expanded stage system
    instead of its loops over the stages (:func:`methodgen.codegen.lower.lower`).
    """
    from .lower import lower

    sig = sig or signature(scheme.system, scheme.key, backend)
    name = module_name or module_filename(scheme.system.name or "system", scheme.key, backend)[:-3]
    with phase("lower", progress):
        ir = lower(scheme, sig, name, expanded=expanded, backend=backend)
    with phase("render", progress):
        return render(ir, backend)
