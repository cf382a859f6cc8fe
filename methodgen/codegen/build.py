"""From a system (or scene) to an imported generated module, reusing files.

:func:`build` computes the signature of ``(system, method)`` first — cheap, no
derivation — and imports an existing file whose signature matches and whose
content is intact.  Only otherwise does it derive, lower and emit.  A file
whose content does not match its hash (edited, truncated) — or, in the
per-user cache, that lacks this user's key tag — is never trusted: it is
regenerated and a warning says so.

:func:`build_text` takes the Hamiltonian as text and keeps a small index in
the cache from a hash of that text (and everything else passed) to the module
built for it and its signature, so that a warm start — the module is already
there — imports neither SymPy nor the derivation code: only numpy and the
generated module.  Derivation imports (problem, schemes) happen on the cold
path only.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import json
import warnings
from collections.abc import Mapping
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from .._version import __version__
from .emit import (cache_dir, cache_root_of, check_cache_folder, emit_source, file_status, generator_hash,
                   load_if_current, load_module, module_filename, resolve_backend, signature,
                   template_hash, warn_regenerating, write_atomic, write_module)
from ..errors import InputError, MethodgenError, MethodNotApplicable, StorageError

if TYPE_CHECKING:  # the derivation is imported by the cold path only (see build_text)
    from ..problem.problem import Hamiltonian

__all__ = ["build", "build_text", "build_processed", "generate", "default_path", "generated_dir", "scene_module_path",
           "scene_targets", "target_key", "scene_system_name", "text_key"]


def generated_dir() -> Path | None:
    """The repository's ``generated/`` folder when running from a source checkout, else None."""
    root = Path(__file__).resolve().parents[2]
    if (root / "pyproject.toml").is_file() and (root / "generated").is_dir():
        return root / "generated"
    return None


def scene_targets(scene) -> list[tuple[str, int, str | None, dict]]:
    """``(method, order, composition, options)`` of every module ``methodgen generate`` keeps
    for ``scene`` (modules of :attr:`Scene.run_system <methodgen.symbolic.scene.Scene.run_system>`).

    Each of the scene's methods as it is (with the scene's ``[run] stages`` for the methods
    that take them) and, when ``[run] order`` is above 2, each composed to that order.
    """
    def opts(m):
        return scene.options(m) if hasattr(scene, "options") else {}
    out = [(m, 2, None, opts(m)) for m in scene.methods]
    if getattr(scene, "order", 2) > 2:
        out += [(m, scene.order, scene.composition, opts(m)) for m in scene.methods]
    return out


def target_key(method: str, order: int, composition: str | None, options: dict) -> str:
    """The method key (file names, signatures) of a ``scene_targets`` entry."""
    from ..symbolic.schemes import composition_for, method_key, scheme_options

    return method_key(method, composition_for(order, composition), scheme_options(method, options))


def _run_system(scene) -> Hamiltonian:
    return getattr(scene, "run_system", scene.system)


def scene_system_name(scene, system=None) -> str:
    """The name in the module file names of ``scene`` × ``system`` (default: the system the scene
    integrates): the scene's name, or the time-transformed system's (``<scene>-tt``)."""
    system = _run_system(scene) if system is None else system
    return scene.name if system is scene.system else (system.name or scene.name)


def _kept_in_generated(scene, key: str, gen: Path, system=None) -> bool:
    """Whether the module ``key`` (a method key) of ``system`` (default: the scene's) belongs
    in the built-in ``scene``'s folder ``generated/``.

    Only modules of the system the scene integrates (its time transformation, if it
    declares one) and only the variants the scene declares (:func:`scene_targets`: its
    methods, ``[run] order``, ``[run] stages``) — or whose file is already there
    (``methodgen generate --order``).  Everything else (another method, order, number of
    stages or time transformation, or the untransformed system of a transformed scene)
    goes to the cache, so that ``methodgen run kepler --method gauss --stages 3`` leaves the
    committed folder alone.
    """
    system = scene.system if system is None else system
    declared = getattr(scene, "declared_fingerprint", None) or _run_system(scene).fingerprint()
    if system.fingerprint() != declared:
        return False
    if (gen / module_filename(scene_system_name(scene, system), key)).is_file():
        return True
    return key in {target_key(*t) for t in scene_targets(scene)}


