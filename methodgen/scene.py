"""Scene files: one problem plus what the user wants done with it (TOML).

Format (see DESIGN.md §3 and the built-in scenes in ``methodgen/scenes``)::

    name = "kepler"
    description = "..."
    [system]
    H = "..."; q = [...]; p = [...]; constraints = []
    [params]
    m = 1.0
    [run]
    method = "energy-momentum"   # or a list
    h = 0.01
    steps = 10000
    y0 = [...]                   # q then p

A scene file is data: it is parsed with ``tomllib`` and validated key by key;
unknown keys and wrong types are errors that name the key and what is valid.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from .errors import InputError, SceneError
from .problem import Hamiltonian

__all__ = ["Scene", "load_scene", "scene_names", "builtin_scene_dir"]

_TOP = {"name": str, "description": str, "system": dict, "params": dict, "run": dict}
_SYSTEM = {"H": str, "q": list, "p": list, "constraints": list}
_RUN = {"method": (str, list), "h": (int, float), "steps": int, "y0": list}


def builtin_scene_dir() -> Path:
    return Path(__file__).resolve().parent / "scenes"


def scene_names() -> list[str]:
    """Names of the built-in scenes, sorted."""
    return sorted(p.stem for p in builtin_scene_dir().glob("*.toml"))


@dataclass(frozen=True)
class Scene:
    """A validated scene.

    Attributes
    ----------
    name, description : str
    system : Hamiltonian
    methods : tuple of str
        The scene's method(s); the first is the default.
    h : float
    steps : int
    y0 : tuple of float, length 2d
    path : Path or None
    builtin : bool
    """

    name: str
    description: str
    system: Hamiltonian
    methods: tuple[str, ...]
    h: float
    steps: int
    y0: tuple[float, ...]
    path: Path | None = None
    builtin: bool = False

    @property
    def method(self) -> str:
        return self.methods[0]


def _check_keys(table: dict, allowed: dict, where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise SceneError(f"unknown key(s) {unknown} in {where}; valid keys are {sorted(allowed)}")
    for key, typ in allowed.items():
        if key in table:
            value = table[key]
            if isinstance(value, bool) or not isinstance(value, typ):
                want = typ.__name__ if isinstance(typ, type) else " or ".join(t.__name__ for t in typ)
                raise SceneError(f"{where}.{key} must be a {want}, got {type(value).__name__} {value!r}")


def _require(table: dict, key: str, where: str):
    if key not in table:
        raise SceneError(f"missing key {key!r} in {where}")
    return table[key]


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{where} must be finite, got {value!r}")
    return value


def parse_scene(data: dict, source: str, path: Path | None = None, builtin: bool = False) -> Scene:
    """Validate a parsed TOML document and build the :class:`Scene`."""
    _check_keys(data, _TOP, "the scene")
    name = _require(data, "name", "the scene")
    system_t = _require(data, "system", "the scene")
    _check_keys(system_t, _SYSTEM, "[system]")
    params_t = data.get("params", {})
    for k, v in params_t.items():
        _number(v, f"[params].{k}")
    run_t = data.get("run", {})
    _check_keys(run_t, _RUN, "[run]")
    for key in ("q", "p", "constraints"):
        for item in system_t.get(key, []):
            if not isinstance(item, str):
                raise SceneError(f"[system].{key} must be a list of strings, got item {item!r}")
    try:
        system = Hamiltonian(_require(system_t, "H", "[system]"), q=_require(system_t, "q", "[system]"),
                             p=_require(system_t, "p", "[system]"), params=params_t,
                             constraints=system_t.get("constraints", []), name=name)
    except SceneError:
        raise
    except InputError as exc:
        raise SceneError(f"{source}: {exc}") from None
    methods = _require(run_t, "method", "[run]")
    methods = (methods,) if isinstance(methods, str) else tuple(methods)
    if not methods or not all(isinstance(m, str) for m in methods):
        raise SceneError("[run].method must be a method name or a non-empty list of names")
    h = _number(_require(run_t, "h", "[run]"), "[run].h")
    if h == 0:
        raise SceneError("[run].h must be non-zero")
    steps = _require(run_t, "steps", "[run]")
    if steps < 0:
        raise SceneError(f"[run].steps must be >= 0, got {steps}")
    y0 = tuple(_number(v, f"[run].y0[{i}]") for i, v in enumerate(_require(run_t, "y0", "[run]")))
    if len(y0) != 2 * system.dim:
        raise SceneError(f"[run].y0 has {len(y0)} values but the state ({', '.join(system.state_names)}) "
                         f"has {2 * system.dim}")
    return Scene(name=name, description=data.get("description", ""), system=system, methods=methods,
                 h=h, steps=steps, y0=y0, path=path, builtin=builtin)


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a built-in scene by name, or a scene file by path.

    Raises
    ------
    SceneError
        Unknown scene, unreadable file, TOML syntax error, or invalid content.
    """
    text_name = str(name_or_path)
    builtin = builtin_scene_dir() / f"{text_name}.toml"
    if "/" not in text_name and not text_name.endswith(".toml") and builtin.is_file():
        path, is_builtin = builtin, True
    else:
        path, is_builtin = Path(name_or_path), False
        if not path.is_file():
            raise SceneError(f"no built-in scene or file named {text_name!r}; built-in scenes: "
                             f"{', '.join(scene_names())}")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene {path}: {exc}") from None
    scene = parse_scene(data, str(path), path, is_builtin)
    if is_builtin and scene.name != text_name:
        raise SceneError(f"built-in scene file {path} declares name {scene.name!r}")
    return scene
