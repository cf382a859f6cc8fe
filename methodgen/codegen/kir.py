"""The kernel IR: a generated kernel as plain data, and the two printers that read it.

Lowering (:mod:`methodgen.codegen.lower`) turns each CSE'd SymPy expression into an
**expression tree of tuples** -- the single product both executions are printed from:

* :func:`python` prints it as Python source (the kernels of the generated modules, on floats
  with :mod:`math`), and
* :func:`to_ast` builds the same tree as :mod:`ast` nodes for the LLVM translator
  (:mod:`methodgen.codegen.llvmkernels`), which emits the machine code with llvmlite's builder.

No generated text is parsed back: the compiled route reads the tree, and its machine code is
keyed by :func:`digest` of the tree (with the printer's :data:`VERSION`), so a kernel asked for
by one tree is never served another's code.

Nodes (every node a tuple; equal trees are equal tuples, so they hash and compare as data):

=====================  ==============================================================
``("n", v)``           a number: ``v`` an ``int`` or ``float``, never negative
``("v", name)``        a variable (or ``math.pi``, ``math.e``, ``numpy.pi``, ``numpy.e``)
``("neg", a)``         ``-a``
``("+", a, b)``        ``a + b``; likewise ``"-"``, ``"*"``, ``"/"`` and ``"**"``
``("call", f, args)``  ``f(*args)``: ``f`` one of :data:`FUNCTIONS` or a removable-singularity
                       helper ``_f_<name>`` (``_v_<name>`` on arrays; :mod:`methodgen.problem.special`)
=====================  ==============================================================

The tree is the evaluation order, operation for operation: building it from a SymPy expression
(:func:`methodgen.codegen.kir_build.from_sympy`) makes exactly the tree Python makes of SymPy's code printer's text for the
same expression (the printer classes of :mod:`methodgen.codegen.lower`: ``"scalar"`` and the
``"check"`` flavour, which writes small powers as products), so the rounding of every generated
kernel is the one it always had.  Parentheses are not data: :func:`python` writes the fewest that
give back the same tree (and keeps a constant fraction such as ``(1/2)`` in parentheses, for the
reader).

References
----------
SymPy's code printers (``sympy.printing.codeprinter.CodePrinter._print_Mul``,
``sympy.printing.str.StrPrinter._print_Add``, ``sympy.printing.pycode``), whose trees
:func:`from_sympy` reproduces; heyoka's expression graph and ``sympy.printing.llvmjitcode``,
which print machine code from a tree rather than from text.
"""

from __future__ import annotations

import ast
import hashlib

__all__ = ["VERSION", "FUNCTIONS", "Unsupported", "Code", "python", "to_ast", "digest", "called",
           "read_names", "tree_of", "attach", "KIR_ATTR", "function", "table_const", "function_lines", "function_def", "flatten", "unflatten",
           "table_text"]

#: the IR's and its printers' version: part of every machine-code key (a change of the
#: printers' meaning must not load code printed by the old ones)
VERSION = "kir-1"

#: functions a tree may call (besides the ``_f_`` / ``_v_`` helpers): SymPy's names for them in
#: Python, on floats (math) and on arrays (numpy: the numpy modules' batch kernels, never compiled)
FUNCTIONS = frozenset({"abs", "min", "max", "math.acos", "math.acosh", "math.asin", "math.asinh", "math.atan",
                       "math.atan2", "math.atanh", "math.cos", "math.cosh", "math.erf", "math.erfc", "math.exp",
                       "math.expm1", "math.hypot", "math.log", "math.log10", "math.log1p", "math.log2",
                       "math.sin", "math.sinh", "math.sqrt", "math.tan", "math.tanh",
                       "numpy.arccos", "numpy.arccosh", "numpy.arcsin", "numpy.arcsinh", "numpy.arctan",
                       "numpy.arctan2", "numpy.arctanh", "numpy.cos", "numpy.cosh", "numpy.exp", "numpy.expm1",
                       "numpy.hypot", "numpy.log", "numpy.log10", "numpy.log1p", "numpy.log2", "numpy.sin",
                       "numpy.sinh", "numpy.sqrt", "numpy.tan", "numpy.tanh", "numpy.maximum"})

