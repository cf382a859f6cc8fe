"""Layer 3, code generation: a scheme to a generated module, and its kernels to machine code.

:mod:`~methodgen.codegen.lower` (a scheme to frozen IR; ``lower_loops``, ``lower_rows``),
:mod:`~methodgen.codegen.emit` (IR through the templates to a file, and loading it),
:mod:`~methodgen.codegen.build` (from a system to an imported module, reusing files),
:mod:`~methodgen.codegen.store` (where modules live and whose they are),
:mod:`~methodgen.codegen.progress` (phase reports), :mod:`~methodgen.codegen.abi` (the contract
between generated code and the runtime), and the compiler of a compiled module's kernels through
LLVM IR: :mod:`~methodgen.codegen.llvmkernels` over ``kir``, ``kernelsource``, ``ktypes`` and
``llvmcache`` (the machine-code cache).  The runtime calls that compiler when a generated module
is loaded, so it sits here, below the runtime: imports go from the runtime down to code
generation, never up.
"""
