"""Layer 2, symbolic: derivation, discretisation and proof, all in SymPy (and mpmath).

:mod:`~methodgen.symbolic.derive` (gradients, structure, invariants), :mod:`~methodgen.symbolic.schemes`
(the methods: a system to a :class:`~methodgen.symbolic.schemes.base.Scheme`), compositions,
splittings, processing, time transformation, stages, projection, compensated sums,
:mod:`~methodgen.symbolic.nbody` (the Wisdom–Holman splittings, certified),
:mod:`~methodgen.symbolic.verify` (exact certificates of the claims) and
:mod:`~methodgen.symbolic.scene` (scene files: a problem and the methods wanted for it; the
built-in ones in ``scenes/``).  Imports the problem layer, never code generation or the runtime.
"""