_BINARY = {"+": ast.Add, "-": ast.Sub, "*": ast.Mult, "/": ast.Div, "**": ast.Pow}
#: Python's binding power of each node (higher binds tighter); ``**`` binds tighter than a
#: unary minus on its left (``-x**2`` is ``-(x**2)``)
_BIND = {"+": 1, "-": 1, "*": 2, "/": 2, "neg": 3, "**": 4}
_ATOM = 9


class Unsupported(Exception):
    """Something the IR has no node for (a relational, a Piecewise …): the caller keeps SymPy's
    text for it, and the kernel its text route."""


# --- printing: the tree -> Python text, or -> ast nodes ----------------------------------------

#: binding power of the integer, comparison and logical nodes (loops and checks of kernels)
_BIND.update({"//": 2, "%": 2, ">>": 0.7, "&": 0.5, "==": 0, "!=": 0, "<": 0, "<=": 0, ">": 0, ">=": 0, "not": -1})
_INT_BINARY = {"//": ast.FloorDiv, "%": ast.Mod, ">>": ast.RShift, "&": ast.BitAnd}
_COMPARE = {"==": ast.Eq, "!=": ast.NotEq, "<": ast.Lt, "<=": ast.LtE, ">": ast.Gt, ">=": ast.GtE}


def _bind(node) -> int:
    return _BIND.get(node[0], _ATOM)


def _is_fraction(node) -> bool:
    return node[0] == "/" and node[1][0] == "n" and node[2][0] == "n"


def _index_text(idx) -> str:
    parts = []
    for i in idx:
        if i[0] == "slice":
            parts.append(f"{'' if i[1] is None else python(i[1])}:{'' if i[2] is None else python(i[2])}")
        else:
            parts.append(python(i))
    return ", ".join(parts)


def python(node) -> str:
    """Python source of an expression tree: the fewest parentheses that give back the same
    tree (``ast.parse(python(t))`` is ``to_ast(t)``), a constant fraction in a product kept in
    parentheses for the reader."""
    op = node[0]
    if op == "n":
        v = node[1]
        return repr(v) if isinstance(v, float) else str(int(v))
    if op == "v":
        return node[1]
    if op == "call":
        return f"{node[1]}({', '.join(python(a) for a in node[2])})"
    if op == "[]":
        return f"{node[1]}[{_index_text(node[2])}]"
    if op == "buffer":
        return f"stack_array({_shape_text(node[1])})"
    if op in ("zeros", "empty"):
        return f"numpy.{op}({_shape_text(node[1])})"
    if op in ("neg", "not"):
        a = node[1]
        text = python(a)
        if op == "not":
            return f"not ({text})" if _bind(a) <= _BIND["not"] or a[0] in _COMPARE else f"not {text}"
        return f"-({text})" if _bind(a) < _BIND["neg"] else f"-{text}"
    left, right = node[1], node[2]
    mine = _BIND[op]
    lt, rt = python(left), python(right)
    if op == "**":
        # right-associative, and tighter than a unary minus on its left
        if _bind(left) <= mine:
            lt = f"({lt})"
        if _bind(right) < mine and right[0] != "neg":
            rt = f"({rt})"
    elif op in _COMPARE:
        # (comparisons are not chained here: both sides are arithmetic)
        if _bind(left) <= mine:
            lt = f"({lt})"
        if _bind(right) <= mine:
            rt = f"({rt})"
    else:
        if _bind(left) < mine or (op == "*" and _is_fraction(left)):
            lt = f"({lt})"
        if _bind(right) <= mine or (op == "*" and _is_fraction(right)):
            rt = f"({rt})"
    return f"{lt}{op}{rt}" if op in ("*", "/", "**") else f"{lt} {op} {rt}"