def scene_module_path(scene, method: str, backend: str = "numpy", system: Hamiltonian | None = None) -> Path:
    """Where the module of ``scene`` × ``method`` lives: ``generated/`` for built-ins in a checkout, else the cache.

    ``method`` is the method key (:func:`methodgen.symbolic.schemes.method_key`); ``system`` the
    system built (default ``scene.system``; pass ``scene.run_system`` for a scene with a
    time transformation — its modules are named after it, ``<scene>-tt``).
    ``generated/`` holds numpy modules only (they are committed and sync-checked):
    modules of other backends always live in the cache, and so do the variants the
    scene does not declare (see :func:`_kept_in_generated`).
    """
    system = scene.system if system is None else system
    name = scene_system_name(scene, system)
    fname = module_filename(name, method, backend)
    gen = generated_dir()
    if scene.builtin and gen is not None and backend == "numpy" and _kept_in_generated(scene, method, gen, system):
        return gen / fname
    sig = signature(system, method, backend)
    return cache_dir() / module_filename(f"{name}_{sig[:12]}", method, backend)


def default_path(system: Hamiltonian, method: str, backend: str = "numpy") -> Path:
    """Where a module goes when no path is given.

    The checkout's ``generated/`` for the system of a built-in scene (same name,
    same fingerprint), otherwise the per-user cache under a name with the signature.
    Modules of backends other than numpy always go to the cache (``generated/``
    holds the committed numpy modules only).
    """
    from ..symbolic.scene import load_scene, scene_names

    gen = generated_dir()
    if gen is not None and backend == "numpy":
        # The scene is found by the system's name, or, for a time transformation, by its original's.
        names = [system.name]
        if system.time_transform is not None:
            names.append(system.time_transform.original.name)
        builtin = scene_names()
        for name in dict.fromkeys(n for n in names if n in builtin):
            scene = load_scene(name)
            own = scene.run_system
            if own.fingerprint() == system.fingerprint() and _kept_in_generated(scene, method, gen, own):
                return gen / module_filename(scene_system_name(scene, own), method)
    sig = signature(system, method, backend)
    return cache_dir() / module_filename(f"{system.name or 'system'}_{sig[:12]}", method, backend)


def generate(scheme, path=None, backend: str = "numpy", *, progress=None) -> ModuleType:
    """Emit ``scheme`` as a solver module, write it, import it and return the module.

    Parameters
    ----------
    scheme : Scheme
        From :func:`methodgen.discretize`.
    path : path-like, optional
        File to write.  Default: ``generated/`` for a built-in scene's system in a
        source checkout, otherwise the per-user cache (``$METHODGEN_CACHE`` or
        ``~/.cache/methodgen``) under a name that includes the signature.  A file that
        is already up to date (same signature, intact content) is not rewritten.
    backend : {"numpy", "numba"}
        ``"numba"`` (the compiled backend; the name is historical): kernels, Newton's
        method and the integration loop compiled through llvmlite (same interface, same
        results to round-off).  Without llvmlite installed: a RuntimeWarning and the numpy
        module.
    progress : callable or True, optional
        ``progress(phase, elapsed, done)`` for the phases lower, render, write and
        load (:mod:`methodgen.codegen.progress`); default: the installed reporter (silent in the API).
    """
    from .emit import generate as emit_generate
    from .progress import about

    backend = resolve_backend(backend)
    if path is None:
        path = default_path(scheme.system, scheme.key, backend)
    with about(Path(path).name):
        return emit_generate(scheme, path, backend, progress=progress)


