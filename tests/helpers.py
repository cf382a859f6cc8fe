"""Test helpers shared by several test files."""

from __future__ import annotations

import functools
import importlib.util
import tempfile
from pathlib import Path
from types import SimpleNamespace

from methodgen.emit import _environment
from methodgen.special import SPECIAL_FUNCTIONS


@functools.lru_cache(maxsize=None)
def special_helpers() -> dict:
    """The removable-singularity helpers exactly as templates/_special.py.j2 emits them."""
    names = tuple(sorted(v[1:] for v in SPECIAL_FUNCTIONS.values()))
    text = "import math\nimport numpy\n" + _environment().get_template("_special.py.j2").render(
        ir=SimpleNamespace(helpers=names))
    path = Path(tempfile.mkdtemp()) / "special_helpers.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("special_helpers", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return {k: getattr(mod, k) for k in dir(mod) if k.startswith(("_f_", "_v_"))}


def oracle_namespace() -> dict:
    """Numerical implementations keyed by the SymPy function names, for lambdify oracles."""
    helpers = special_helpers()
    return {cls.__name__: helpers["_v" + name] for cls, name in SPECIAL_FUNCTIONS.items()}