def _shape_text(shape) -> str:
    return f"({shape[0]},)" if len(shape) == 1 else "(" + ", ".join(map(str, shape)) + ")"


def _name(text: str, ctx) -> ast.expr:
    head, _, attr = text.rpartition(".")
    if head:
        return ast.Attribute(_name(head, ast.Load()), attr, ctx)
    return ast.Name(attr, ctx)


def _index_ast(idx) -> ast.expr:
    items = [ast.Slice(None if i[1] is None else to_ast(i[1]), None if i[2] is None else to_ast(i[2]))
             if i[0] == "slice" else to_ast(i) for i in idx]
    return items[0] if len(items) == 1 else ast.Tuple(items, ast.Load())


def _shape_ast(shape) -> ast.expr:
    return ast.Tuple([ast.Constant(k) for k in shape], ast.Load())


def to_ast(node, ctx=None) -> ast.expr:
    """The tree as :mod:`ast` nodes (built, not parsed): what Python makes of :func:`python`'s
    text, for the LLVM translator.  ``ctx``: ``ast.Store()`` for an assignment's target."""
    op = node[0]
    if op == "n":
        return ast.Constant(node[1])
    if op == "v":
        return _name(node[1], ctx or ast.Load())        # (math.pi, math.e: attributes)
    if op == "neg":
        return ast.UnaryOp(ast.USub(), to_ast(node[1]))
    if op == "not":
        return ast.UnaryOp(ast.Not(), to_ast(node[1]))
    if op == "call":
        return ast.Call(_name(node[1], ast.Load()), [to_ast(a) for a in node[2]], [])
    if op == "[]":
        return ast.Subscript(ast.Name(node[1], ast.Load()), _index_ast(node[2]), ctx or ast.Load())
    if op == "buffer":
        return ast.Call(_name("stack_array", ast.Load()), [_shape_ast(node[1])], [])
    if op in ("zeros", "empty"):
        return ast.Call(_name("numpy." + op, ast.Load()), [_shape_ast(node[1])], [])
    if op in _COMPARE:
        return ast.Compare(to_ast(node[1]), [_COMPARE[op]()], [to_ast(node[2])])
    cls = _BINARY.get(op) or _INT_BINARY[op]
    return ast.BinOp(to_ast(node[1]), cls(), to_ast(node[2]))


# --- kernels: statements and functions ---------------------------------------------------------
#
# Statements (tuples too):
#   ("=", target, e)            target ("v", name) or ("[]", array, index)
#   ("+=", target, e), ("-=", target, e)
#   ("for", var, start, stop, body)   for var in range(start, stop), body a tuple of statements
#   ("forin", var, values, body)      for var in (v0, v1, …): a constant tuple of ints (unrolled)
#   ("if", cond, body, orelse)
#   ("expr", e)                 a call for its effect (an inlined kernel writing into arrays)
#   ("return", e)
#   ("#", text)                 a comment (printed; not executed)
# A function: ("def", name, params, body, consts).  Index entries may be ("slice", lo, hi)
# (None: open).  ``consts``: the module-level names the body reads, with their values -- part of
# the tree (and of its digest), so its machine code depends on nothing else: ``(name, value)``
# with value an int, a float, or a table ``("array", kind, shape, values)`` (kind "f" float64,
# "i" int64, values flat in C order).


def function(name: str, params, body, consts=()) -> tuple:
    """A kernel function: ``("def", name, params, body, consts)`` (lists in ``body`` become tuples;
    ``consts`` sorted by name)."""
    return ("def", name, tuple(params), _freeze(body), tuple(sorted(_freeze(consts))))