def _build(system, method: str, path, backend: str, order: int, composition, options: dict,
           progress) -> tuple[ModuleType, Path, str]:
    """:func:`build`, also returning the module's path and signature."""
    from .progress import about, phase
    from ..symbolic.schemes import composition_for, discretize, method_key, scheme_options
    from ..symbolic.timetransform import autonomise

    system = autonomise(system)   # a time-dependent H: its autonomous extension K = H + e
    backend = resolve_backend(backend, stacklevel=4)
    key = method_key(method, composition_for(order, composition), scheme_options(method, options))
    sig = signature(system, key, backend)
    path = default_path(system, key, backend) if path is None else Path(path)
    check_cache_folder(path)  # a cache others can write to is refused before any derivation
    status = file_status(path, sig)
    with about(path.name):
        if status != "ok":
            warn_regenerating(path, status, stacklevel=4)
            with phase("derive", progress):
                scheme = discretize(system, method, order=order, composition=composition, **options)
            text = emit_source(scheme, sig, backend=backend, progress=progress)
            with phase("write", progress):
                write_module(path, text)
        with phase("load", progress):
            # checked on the bytes imported: a file replaced since file_status is refused, not run
            module = load_module(path, expected_signature=sig)
    return module, path, sig


def build(system: Hamiltonian, method: str, path=None, backend: str = "numpy", *, order: int = 2,
          composition: str | None = None, progress=None, **options) -> ModuleType:
    """Return the generated module for ``system`` and ``method``, generating it only if needed.

    A file in the per-user cache is imported only when it carries this user's
    key tag (:func:`methodgen.codegen.emit.file_status`) and its folders are private
    (:func:`methodgen.codegen.emit.check_cache_folder`); an edited, truncated or
    planted file is regenerated with a RuntimeWarning, never imported.

    Parameters
    ----------
    system : Hamiltonian
        A time-dependent one (``time="t"``) is built as its autonomous extension
        (:func:`methodgen.autonomise`): the module's state is ``(q, t, p, e)``; start from
        ``module.initial_state(y0, t0)``.
    method : str
    path : path-like, optional
        Target file; default: the per-user cache, named by the signature.
    backend : {"numpy", "numba"}
        See :func:`generate`; without llvmlite installed, ``"numba"`` warns
        (RuntimeWarning) and builds the numpy module.
    order : {2, 4, 6, 8, 10}
    composition : str, optional
        For ``order > 2``: the composition family (see :func:`methodgen.discretize`).
    progress : callable or True, optional
        ``progress(phase, elapsed, done)``, called at the start and the end of each
        phase of a cold build — derive, lower, render, write — and of load
        (:mod:`methodgen.codegen.progress`; :func:`methodgen.codegen.progress.tqdm_reporter` for tqdm
        bars).  Default: the installed reporter, none in the API (silent).
    **options
        Method options (e.g. ``stages=3`` for ``"gauss"``), passed to :func:`methodgen.discretize`.
    """
    from ..symbolic.compositions import PROCESSED_FAMILIES

    if composition in PROCESSED_FAMILIES:
        # three modules of one base scheme (kernel, pre- and post-processor): methodgen.symbolic.processing

        if path is not None:
            raise InputError(f"path= does not apply to the processed composition {composition!r}: it is "
                             "three generated modules (kernel, pre- and post-processor), kept in the cache")
        return build_processed(system, method, order, composition, backend=backend, progress=progress,
                               **options)
    return _build(system, method, path, backend, order, composition, options, progress)[0]


# --- warm start from the Hamiltonian's text ------------------------------------------------------

#: Folder of the cache with the warm-start index (one small JSON file per text key).
WARM_INDEX = "warm-index"


