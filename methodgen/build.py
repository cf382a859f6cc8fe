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
from .schemes import METHODS, composition_for, discretize, method_key, scheme_options

__all__ = ["build", "generate", "default_path", "generated_dir", "scene_module_path", "scene_targets"]


def generated_dir() -> Path | None:
    """The repository's ``generated/`` folder when running from a source checkout, else None."""
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").is_file() and (root / "generated").is_dir():
        return root / "generated"
    return None


def scene_targets(scene) -> list[tuple[str, int, str | None]]:
    """``(method, order, composition)`` of every module ``methodgen generate`` keeps for ``scene``.

    Each of the scene's methods as it is and, when ``[run] order`` is above 2, each
    composed to that order.
    """
    out = [(m, 2, None) for m in scene.methods]
    if getattr(scene, "order", 2) > 2:
        out += [(m, scene.order, scene.composition) for m in scene.methods]
    return out


def _kept_in_generated(scene, key: str, gen: Path) -> bool:
    """Whether the module ``key`` (a method key) of a built-in scene belongs in ``generated/``.

    Base methods: yes (as always).  Composed keys only when the scene's ``[run] order``
    declares them or the file is already there (``methodgen generate --order``);
    otherwise they go to the cache, so that ``methodgen run kepler --order 8`` leaves
    the committed folder alone.
    """
    if key in METHODS or (gen / module_filename(scene.name, key)).is_file():
        return True
    return key in {method_key(m, composition_for(o, c)) for m, o, c in scene_targets(scene)}


def scene_module_path(scene, method: str, backend: str = "numpy") -> Path:
    """Where the module of ``scene`` × ``method`` lives: ``generated/`` for built-ins in a checkout, else the cache.

    ``method`` is the method key (:func:`methodgen.schemes.method_key`).
    ``generated/`` holds numpy modules only (they are committed and sync-checked):
    modules of other backends always live in the cache, and so do composed modules
    the scene does not declare (see :func:`scene_targets`).
    """
    fname = module_filename(scene.name, method, backend)
    gen = generated_dir()
    if scene.builtin and gen is not None and backend == "numpy" and _kept_in_generated(scene, method, gen):
        return gen / fname
    sig = signature(scene.system, method, backend)
    return cache_dir() / module_filename(f"{scene.name}_{sig[:12]}", method, backend)


def default_path(system: Hamiltonian, method: str, backend: str = "numpy") -> Path:
    """Where a module goes when no path is given.

    The checkout's ``generated/`` for the system of a built-in scene (same name,
    same fingerprint), otherwise the per-user cache under a name with the signature.
    Modules of backends other than numpy always go to the cache (``generated/``
    holds the committed numpy modules only).
    """
    from .scene import load_scene, scene_names

    gen = generated_dir()
    if gen is not None and backend == "numpy" and system.name in scene_names():
        scene = load_scene(system.name)
        if scene.system.fingerprint() == system.fingerprint() and _kept_in_generated(scene, method, gen):
            return gen / module_filename(scene.name, method)
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
