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
* Generated modules are imported from their file (never ``exec`` of a string).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import sys
import tempfile
import warnings
from pathlib import Path
from types import ModuleType

import jinja2
import sympy

from ._version import __version__
from .errors import GenerationError, InputError
from .lower import Kernel, ModuleIR, lower

__all__ = ["template_dir", "template_hash", "signature", "render", "write_atomic", "file_status",
           "load_module", "generate", "module_filename", "cache_dir", "BACKENDS", "numba_available",
           "resolve_backend"]

#: Code generation backends: plain numpy, or numba-compiled kernels and integration loop.
BACKENDS = ("numpy", "numba")
# Top-level template of each backend; numba templates are named numba_*.j2 so
# that the numpy template hash (and with it every numpy signature) ignores them.
_TEMPLATES = {"numpy": "module.py.j2", "numba": "numba_module.py.j2"}

HEADER_SIGNATURE = "# signature: "
HEADER_CONTENT = "# content-sha256: "


def template_dir() -> Path:
    """The templates folder: inside the installed package, or the repo's top-level ``templates/``."""
    here = Path(__file__).resolve().parent
    for cand in (here / "templates", here.parent / "templates"):
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
        if backend == "numpy" and path.name.startswith("numba_"):
            continue
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def signature(system, method: str, backend: str = "numpy") -> str:
    """Hash of everything a generated module depends on.

    Computed from the system's fingerprint, the method name, the backend and
    the versions of methodgen, SymPy and the templates — no derivation needed,
    so a cached module can be reused without re-deriving the scheme.  The
    backend enters the hash only when it is not ``"numpy"``: numpy signatures
    stay what they were before there was a choice (committed modules remain in
    sync), and a numpy and a numba module never share a signature.
    """
    parts = [system.fingerprint(), method, __version__, sympy.__version__, template_hash(backend)]
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


def numba_available() -> bool:
    """True when numba can be imported (the ``methodgen[fast]`` extra)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_backend(backend: str, stacklevel: int = 3) -> str:
    """Validate ``backend``; ``"numba"`` without numba installed falls back to ``"numpy"`` with a warning.

    Raises
    ------
    InputError
        For a name not in :data:`BACKENDS`.
    """
    _check_backend(backend)
    if backend == "numba" and not numba_available():
        warnings.warn('numba is not installed, so the numpy backend is used instead; install it with '
                      'pip install "methodgen[fast]" for the compiled backend', RuntimeWarning,
                      stacklevel=stacklevel)
        return "numpy"
    return backend


def cache_dir() -> Path:
    """Per-user cache for generated modules (``$METHODGEN_CACHE`` or the XDG cache)."""
    env = os.environ.get("METHODGEN_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "methodgen"


# --- rendering --------------------------------------------------------------

def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_dir())),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )
    env.filters["pyrepr"] = repr
    env.filters["pytuple"] = lambda seq: repr(tuple(seq))
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
    return {"temps": kern.temps, "targets": targets, "allocs": allocs, "returns": returns}


def _docsafe(text: str) -> str:
    return " ".join(text.replace("\\", " ").replace('"""', "'''").split())