def _tagged(value, what: str):
    """``value`` as JSON with its type in every node (the key of :func:`build_text`).

    Every value carries its type, so no two arguments that build differently
    share a key (``1.0`` and ``{"float": "1.0"}``, ``1`` and ``True``, a
    ``numpy.float64`` and a float); mappings keep their order (a system's
    parameters and invariants are declared in order: ``PARAM_NAMES``,
    ``INVARIANT_NAMES`` and the signature follow it).  Anything but text,
    numbers, None, lists and mappings of them is refused.
    """
    kind = type(value)
    if value is None:
        return ["none"]
    if kind in (bool, int, str):
        return [kind.__name__, value]
    if kind is float:
        return ["float", repr(value)]      # repr round-trips
    if isinstance(value, (bool, int, float, str)):   # subclasses (numpy.float64 …): their own type
        return [f"{kind.__module__}.{kind.__qualname__}", repr(value)]
    if isinstance(value, Mapping):
        return ["map", [[_tagged(k, f"{what} key"), _tagged(v, f"{what}[{k!r}]")] for k, v in value.items()]]
    if isinstance(value, (list, tuple)):
        return ["seq", [_tagged(v, what) for v in value]]
    raise InputError(f"build_text takes text and numbers: {what} is a {kind.__name__}; use "
                     "methodgen.Hamiltonian(...) with methodgen.build(...) for SymPy objects")


def _sequence(value, what: str, example: str):
    """``value`` (a list of ``what``) checked as :class:`~methodgen.problem.problem.Hamiltonian` would: text is refused."""
    if isinstance(value, (str, bytes)):
        raise InputError(f"{what} must be a list, e.g. {example}, got the string {value!r}")
    if not isinstance(value, (list, tuple)):
        raise InputError(f"build_text takes {what} as a list, e.g. {example}, got a {type(value).__name__}")
    return value


def _mapping(value, what: str, example: str):
    """``value`` (None or a mapping) checked as :class:`~methodgen.problem.problem.Hamiltonian` would."""
    if value is not None and not isinstance(value, Mapping):
        raise InputError(f"{what} must be a mapping, e.g. {example}, got a {type(value).__name__}")
    return value


@functools.lru_cache(maxsize=None)
def _own_source_hash() -> str:
    """SHA-256 of this file: how text becomes a build (outside :func:`~methodgen.codegen.emit.generator_hash`)."""
    return hashlib.sha256(Path(__file__).read_bytes()).hexdigest()


def _sympy_identity() -> str | None:
    """Which SymPy ``import sympy`` would import, without importing it; None when there is none.

    The SymPy found first on ``sys.path`` (:func:`importlib.util.find_spec`, as
    the import itself finds it — also one on ``PYTHONPATH`` that shadows the
    installed one), named by its folder and the bytes of its ``__init__.py``
    and ``release.py`` (where its ``__version__`` is set).  Any other SymPy —
    another version or another copy — gives another identity.
    """
    import importlib.util

    try:
        spec = importlib.util.find_spec("sympy")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.origin:
        return None
    init = Path(spec.origin)
    h = hashlib.sha256(str(init.resolve()).encode() + b"\0")
    for part in (init, init.with_name("release.py")):
        try:
            h.update(part.read_bytes() + b"\0")
        except FileNotFoundError:
            h.update(b"-\0")
        except OSError:
            return None
    return h.hexdigest()


