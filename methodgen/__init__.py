"""methodgen: geometric integrators generated from your Hamiltonian.

Pipeline (data flows one way)::

    scene.toml -> Hamiltonian -> derive -> discretize (Scheme) -> verify
               -> lower (IR) -> emit (templates) -> generated/*.py -> run / bench

Public API
----------
Hamiltonian(H, q, p, params=None, constraints=(), name=None, invariants=None, time=None)
autonomise(system) -> Hamiltonian               (K = H(q, p, t) + e on (q, t; p, e); done by discretize/build)
PoissonSystem(H, y, S, params=None, invariants=None, name=None)   (y' = S(y)∇H(y), non-canonical)
discretize(system, method) -> Scheme
generate(scheme, path=None, backend="numpy") -> module   (backend="numba": compiled loop)
build(system, method, path=None, backend="numpy") -> module  (reuses an up-to-date file without deriving)
build_text(H, q, p, method, params=..., ...) -> module  (warm start: no SymPy when the module is cached)
verify(scheme) -> Report                        (exact certificates of the method's claims)
load_scene(name_or_path) -> Scene
Lattice(H, q="q", p="p", size="N", params=None, invariants=None)   (site sums of symbolic size N)
build_lattice(lattice, "avf" | "midpoint", path=None) -> module     (one module for every N)
load_lattice_scene(name_or_path) -> LatticeScene
wisdom_holman(scene, "sbab4") -> WisdomHolman  (Wisdom–Holman splittings of [nbody] scenes)
methods() / scenes()

``import methodgen`` imports numpy but not SymPy: the names that need SymPy
(Hamiltonian, discretize, verify, load_scene …) are imported on first use
(PEP 562), so loading a cached module through :func:`build_text` stays light.
"""

from ._version import __version__
from .build import build, build_text, generate
from .errors import (GenerationError, InputError, MethodgenError, MethodNotApplicable,
                     ParseError, SceneError)

__all__ = [
    "__version__", "Hamiltonian", "PoissonSystem", "discretize", "generate", "build", "build_text",
    "Scheme", "Traits", "load_scene", "Scene", "scene_names", "methods", "scenes", "applicable_methods",
    "verify", "MethodgenError", "InputError", "ParseError", "SceneError", "MethodNotApplicable",
    "GenerationError", "time_transform", "autonomise", "wisdom_holman", "cite", "event", "section_event",
    "poincare", "save_trajectory", "read_trajectory", "Lattice", "build_lattice", "load_lattice_scene",
]


def _lazy_names():
    """``__getattr__`` and ``__dir__`` of the package (PEP 562); its helpers stay out of the namespace."""
    import importlib
    import sys
    import types

    # Public names imported on first use (they import SymPy and the derivation code).
    lazy = {
        "Hamiltonian": ".problem", "PoissonSystem": ".poisson",
        "Scheme": ".schemes", "Traits": ".schemes", "applicable_methods": ".schemes",
        "discretize": ".schemes", "method_names": ".schemes",
        "Scene": ".scene", "load_scene": ".scene", "scene_names": ".scene",
        "autonomise": ".timetransform", "time_transform": ".timetransform",
        "verify": ".verify", "wisdom_holman": ".nbody", "cite": ".cite",
        "event": ".events", "section_event": ".events", "poincare": ".events",
        "save_trajectory": ".trajfile", "read_trajectory": ".trajfile",
        "Lattice": ".lattice", "build_lattice": ".lattice_emit", "load_lattice_scene": ".lattice_scene",
    }
    found: list[frozenset] = []

    def submodules() -> frozenset:
        if not found:
            import pkgutil

            found.append(frozenset(m.name for m in pkgutil.iter_modules(__path__)
                                   if not m.name.startswith("__")))   # never __main__ (the CLI)
        return found[0]

    def __getattr__(name: str):
        where = lazy.get(name)
        if where is not None:
            value = getattr(importlib.import_module(where, __name__), name)
            globals()[name] = value
            return value
        if name in submodules():   # methodgen.derive, methodgen.schemes … as before the lazy import
            return importlib.import_module(f"{__name__}.{name}")
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(globals()) | set(lazy) | submodules())

    class Package(types.ModuleType):
        """Keeps ``methodgen.verify`` the function when the subpackage of that name is imported.

        Importing a subpackage binds it as an attribute of its parent; the eager
        ``from .verify import verify`` used to rebind the function right after.  With
        the lazy import the subpackage may be imported first (by a test or by the
        CLI): the function must still win, as before.
        """

        def __setattr__(self, name, value):
            if name == "verify" and isinstance(value, types.ModuleType):
                return
            super().__setattr__(name, value)

    sys.modules[__name__].__class__ = Package
    return __getattr__, __dir__


__getattr__, __dir__ = _lazy_names()
del _lazy_names


def methods() -> list[str]:
    """Names of all methods in the library."""
    from .schemes import method_names

    return method_names()


def scenes() -> list[str]:
    """Names of the built-in scenes."""
    from .scene import scene_names

    return scene_names()