def table_const(name: str, values, kind: str = "f") -> tuple:
    """A constant table of a kernel (``consts`` of :func:`function`) from nested sequences of
    numbers: ``(name, ("array", kind, shape, flat values))``, floats or ints by ``kind``."""
    shape, flat, level = [], [], [values]
    while isinstance(level[0], (tuple, list)):
        shape.append(len(level[0]))
        level = [x for row in level for x in row]
    cast = float if kind == "f" else int
    flat = tuple(cast(x) for x in level)
    return (name, ("array", kind, tuple(shape), flat))


def _freeze(x):
    return tuple(_freeze(v) for v in x) if isinstance(x, (list, tuple)) else x


def function_lines(fn, indent: str = "") -> list[str]:
    """The Python source lines of a kernel function (without decorators; its constants are the
    module's own names)."""
    _, name, params, body, _ = fn
    lines = [f"{indent}def {name}({', '.join(params)}):"]
    _block(body, indent + "    ", lines)
    return lines


def _target_text(t) -> str:
    return python(t)


def _block(body, indent: str, lines: list) -> None:
    if not body:
        lines.append(indent + "pass")
    for st in body:
        op = st[0]
        if op == "=":
            lines.append(f"{indent}{_target_text(st[1])} = {python(st[2])}")
        elif op in ("+=", "-="):
            lines.append(f"{indent}{_target_text(st[1])} {op} {python(st[2])}")
        elif op == "for":
            bounds = python(st[3]) if st[2] == ("n", 0) else f"{python(st[2])}, {python(st[3])}"
            lines.append(f"{indent}for {st[1]} in range({bounds}):")
            _block(st[4], indent + "    ", lines)
        elif op == "forin":
            lines.append(f"{indent}for {st[1]} in ({', '.join(map(str, st[2]))},):")
            _block(st[3], indent + "    ", lines)
        elif op == "if":
            lines.append(f"{indent}if {python(st[1])}:")
            _block(st[2], indent + "    ", lines)
            if st[3]:
                lines.append(f"{indent}else:")
                _block(st[3], indent + "    ", lines)
        elif op == "expr":
            lines.append(indent + python(st[1]))
        elif op == "return":
            lines.append(f"{indent}return {python(st[1])}")
        elif op == "#":
            lines.append(f"{indent}# {st[1]}")
        else:
            raise ValueError(f"not a statement of the kernel IR: {op!r}")


def _statements_ast(body) -> list:
    out = []
    for st in body:
        op = st[0]
        if op == "=":
            out.append(ast.Assign([to_ast(st[1], ast.Store())], to_ast(st[2])))
        elif op in ("+=", "-="):
            out.append(ast.AugAssign(to_ast(st[1], ast.Store()), ast.Add() if op == "+=" else ast.Sub(),
                                     to_ast(st[2])))
        elif op == "for":
            bounds = [to_ast(st[3])] if st[2] == ("n", 0) else [to_ast(st[2]), to_ast(st[3])]
            it = ast.Call(ast.Name("range", ast.Load()), bounds, [])
            out.append(ast.For(ast.Name(st[1], ast.Store()), it, _statements_ast(st[4]) or [ast.Pass()], []))
        elif op == "forin":
            it = ast.Tuple([ast.Constant(int(v)) for v in st[2]], ast.Load())
            out.append(ast.For(ast.Name(st[1], ast.Store()), it, _statements_ast(st[3]) or [ast.Pass()], []))
        elif op == "if":
            out.append(ast.If(to_ast(st[1]), _statements_ast(st[2]) or [ast.Pass()], _statements_ast(st[3])))
        elif op == "expr":
            out.append(ast.Expr(to_ast(st[1])))
        elif op == "return":
            out.append(ast.Return(to_ast(st[1])))
        elif op != "#":
            raise ValueError(f"not a statement of the kernel IR: {op!r}")
    return out