def text_key(H: str, q, p, method: str, *, params=None, constraints=(), name=None, invariants=None,
             time=None, path=None, backend: str = "numpy", order: int = 2, composition=None,
             options=None) -> str | None:
    """Hash of everything :func:`build_text` is given and of what the module depends on besides.

    The text of the system (parameters and invariants in their order: the
    module follows it), the method and its options, the backend and path, the
    cache root (resolved: an index copied into another cache finds nothing),
    methodgen's version, the SymPy that would be imported
    (:func:`_sympy_identity`; SymPy is not imported), the templates, the
    generator's sources and this file's own source — so a key made by other
    code never finds a module.  None when there is no SymPy (then there is no
    warm start).

    Raises
    ------
    InputError
        An argument that is not text or numbers, ``q``, ``p`` or ``constraints``
        given as a string, ``params`` or ``invariants`` not a mapping — as the
        cold path (:class:`methodgen.Hamiltonian`) would refuse them.
    """
    if not isinstance(H, str):
        raise InputError(f"build_text takes H as text, got a {type(H).__name__}; use "
                         "methodgen.Hamiltonian(...) with methodgen.build(...) for SymPy objects")
    args = [("H", H), ("q", _sequence(q, "q", '["q"]')), ("p", _sequence(p, "p", '["p"]')),
            ("params", _mapping(params, "params", '{"m": 1.0}')),
            ("constraints", _sequence(constraints, "constraints", '["q1**2 + q2**2 - 1"]')),
            ("name", name), ("invariants", _mapping(invariants, "invariants", '{"P": "p1 + p2"}')),
            ("time", time), ("path", str(Path(path).resolve()) if path is not None else None),
            ("method", method), ("order", order), ("composition", composition),
            # keyword options: their order means nothing, so they are sorted
            ("options", dict(sorted(dict(options or {}).items())))]
    parts = [[k, _tagged(v, k)] for k, v in args]
    sympy_id = _sympy_identity()
    if sympy_id is None:
        return None
    blob = json.dumps({"inputs": parts, "methodgen": __version__, "sympy": sympy_id,
                       "cache": str(cache_dir().resolve()), "backend": backend,
                       "templates": template_hash(backend), "generator": generator_hash(),
                       "build": _own_source_hash()}, sort_keys=True)
    return hashlib.sha256(b"methodgen-text-key-v2\0" + blob.encode()).hexdigest()


def _index_file(key: str) -> Path:
    return cache_dir() / WARM_INDEX / f"{key[:40]}.json"


#: HMAC domain of the index entries (never the same message as a module's tag, see emit._keyed_tag).
_INDEX_DOMAIN = b"methodgen-warm-index-v2\0"


def _index_tag(root: Path, body: str) -> str | None:
    from .emit import _cache_key

    secret = _cache_key(root, create=False)
    return None if secret is None else hmac.new(secret, _INDEX_DOMAIN + body.encode(), hashlib.sha256).hexdigest()


def _inside(base: Path, rel: str) -> Path | None:
    """``base / rel`` resolved, when ``rel`` is relative and stays inside ``base`` (no ``..``, no link out)."""
    if not rel or Path(rel).is_absolute() or ".." in Path(rel).parts:
        return None
    target = (base / rel).resolve()
    try:
        target.relative_to(base)
    except ValueError:
        return None
    return target


def _where(module_path: Path, path) -> dict | None:
    """How the index names ``module_path``: relative to the cache or ``generated/``, or the path given."""
    module_path = Path(module_path).resolve()
    if path is not None:
        return {"in": "path", "path": str(Path(path).resolve())}
    for base_name, base in (("cache", cache_dir().resolve()), ("generated", generated_dir())):
        if base is None:
            continue
        try:
            return {"in": base_name, "path": module_path.relative_to(base.resolve()).as_posix()}
        except ValueError:
            continue
    return None   # pragma: no cover - default_path puts modules in one of the two


def _located(where: dict, path) -> Path | None:
    """The module an index entry names, if it is where this call's modules go (else None).

    ``path=None``: the entry's relative path, inside the current cache root (or
    the checkout's ``generated/``) — never a file elsewhere, whatever the entry
    says.  A given ``path``: the entry must name exactly that file.
    """
    kind, text = where.get("in"), where.get("path")
    if not isinstance(text, str):
        return None
    if path is not None:
        wanted = Path(path).resolve()
        return wanted if kind == "path" and text == str(wanted) else None
    if kind == "cache":
        return _inside(cache_dir().resolve(), text)
    if kind == "generated":
        gen = generated_dir()
        return None if gen is None else _inside(gen.resolve(), text)
    return None


