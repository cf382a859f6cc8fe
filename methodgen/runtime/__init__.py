"""Layer 4, the runtime: what generated modules and runs execute on.

:mod:`~methodgen.runtime.stepper` (the integration loop, one source),
:mod:`~methodgen.runtime.fused` (the stepper compiled with a module's kernels inlined),
:mod:`~methodgen.runtime.nbabi` (the compiled runtime's interface a compiled module loads), :mod:`~methodgen.runtime.kepler_flow` and :mod:`~methodgen.runtime.nbody`
(the Wisdom–Holman splittings run), :mod:`~methodgen.runtime.events`,
:mod:`~methodgen.runtime.physical_time`, and trajectories on disk (:mod:`~methodgen.runtime.runio`,
:mod:`~methodgen.runtime.trajfile`).  May import every layer below it: the compiled runtime
compiles a module's kernels with :mod:`methodgen.codegen.llvmkernels` when the module is loaded.
"""