def function_def(fn) -> ast.FunctionDef:
    """The kernel function as an :class:`ast.FunctionDef` (built from the tree, never parsed):
    what the LLVM translator reads."""
    _, name, params, body, _ = fn
    args = ast.arguments(posonlyargs=[], args=[ast.arg(p) for p in params], vararg=None, kwonlyargs=[],
                         kw_defaults=[], kwarg=None, defaults=[])
    fdef = ast.FunctionDef(name=name, args=args, body=_statements_ast(body) or [ast.Pass()], decorator_list=[],
                           returns=None, type_comment=None)
    if "type_params" in ast.FunctionDef._fields:       # Python 3.12
        fdef.type_params = []
    mod = ast.fix_missing_locations(ast.Module([fdef], type_ignores=[]))
    return mod.body[0]


# --- data: a table of nodes (no nesting), and its digest ----------------------------------------
#
# A tree is written into a module as a flat table: each entry a node whose child nodes are
# replaced by the indices of earlier entries (equal subtrees share one), so that no literal nests
# deeper than a node (Python's parser limits nesting) and shared loads and subexpressions are
# written once.  The field kinds of each node: "N" a node, "*" a tuple of nodes, "o" a node or
# None, anything else a literal kept as it is.

_FIELDS = {"n": "L", "v": "L", "neg": "N", "not": "N", "call": "L*", "[]": "L*", "slice": "oo", "buffer": "L",
           "zeros": "L", "empty": "L", "=": "NN", "+=": "NN", "-=": "NN", "for": "LNN*", "forin": "LL*", "if": "N**",
           "expr": "N", "return": "N", "#": "L", "def": "LL*L"}
for _op in ("+", "-", "*", "/", "**", "//", "%", ">>", "&", "==", "!=", "<", "<=", ">", ">="):
    _FIELDS[_op] = "NN"


def _map_fields(node: tuple, f) -> tuple:
    """``node`` with ``f`` applied to each of its child-node fields (by :data:`_FIELDS`), literals
    kept: children to indices in :func:`flatten`, indices to children in :func:`unflatten`."""
    out = []
    for kind, value in zip(_FIELDS[node[0]], node[1:]):
        if kind == "N":
            out.append(f(value))
        elif kind == "*":
            out.append(tuple(f(v) for v in value))
        elif kind == "o":
            out.append(None if value is None else f(value))
        else:
            out.append(value)
    return (node[0],) + tuple(out)


def flatten(roots) -> tuple[tuple, tuple]:
    """``(table, indices)``: the nodes of the trees ``roots`` as a flat table (children by index,
    shared subtrees once, children before parents) and the index of each root."""
    table, memo = [], {}

    def put(node):
        kinds = _FIELDS.get(node[0])
        if kinds is None or len(kinds) != len(node) - 1:
            raise ValueError(f"not a node of the kernel IR: {node[:1]!r}")
        entry = _map_fields(node, put)
        # keyed by the entry's text (shallow: children are indices), which keeps 0, 0.0 and -0.0
        # apart -- equal as Python values, so they would share an entry -- in constants too
        key = repr(entry)
        got = memo.get(key)
        if got is None:
            got = memo[key] = len(table)
            table.append(entry)
        return got

    indices = tuple(put(r) for r in roots)
    return tuple(table), indices


def unflatten(table, index: int) -> tuple:
    """The tree at ``table[index]`` (:func:`flatten`'s inverse; children precede parents)."""
    built: list = []
    for i in range(index + 1):
        built.append(_map_fields(table[i], built.__getitem__))
    return built[index]


def digest(tree) -> str:
    """SHA-256 (hex) of a tree (an expression, a kernel function, any node) with
    :data:`VERSION`: the name of the machine code printed from it.  Hashed through its flat
    table (:func:`flatten`: canonical, children first), whose ``repr`` -- tuples of str, int and
    float, floats by their shortest round-trip digits -- is exact and deterministic."""
    table, _ = flatten([tree])
    return hashlib.sha256((VERSION + "\n" + repr(table)).encode("utf-8")).hexdigest()


