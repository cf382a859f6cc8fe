"""Layer 1, the problem: the user's system and its parsing.

:mod:`~methodgen.problem.parse` (expression text into SymPy, safely),
:mod:`~methodgen.problem.problem` (:class:`~methodgen.problem.problem.Hamiltonian`),
:mod:`~methodgen.problem.poisson` (:class:`~methodgen.problem.poisson.PoissonSystem`), and the
expression helpers they check with: :mod:`~methodgen.problem.special` (removable-singularity
functions), :mod:`~methodgen.problem.zeros` (exact zero tests), :mod:`~methodgen.problem.families`
(sums of like terms).  Imports :mod:`methodgen.errors` only, of methodgen.
"""