class _IndexTrouble(Exception):
    """The index could not be used (a cache folder or key not trusted, a file unreadable)."""


def _index_lookup(key: str, path=None) -> tuple[Path, str] | None:
    """``(module path, signature)`` the index holds for ``key``; None if absent or not to be trusted.

    Raises
    ------
    _IndexTrouble
        The cache folder or key cannot be trusted, or the entry cannot be read
        (the caller warns once and takes the cold path).
    """
    entry = _index_file(key)
    try:
        root = check_cache_folder(entry)
        raw = entry.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (MethodgenError, OSError) as exc:
        raise _IndexTrouble(str(exc)) from None
    try:
        data = json.loads(raw)
        body = json.dumps(data["entry"], sort_keys=True)
        tag, where, sig = data["tag"], data["entry"]["where"], str(data["entry"]["signature"])
        if data["entry"]["key"] != key or not isinstance(where, dict):
            return None
    except (ValueError, KeyError, TypeError):
        return None
    try:
        expected = _index_tag(root, body) if root is not None else None
    except (MethodgenError, OSError) as exc:
        raise _IndexTrouble(str(exc)) from None
    if expected is None or not hmac.compare_digest(str(tag), expected):
        return None   # not written by this user's methodgen: ignored (the cold path decides)
    module_path = _located(where, path)
    return None if module_path is None else (module_path, sig)


def _index_record(key: str, module_path: Path, sig: str, path=None) -> None:
    """Remember that ``key`` was built into ``module_path`` with signature ``sig`` (keyed with the user's secret).

    Raises
    ------
    _IndexTrouble
        The entry could not be written (the module is built; only the next start is cold).
    """
    where = _where(module_path, path)
    entry = _index_file(key)
    root = cache_root_of(entry)
    if where is None or root is None:  # pragma: no cover - the index lives in the cache by construction
        return
    from .emit import _cache_key

    body = {"key": key, "where": where, "signature": sig}
    try:
        try:
            root.mkdir(mode=0o700, parents=True, exist_ok=True)   # as for a module in the cache
            entry.parent.mkdir(mode=0o700, exist_ok=True)
        except OSError as exc:
            raise StorageError(f"cannot create {entry.parent}: {exc.strerror or exc}", entry.parent,
                               exc.errno) from None
        check_cache_folder(entry)
        _cache_key(root, create=True)
        tag = _index_tag(root, json.dumps(body, sort_keys=True))
        write_atomic(entry, json.dumps({"entry": body, "tag": tag}, sort_keys=True) + "\n")
    except (MethodgenError, OSError) as exc:
        raise _IndexTrouble(str(exc)) from None


def _warn_no_index(exc: _IndexTrouble, stacklevel: int) -> None:
    warnings.warn(f"the warm-start index cannot be used ({exc}); no warm start: the module is built "
                  "as methodgen.build builds it", RuntimeWarning, stacklevel=stacklevel + 1)