def table_text(table, width: int = 100) -> list[str]:
    """Lines of Python of a flat table's entries (a tuple literal's body, several entries a line,
    deterministic), for a module to hold its kernels as data."""
    lines, line = [], ""
    for entry in table:
        item = repr(entry) + ","
        if line and len(line) + 1 + len(item) > width:
            lines.append(line)
            line = item
        else:
            line = f"{line} {item}" if line else item
    if line:
        lines.append(line)
    return lines


class Code(str):
    """Python text of an expression, carrying its tree (``.tree``): what the lowering's kernels
    hold, so a template prints the text and the compiled route reads the tree."""

    tree: tuple

    def __new__(cls, tree):
        self = super().__new__(cls, python(tree))
        self.tree = tree
        return self


def _nodes(tree):
    """Every node of a tree (an expression, a statement or a function), parents first."""
    stack = [tree]
    while stack:
        n = stack.pop()
        if isinstance(n, tuple) and n:
            if isinstance(n[0], str):
                yield n
            stack.extend(x for x in n if isinstance(x, tuple))


def tree_of(code) -> tuple:
    """The tree of a kernel entry's code: a :class:`Code`'s, or ``0.0`` for an entry without
    output (``Kernel.entries``); :class:`Unsupported` for text without a tree."""
    tree = getattr(code, "tree", None)
    if tree is not None:
        return tree
    if code == "0.0":
        return ("n", 0.0)
    raise Unsupported(f"code without a tree: {code[:40]!r}")


def called(tree) -> set:
    """The names of the functions a tree calls."""
    return {n[1] for n in _nodes(tree) if n[0] == "call" and len(n) == 3 and isinstance(n[1], str)}


def read_names(tree) -> set:
    """Every variable and array name a tree (a function, statement or expression) mentions."""
    return {n[1] for n in _nodes(tree) if (n[0] == "v" and len(n) == 2)
            or (n[0] == "[]" and len(n) == 3 and isinstance(n[1], str))}


#: the attribute of a generated kernel's Python function holding its tree
KIR_ATTR = "__kir__"


def attach(py_func, table):
    """Give a generated kernel's Python function its kernel IR: the tree at the end of ``table``
    (:func:`flatten`), which must be the definition of that function (its
    name and parameters), its digest and the names its body is translated in.  The compiled
    route then reads the tree and keys the machine code by its digest; the function's text (the
    module's) is never read.  Returns ``py_func``.

    Raises
    ------
    ValueError
        The table is not a kernel-IR function of that name and those parameters.
    """
    import math
    import types

    import numpy as np

    from . import special_helpers

    if not table:
        raise ValueError(f"{py_func.__name__}: an empty kernel table")
    tree = unflatten(table, len(table) - 1)
    code = py_func.__code__
    params = tuple(code.co_varnames[:code.co_argcount])
    if tree[0] != "def" or tree[1] != py_func.__name__ or tree[2] != params:
        raise ValueError(f"{py_func.__name__}{params}: its kernel table defines {tree[0]} {tree[1:3]!r}")
    names = {"math": math}
    for name, value in tree[4]:
        if isinstance(value, tuple):        # ("array", kind, shape, values)
            _, kind, shape, flat = value
            value = np.array(flat, dtype=np.float64 if kind == "f" else np.int64).reshape(shape)
        names[name] = value
    g = py_func.__globals__
    for name in sorted(called(tree)):
        if name.startswith("_f_"):
            names[name] = getattr(special_helpers, name)     # the package's helper, not the module's copy
        elif "." not in name and name not in ("abs", "min", "max", "range"):
            other = getattr(g.get(name), "py_func", g.get(name))
            if not isinstance(other, types.FunctionType) or getattr(other, KIR_ATTR, None) is None:
                raise ValueError(f"{py_func.__name__} calls {name}, which is not a kernel with a table")
            names[name] = other
    setattr(py_func, KIR_ATTR, tree)
    py_func.__kir_digest__ = digest(tree)
    py_func.__kir_names__ = names
    return py_func
