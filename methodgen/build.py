"""From a system (or scene) to an imported generated module, reusing files.

:func:`build` computes the signature of ``(system, method)`` first — cheap, no
derivation — and imports an existing file whose signature matches and whose
content is intact.  Only otherwise does it derive, lower and emit.  A file
whose content does not match its hash (edited, truncated) — or, in the
per-user cache, that lacks this user's key tag — is never trusted: it is
regenerated and a warning says so.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

from .emit import (cache_dir, check_cache_folder, emit_source, file_status, load_module, module_filename,
                   resolve_backend, signature, warn_regenerating, write_module)
from .problem import Hamiltonian
from .schemes import composition_for, discretize, method_key, scheme_options

__all__ = ["build", "generate", "default_path", "generated_dir", "scene_module_path", "scene_targets",
           "target_key", "scene_system_name"]


def generated_dir() -> Path | None:
    """The repository's ``generated/`` folder when running from a source checkout, else None."""
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").is_file() and (root / "generated").is_dir():
        return root / "generated"
    return None


def scene_targets(scene) -> list[tuple[str, int, str | None, dict]]:
    """``(method, order, composition, options)`` of every module ``methodgen generate`` keeps
    for ``scene`` (modules of :attr:`Scene.run_system <methodgen.scene.Scene.run_system>`).

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

    ``method`` is the method key (:func:`methodgen.schemes.method_key`); ``system`` the
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
    from .scene import load_scene, scene_names

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


def generate(scheme, path=None, backend: str = "numpy") -> ModuleType:
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
        ``"numba"``: kernels, Newton's method and the integration loop compiled
        with ``numba.njit(cache=True)`` (same interface, same results to
        round-off).  Without numba installed: a RuntimeWarning and the numpy module.
    """
    from .emit import generate as emit_generate

    backend = resolve_backend(backend)
    if path is None:
        path = default_path(scheme.system, scheme.key, backend)
    return emit_generate(scheme, path, backend)


def build(system: Hamiltonian, method: str, path=None, backend: str = "numpy", *, order: int = 2,
          composition: str | None = None, **options) -> ModuleType:
    """Return the generated module for ``system`` and ``method``, generating it only if needed.

    A file in the per-user cache is imported only when it carries this user's
    key tag (:func:`methodgen.emit.file_status`) and its folders are private
    (:func:`methodgen.emit.check_cache_folder`); an edited, truncated or
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
        See :func:`generate`; without numba installed, ``"numba"`` warns
        (RuntimeWarning) and builds the numpy module.
    order : {2, 4, 6, 8, 10}
    composition : str, optional
        For ``order > 2``: the composition family (see :func:`methodgen.discretize`).
    **options
        Method options (e.g. ``stages=3`` for ``"gauss"``), passed to :func:`methodgen.discretize`.
    """
    from .timetransform import autonomise

    system = autonomise(system)   # a time-dependent H: its autonomous extension K = H + e
    backend = resolve_backend(backend)
    key = method_key(method, composition_for(order, composition), scheme_options(method, options))
    sig = signature(system, key, backend)
    path = default_path(system, key, backend) if path is None else Path(path)
    check_cache_folder(path)  # a cache others can write to is refused before any derivation
    status = file_status(path, sig)
    if status == "ok":
        return load_module(path)
    warn_regenerating(path, status)
    scheme = discretize(system, method, order=order, composition=composition, **options)
    write_module(path, emit_source(scheme, sig, backend=backend))
    return load_module(path)