def build_text(H: str, q, p, method: str, *, params=None, constraints=(), name: str | None = None,
               invariants=None, time: str | None = None, path=None, backend: str = "numpy",
               order: int = 2, composition: str | None = None, progress=None, **options) -> ModuleType:
    """The generated module for a Hamiltonian given as text: warm starts without SymPy.

    The same as ``build(Hamiltonian(H, q, p, params=..., ...), method, ...)``, but
    a module already built for exactly these arguments is found through an index
    in the cache (:func:`text_key` → module and signature) and imported without
    importing SymPy or the derivation code: the warm path computes a hash, reads
    one small file (tagged with this user's key), and imports the module after
    checking — on the very bytes it runs — its signature, content hash and, in the
    cache, this user's key tag, as :func:`build` does.  The entry names the module
    relative to the current cache root (or ``generated/``) when ``path`` is None,
    and must name exactly ``path`` otherwise: it never leads to a file elsewhere.
    Anything else — no entry, a module edited, replaced by another signature
    (stale) or untrusted, another methodgen, SymPy, templates or generator sources
    — goes the cold way, :func:`build`, which derives and rewrites the module when
    needed and records the entry.  An index that cannot be used (a cache folder
    others can write to while ``path`` is elsewhere, an unreadable entry) means no
    warm start: one RuntimeWarning, and the cold way.

    Parameters
    ----------
    H : str
        The Hamiltonian as text (parsed, never evaluated, on the cold path only).
    q, p, params, constraints, name, invariants, time
        As for :class:`methodgen.Hamiltonian`, as text and numbers.
    method, path, backend, order, composition, progress, **options
        As for :func:`build`.

    Raises
    ------
    InputError
        An argument that is not text or numbers (SymPy objects: use :func:`build`),
        ``q``, ``p`` or ``constraints`` as a string, ``params`` or ``invariants`` not
        a mapping — whether or not the module is cached.
    """
    backend = resolve_backend(backend)
    key = text_key(H, q, p, method, params=params, constraints=constraints, name=name, invariants=invariants,
                   time=time, path=path, backend=backend, order=order, composition=composition,
                   options=options)
    index_usable = key is not None
    if index_usable:
        try:
            found = _index_lookup(key, path)
        except _IndexTrouble as exc:   # e.g. a cache others can write to, with path= elsewhere
            _warn_no_index(exc, stacklevel=2)
            found, index_usable = None, False
        if found is not None:
            module_path, sig = found
            from .progress import about, phase

            with about(module_path.name), phase("load", progress):
                # one read: signature, content hash and key tag checked on the bytes that run
                _, module = load_if_current(module_path, sig)
            if module is not None:
                return module
            # stale, edited, untrusted, missing: the cold path rebuilds (and warns as build does)
    from ..problem.problem import Hamiltonian

    system = Hamiltonian(H, q, p, params=params, constraints=constraints, name=name, invariants=invariants,
                         time=time)
    module, module_path, sig = _build(system, method, path, backend, order, composition, options, progress)
    if index_usable:
        try:
            _index_record(key, module_path, sig, path)
        except _IndexTrouble as exc:
            _warn_no_index(exc, stacklevel=2)
    return module


def build_processed(system, method: str, order: int = 8, family: str = "blanes-casas-murua", *,
                    backend: str = "numpy", progress=None, **options) -> ProcessedIntegrator:
    """Build the processed composition of ``method`` on ``system``.

    Parameters
    ----------
    system : Hamiltonian
    method : str
        A method that is symmetric of order 2 on ``system`` (as for ``order=`` in
        :func:`methodgen.discretize`).
    order : {6, 8}
    family : str
        One of :data:`PROCESSED`.
    backend : {"numpy", "numba"}
    progress : callable or True, optional
        As for :func:`methodgen.build` (the phases of each module's generation).
    **options
        Method options, passed to :func:`methodgen.discretize`.

    Returns
    -------
    ProcessedIntegrator
    """
    from ..symbolic.processing import ProcessedIntegrator, processed_composition
    from ..symbolic.schemes import SYMMETRIC_METHODS, applicable_methods, discretize

    try:
        proc = processed_composition(order, family)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    base = discretize(system, method, **options)
    t = base.traits
    if not (t.symmetric and t.order == 2) or base.composition is not None:
        ok = [m for m in applicable_methods(system) if m in SYMMETRIC_METHODS]
        raise MethodNotApplicable(
            f"a processed composition needs a symmetric method of order 2; {method} is "
            f"{'not symmetric' if not t.symmetric else f'of order {t.order}'} for this system. "
            f"Symmetric methods that apply: {', '.join(ok) if ok else '(none)'}")
    mods = [generate(base.compose(proc.composition(role)), backend=backend, progress=progress)
            for role in ("kernel", "pre-processor", "post-processor")]
    return ProcessedIntegrator(proc, *mods)
