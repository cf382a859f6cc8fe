"""methodgen: geometric integrators generated from your Hamiltonian.

Pipeline (data flows one way, and so do the imports: each layer imports only the layers
before it; tests/test_import_graph.py checks it)::

    problem/   scene text -> Hamiltonian, PoissonSystem (parse, special functions)
    symbolic/  derive -> discretize (Scheme) -> verify; compositions, splittings, scenes
    codegen/   lower (IR) -> emit (templates) -> generated/*.py; kernels to machine code
    runtime/   the stepper the generated modules run on; trajectories on disk
    app/       the command line, bench, sweep, figures

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
Particles(H, q=[...], p=[...], size="N", arrays=["m"], params=None)   (one-body and pair sums of symbolic N)
build_particles(fam, "stormer-verlet" | "energy-momentum", order=2, backend="numpy") -> module  (every N)
verify_particles(fam, method, order=2) -> list of Certificate      (exact, per template: every N)
wisdom_holman(scene, "sbab4") -> WisdomHolman  (Wisdom–Holman splittings of [nbody] scenes)
methods() / scenes()

``import methodgen`` imports numpy but not SymPy: the names that need SymPy
(Hamiltonian, discretize, verify, load_scene …) are imported on first use
(PEP 562), so loading a cached module through :func:`build_text` stays light.
"""

from ._version import __version__
from .codegen.build import build, build_text, generate
from .errors import (GenerationError, InputError, MethodgenError, MethodNotApplicable,
                     ParseError, SceneError)

__all__ = [
    "__version__", "Hamiltonian", "PoissonSystem", "discretize", "generate", "build", "build_text",
    "Scheme", "Traits", "load_scene", "Scene", "scene_names", "methods", "scenes", "applicable_methods",
    "verify", "MethodgenError", "InputError", "ParseError", "SceneError", "MethodNotApplicable",
    "GenerationError", "time_transform", "autonomise", "wisdom_holman", "cite", "event", "section_event",
    "poincare", "save_trajectory", "read_trajectory", "Lattice", "build_lattice", "load_lattice_scene",
    "Particles", "build_particles", "verify_particles",
]


def _lazy_names():
    """``__getattr__`` and ``__dir__`` of the package (PEP 562); its helpers stay out of the namespace."""
    import importlib

    # Public names imported on first use (they import SymPy and the derivation code).
    lazy = {
        "Hamiltonian": ".problem.problem", "PoissonSystem": ".problem.poisson",
        "Scheme": ".symbolic.schemes", "Traits": ".symbolic.schemes", "applicable_methods": ".symbolic.schemes",
        "discretize": ".symbolic.schemes", "method_names": ".symbolic.schemes",
        "Scene": ".symbolic.scene", "load_scene": ".symbolic.scene", "scene_names": ".symbolic.scene",
        "autonomise": ".symbolic.timetransform", "time_transform": ".symbolic.timetransform",
        "verify": ".symbolic.verify", "wisdom_holman": ".runtime.nbody", "cite": ".app.cite",
        "event": ".runtime.events", "section_event": ".runtime.events", "poincare": ".runtime.events",
        "save_trajectory": ".runtime.trajfile", "read_trajectory": ".runtime.trajfile",
        "Lattice": ".problem.lattice", "build_lattice": ".codegen.lattice_emit",
        "load_lattice_scene": ".app.lattice_scene",
        "Particles": ".problem.particles", "build_particles": ".codegen.particle_emit",
        "verify_particles": ".symbolic.particle_scheme",
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
        if name in submodules():   # methodgen.problem, methodgen.symbolic … (the layers)
            return importlib.import_module(f"{__name__}.{name}")
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(globals()) | set(lazy) | submodules())

    return __getattr__, __dir__


__getattr__, __dir__ = _lazy_names()
del _lazy_names


def methods() -> list[str]:
    """Names of all methods in the library."""
    from .symbolic.schemes import method_names

    return method_names()


def scenes() -> list[str]:
    """Names of the built-in scenes."""
    from .symbolic.scene import scene_names

    return scene_names()
