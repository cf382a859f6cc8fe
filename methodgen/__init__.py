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
verify(scheme) -> Report                        (exact certificates of the method's claims)
load_scene(name_or_path) -> Scene
methods() / scenes()
"""

from ._version import __version__
from .errors import (GenerationError, InputError, MethodgenError, MethodNotApplicable,
                     ParseError, SceneError)
from .problem import Hamiltonian
from .poisson import PoissonSystem
from .schemes import Scheme, Traits, applicable_methods, discretize, method_names
from .build import build, generate
from .scene import Scene, load_scene, scene_names
from .timetransform import autonomise, time_transform
from .verify import verify

__all__ = [
    "__version__", "Hamiltonian", "PoissonSystem", "discretize", "generate", "build", "Scheme", "Traits",
    "load_scene", "Scene", "scene_names", "methods", "scenes", "applicable_methods", "verify",
    "MethodgenError", "InputError", "ParseError", "SceneError", "MethodNotApplicable",
    "GenerationError", "time_transform", "autonomise",
]


def methods() -> list[str]:
    """Names of all methods in the library."""
    return method_names()


def scenes() -> list[str]:
    """Names of the built-in scenes."""
    return scene_names()
