"""Exception hierarchy of methodgen.

Every error a user can provoke with bad input is a :class:`MethodgenError`; the
CLI turns these into a one-line message and a non-zero exit status, never a
traceback.  Errors raised *inside generated modules* are defined in the module
itself (generated code must not import methodgen), but they carry the same
names so that ``except module.ConvergenceError`` reads naturally.
"""

from __future__ import annotations


class MethodgenError(Exception):
    """Base class of every error methodgen raises on purpose."""


class InputError(MethodgenError, ValueError):
    """Bad user input: a Hamiltonian, a scene file, an initial value, a step size."""


class ParseError(InputError):
    """Expression text that is not in the accepted grammar."""


class SceneError(InputError):
    """A scene file that cannot be read or does not follow the scene format."""


class MethodNotApplicable(InputError):
    """A method was asked for a system it does not apply to."""


class GenerationError(MethodgenError):
    """Code generation failed or a generated file cannot be trusted."""
