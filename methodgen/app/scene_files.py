"""Scene files of the families of symbolic size (lattices, particles): where the built-in ones are,
which kind a file is, reading one and checking its tables' keys.

A family scene is a TOML file with a table named after its kind (``[lattice]``, ``[particles]``);
the built-in ones are in ``methodgen/symbolic/scenes/<kind>/``.  The file is data: read with
``tomllib`` and checked key by key here; its formulas are parsed by the kinds' own modules with the
whitelist parser (:func:`methodgen.problem.parse.parse_expr`).
"""

from __future__ import annotations

import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from ..errors import SceneError

__all__ = ["folder", "names", "path_of", "is_kind", "read", "check_keys"]


def folder(kind: str) -> Path:
    """The folder of the built-in scenes of ``kind``."""
    from ..symbolic.scene import builtin_scene_dir

    return builtin_scene_dir() / kind


def names(kind: str) -> list[str]:
    """Names of the built-in scenes of ``kind``, sorted."""
    return sorted(p.stem for p in folder(kind).glob("*.toml"))


def path_of(kind: str, name_or_path) -> Path | None:
    """The file of a ``.toml`` path or of a built-in scene's name of ``kind``; None for neither."""
    p = Path(name_or_path)
    if p.suffix == ".toml" and p.is_file():
        return p
    if str(name_or_path) in names(kind):
        return folder(kind) / f"{name_or_path}.toml"
    return None


def is_kind(kind: str, name_or_path) -> bool:
    """True for a built-in scene's name of ``kind`` or a TOML file with a ``[kind]`` table."""
    p = path_of(kind, name_or_path)
    if p is None:
        return False
    try:
        with open(p, "rb") as fh:
            return kind in tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError):
        return False      # the loader reports what is wrong with the file


def read(kind: str, name_or_path, top: dict, what: str) -> tuple[dict, Path]:
    """``(data, path)``: the scene's tables, checked against ``top`` (key → type) with the tables
    ``[kind]`` and ``[run]`` present, and the file they were read from.

    Raises
    ------
    SceneError
        No such scene (naming the built-in ones of ``kind``, called ``what``), an unreadable file,
        invalid TOML, an unknown or mistyped key, a missing table.
    """
    p = path_of(kind, name_or_path)
    if p is None:
        raise SceneError(f"no {what} scene {name_or_path!r}; built-in: {', '.join(names(kind))}")
    try:
        with open(p, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise SceneError(f"cannot read {p}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{p}: not valid TOML: {exc}") from None
    where = str(p)
    check_keys(data, top, where)
    for t in (kind, "run"):
        if t not in data:
            raise SceneError(f"{where}: the [{t}] table is missing")
    return data, p


def check_keys(table: dict, allowed: dict, where: str) -> None:
    """Every key of ``table`` is one of ``allowed`` and of its type (``allowed[k]``: a type or a tuple
    of types); a bool is accepted only where ``allowed`` says ``bool`` (TOML's true is not a 1)."""
    for k, v in table.items():
        if k not in allowed:
            raise SceneError(f"{where}: unknown key {k!r}; valid keys are {', '.join(allowed)}")
        if allowed[k] is bool:
            if not isinstance(v, bool):
                raise SceneError(f"{where}: {k!r} must be true or false, got {v!r}")
        elif not isinstance(v, allowed[k]) or isinstance(v, bool):
            kinds = allowed[k] if isinstance(allowed[k], tuple) else (allowed[k],)
            raise SceneError(f"{where}: {k!r} must be {' or '.join(t.__name__ for t in kinds)}, got {v!r}")


def run_orders(order, methods, offered, where: str, what: str) -> dict:
    """A family scene's ``[run] order`` -- one number for every method, or a table per method -- as
    ``{method: order}`` (2 where a table leaves a method out), checked: a method the scene does not
    run, or an order not in ``offered``, is refused (SceneError) naming what is valid (``what``:
    who is composed, for the message)."""
    given = order if isinstance(order, dict) else {m: order for m in methods}
    for m, k in given.items():
        if m not in methods:
            raise SceneError(f"{where} [run]: order of {m!r}, a method the scene does not run; its methods are "
                             f"{', '.join(methods)}")
        if isinstance(k, bool) or k not in offered:
            raise SceneError(f"{where} [run]: order {k!r} for {m}: {what} composed to order "
                             f"{', '.join(map(str, offered))}")
    return {m: given.get(m, 2) for m in methods}
