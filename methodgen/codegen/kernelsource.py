"""The exact text of the hand-written functions the LLVM translator compiles (never generated code).

:mod:`methodgen.codegen.llvmkernels` translates the runtime written in its subset of Python --
the stepper (:mod:`methodgen.runtime.stepper`), the Wisdom–Holman flows
(:mod:`methodgen.runtime.kepler_flow`), the lattice step loop, the scalar helpers
(:mod:`methodgen.codegen.special_helpers`) -- from their source files, and
:mod:`methodgen.codegen.llvmcache` keys their machine code by a digest of that text.  Generated
code is never among them: a generated kernel is compiled from its kernel IR
(:mod:`methodgen.codegen.kir`), which the module holds as data, and its text is never read back.

A function of a module methodgen's loader imported (:data:`GENERATED_ATTR`) is refused outright.
For any other function, the text must be the one that was *executed*, not whatever is on disk or
in :mod:`linecache` now (``inspect.getsource`` reads through ``linecache``, which keeps the first
text it read of a file for the life of the process: that once ran a regenerated module's
previous kernels).  Its file is read now and accepted only if compiling it reproduces the
function's code object (bytecode, constants, names); a file edited since the import fails that
check: :class:`StaleSource` is raised and the caller does not translate it.  Only methodgen's own
files are cacheable (:func:`cache_digest`).

References
----------
Python's ``inspect.findsource`` and ``linecache`` (the stale-text behaviour this replaces).
"""

from __future__ import annotations

import ast
import hashlib
import os
import threading
import types

__all__ = ["GENERATED_ATTR", "StaleSource", "source_of", "function_def", "cache_digest"]

#: the name under which methodgen's loader marks a generated module's namespace: its functions'
#: text is never translated (their kernel IR is)
GENERATED_ATTR = "__methodgen_generated__"

#: methodgen's own folder (all its layers): its files' machine code may be cached
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
_LOCK = threading.Lock()
#: sha256 -> parsed module (the last few: a kernel's definition is kept in _DEFS)
_TREES: dict = {}
#: sha256 -> compiled module code (to verify a file against a function's code object)
_CODES: dict = {}
#: id(code) -> (code, text, sha256, in_package): a verified file, kept with its code object so
#: the id cannot be reused while the entry lives
_VERIFIED: dict = {}


def _remember(store: dict, key, value, keep: int):
    """``store[key] = value``, dropping the oldest entries past ``keep`` (a regenerating
    process -- a sweep, a bench -- must not keep every module's parse tree: ~70x its text)."""
    with _LOCK:
        store.pop(key, None)
        store[key] = value
        while len(store) > keep:
            del store[next(iter(store))]
    return value


class StaleSource(Exception):
    """No text that reproduces the function's code may be translated: the file changed since
    import, there is no file, or the function is generated code (compiled from its kernel IR)."""


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _same_code(a: types.CodeType, b: types.CodeType) -> bool:
    """Whether two code objects are the same compilation (bytecode, constants -- nested code
    compared recursively -- and names)."""
    if (a.co_code != b.co_code or a.co_names != b.co_names or a.co_varnames != b.co_varnames
            or a.co_name != b.co_name or len(a.co_consts) != len(b.co_consts)):
        return False
    return all(_same_const(x, y) for x, y in zip(a.co_consts, b.co_consts))


def _same_const(x, y) -> bool:
    """Constants equal in value and in type (1 == 1.0 == True) and bits (0.0 == -0.0)."""
    if type(x) is not type(y):
        return False
    if isinstance(x, types.CodeType):
        return _same_code(x, y)
    if isinstance(x, tuple):
        return len(x) == len(y) and all(_same_const(u, v) for u, v in zip(x, y))
    if isinstance(x, frozenset):
        return x == y
    return repr(x) == repr(y)


def _find_code(module_code: types.CodeType, name: str, firstlineno: int):
    stack = [module_code]
    while stack:
        c = stack.pop()
        for k in c.co_consts:
            if isinstance(k, types.CodeType):
                if k.co_name == name and k.co_firstlineno == firstlineno:
                    return k
                stack.append(k)
    return None