def render(ir: ModuleIR, backend: str = "numpy") -> str:
    """Render the module source for ``ir`` with the templates of ``backend`` (deterministic)."""
    _check_backend(backend)
    template = _TEMPLATES[backend]
    n, d2 = ir.n_unknowns, 2 * ir.dim
    vector = {
        "increment": _vector_view(ir.vector["increment"], [("_out", (d2,))], "_out"),
        "hamiltonian": _vector_view(ir.vector["hamiltonian"], [("_out", (1,))], "_out[..., 0]"),
        "invariants": _vector_view(ir.vector["invariants"],
                                   [("_out", (len(ir.invariant_names),))], "_out"),
    }
    if ir.n_constraints:
        m, d = ir.n_constraints, ir.dim
        vector["constraints"] = _vector_view(ir.vector["constraints"], [("_g", (m,)), ("_G", (m, d))], "_g, _G")
        vector["minv"] = _vector_view(ir.vector["minv"], [("_out", (d, d))], "_out")
    if n:
        vector["guess"] = _vector_view(ir.vector["guess"], [("_out", (n,))], "_out")
        vector["res"] = _vector_view(ir.vector["res"], [("_R", (n,))], "_R")
        vector["resjac"] = _vector_view(ir.vector["resjac"], [("_R", (n,)), ("_J", (n, n))], "_R, _J")
        if "scale" in ir.vector:
            vector["scale"] = _vector_view(ir.vector["scale"], [("_out", (1,))], "_out[..., 0]")
    defaults = "{" + ", ".join(f"{k!r}: {v}" for k, v in zip(ir.param_names, ir.param_defaults)) + "}"
    clean = ir.__class__(**{**ir.__dict__, "source": _docsafe(ir.source),
                            "constraints": tuple(_docsafe(c) for c in ir.constraints)})
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
        traits_text=repr(ir.traits))
    text = re.sub(r"\n{4,}", "\n\n\n", text).rstrip() + "\n"
    digest = hashlib.sha256(text.encode()).hexdigest()
    return HEADER_CONTENT + digest + "\n" + text


# --- files --------------------------------------------------------------------

def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file + ``os.replace``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=str(path.parent))
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def file_status(path: Path, expected_signature: str | None = None) -> str:
    """Classify a generated file.

    Returns
    -------
    str
        ``"missing"``; ``"corrupt"`` (no header, or the body does not match
        its content hash: edited or truncated); ``"stale"`` (valid, but its
        signature differs from ``expected_signature``); or ``"ok"``.
    """
    path = Path(path)
    if not path.is_file():
        return "missing"
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return "corrupt"
    first, _, body = text.partition("\n")
    if not first.startswith(HEADER_CONTENT):
        return "corrupt"
    if hashlib.sha256(body.encode()).hexdigest() != first[len(HEADER_CONTENT):].strip():
        return "corrupt"
    if expected_signature is not None:
        m = re.search(r"^" + re.escape(HEADER_SIGNATURE) + r"([0-9a-f]{64})$", body, re.M)
        if not m or m.group(1) != expected_signature:
            return "stale"
    return "ok"


def load_module(path: Path) -> ModuleType:
    """Import a generated module from its file (content hash checked first)."""
    path = Path(path).resolve()
    status = file_status(path)
    if status != "ok":
        raise GenerationError(f"generated module {path} is {status}; regenerate it")
    digest = hashlib.sha256(str(path).encode()).hexdigest()[:12]
    name = f"methodgen_generated.{path.stem}_{digest}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:  # pragma: no cover - defensive
        raise GenerationError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def generate(scheme, path: str | os.PathLike | None = None, backend: str = "numpy") -> ModuleType:
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
        ``"numba"`` compiles kernels, Newton's method and the integration loop
        with ``numba.njit(cache=True)`` (same interface and results to
        round-off).  Without numba installed a RuntimeWarning is issued and the
        numpy module is returned.

    Returns
    -------
    module
        The imported generated module.
    """
    backend = resolve_backend(backend)
    sig = signature(scheme.system, scheme.method, backend)
    name = scheme.system.name or "system"
    if path is None:
        path = cache_dir() / module_filename(f"{name}_{sig[:12]}", scheme.method, backend)
    path = Path(path)
    if file_status(path, sig) != "ok":
        write_atomic(path, emit_source(scheme, sig, path.stem, backend))
    return load_module(path)


def emit_source(scheme, sig: str | None = None, module_name: str | None = None,
                backend: str = "numpy") -> str:
    """The full source text of the generated module for ``scheme`` (no fallback: any backend renders)."""
    sig = sig or signature(scheme.system, scheme.method, backend)
    name = module_name or module_filename(scheme.system.name or "system", scheme.method, backend)[:-3]
    return render(lower(scheme, sig, name), backend)
