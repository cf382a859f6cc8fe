"""Layer 5, the applications: the command line (:mod:`~methodgen.app.cli`) and what it runs
besides a module -- bench, sweep, figures, plots, peers, citations, limits and statistics.

Nothing below imports it.
"""