def _verified_file(code: types.CodeType):
    """(text, sha256, in_package) of ``code``'s file, read now, if it reproduces ``code``."""
    with _LOCK:
        got = _VERIFIED.get(id(code))
    if got is not None and got[0] is code:
        return got[1:]
    filename = code.co_filename
    try:
        with open(filename, "rb") as f:
            raw = f.read()
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StaleSource(f"{filename}: cannot read the source ({exc})") from None
    sha = _sha(text)
    with _LOCK:
        module_code = _CODES.get((sha, filename))
    if module_code is None:
        try:
            module_code = compile(text, filename, "exec", dont_inherit=True)
        except SyntaxError as exc:
            raise StaleSource(f"{filename}: the file no longer compiles ({exc})") from None
        _remember(_CODES, (sha, filename), module_code, 8)
    found = _find_code(module_code, code.co_name, code.co_firstlineno)
    if found is None or not _same_code(found, code):
        raise StaleSource(f"{filename}: the file has changed since {code.co_name} was imported")
    entry = (code, text, sha, os.path.abspath(filename).startswith(_PACKAGE))
    _remember(_VERIFIED, id(code), entry, 256)
    return entry[1:]


def _unwrap(fn):
    py = getattr(fn, "py_func", fn)
    code = getattr(py, "__code__", None)
    if code is None:
        raise StaleSource(f"{fn!r} has no Python code")
    return py, code


def source_of(fn) -> tuple[str, str, bool]:
    """The text ``fn`` was compiled from: ``(text, sha256, cacheable)``.

    Parameters
    ----------
    fn : function, or an object holding one as ``py_func`` (an LLVM kernel), not of a generated module

    Returns
    -------
    text : str
        The whole file's text (the function, its helpers and its tables).
    sha256 : str
        Hex SHA-256 of ``text`` (UTF-8).
    cacheable : bool
        Whether machine code translated from it may be stored and loaded by this digest: True
        for methodgen's own files.

    Raises
    ------
    StaleSource
        The function is generated code (its module was imported by methodgen's loader: it is
        compiled from its kernel IR, never from its text), or no text reproduces it (see the
        module docstring).
    """
    py, code = _unwrap(fn)
    if (getattr(py, "__globals__", None) or {}).get(GENERATED_ATTR):
        raise StaleSource(f"{code.co_name} is generated code: compiled from its kernel IR, never from its text")
    return _verified_file(code)


def cache_digest(fn) -> str | None:
    """The digest naming ``fn``'s machine code in a cache key (``sha256:name:line``), or None
    when it must not be cached (:func:`source_of`)."""
    try:
        text, sha, cacheable = source_of(fn)
    except StaleSource:
        return None
    if not cacheable:
        return None
    _, code = _unwrap(fn)
    return f"{sha}:{code.co_name}:{code.co_firstlineno}"


def function_def(fn) -> ast.FunctionDef:
    """The definition of ``fn`` in the text it was compiled from.

    Shared and read-only (the translator only reads it): one parse of a module's text serves
    all its kernels, where a copy per call cost a tenth of a second of a large module's first
    use.

    Raises
    ------
    StaleSource
        See :func:`source_of`.
    """
    text, sha, _ = source_of(fn)
    _, code = _unwrap(fn)
    key = (sha, code.co_name, code.co_firstlineno)
    with _LOCK:
        got = _DEFS.get(key)
    if got is not None:
        return got
    with _LOCK:
        tree = _TREES.get(sha)
    if tree is None:
        tree = _remember(_TREES, sha, ast.parse(text), 4)
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == code.co_name:
            first = min([node.lineno] + [d.lineno for d in node.decorator_list])
            if code.co_firstlineno in (node.lineno, first):
                return _remember(_DEFS, key, node, 1024)
    raise StaleSource(f"no definition of {code.co_name} at line {code.co_firstlineno} in its source")


#: (sha256, name, first line) -> the function's definition in that text
_DEFS: dict = {}
