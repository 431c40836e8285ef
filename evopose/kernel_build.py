"""Compile the kernels ahead of time into :data:`evopose.kernel_abi.AOT_MODULES` (``make install`` runs this).

Run from the repository root (about 25 s on 2 cores: each module in its own process, at once; nothing to do, and
under a second, when the modules are current)::

    python -m evopose.kernel_build [--force]

numba's ``pycc`` (docs/design.md §2, "Compiled kernels") compiles each kernel of
:data:`evopose.kernel_abi.EXPORTS` for its one set of argument types into an extension module that needs neither
numba nor llvmlite at run time, with numba's own runtime for the arrays a kernel allocates. Each exported function is
a thin wrapper that calls the kernel, so the kernel is compiled by its own dispatcher with its own options
(``fastmath``, ``inline``), from an empty numba cache, as numba's JIT compiles it. Three settings of
``pycc`` are changed to match the JIT: the wrappers release the GIL (the kernels' ``nogil``: the bus threads run
while a search computes), and the code is generated for this machine's processor and its instruction-set features
(pycc's default is a generic processor: slower, and not the JIT's code). The module also exports ``build_key()``,
:func:`evopose.kernel_backend.build_key` at build time, so that a checkout whose kernels changed since, or another
machine, does not use it. ``pycc`` is pending deprecation in numba (since 0.57) without a replacement yet;
``constraints.txt`` pins numba.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from .kernel_abi import AOT_MODULES, EXPORTS
from .kernel_backend import ROOT, build_key, load_aot


def _wrapper(name: str, module: str, n_args: int):
    """``def name(a0, ..., an): return kernel(a0, ..., an)`` (pycc exports functions of fixed arity)."""
    import importlib

    params = ", ".join(f"a{i}" for i in range(n_args))
    namespace = {"kernel": getattr(importlib.import_module(module), name)}
    exec(f"def {name}({params}):\n    return kernel({params})\n", namespace)  # noqa: S102 - our own names
    return namespace[name]


def _key_function(key: int):
    def build_key():
        return key
    return build_key


def build(output_dir: str, module: str, kernels: tuple[str, ...]) -> str:
    """Compile ``module`` (a name of :data:`evopose.kernel_abi.AOT_MODULES`) with ``kernels`` into ``output_dir``, from
    an empty numba cache there; its file name."""
    os.makedirs(output_dir, exist_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(output_dir, "numba-cache")  # compile every kernel afresh
    import warnings

    from numba.core import codegen
    from numba.core.compiler import Flags
    from numba.core.errors import NumbaPendingDeprecationWarning
    import numba.pycc.compiler as pycc_compiler

    class _ReleaseGil(Flags):  # the exported wrappers release the GIL, as the kernels' nogil=True
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.release_gil = True

    pycc_compiler.Flags = _ReleaseGil
    # the host's features, as numba's JIT (pycc takes only those the processor's name implies)
    codegen.AOTCPUCodegen._customize_tm_features = lambda self: self._get_host_cpu_features()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaPendingDeprecationWarning)
        from numba.pycc import CC

    cc = CC(module.rpartition(".")[2], source_module=__name__)
    cc.target_cpu = "host"
    cc.output_dir = output_dir
    for name in kernels:
        source, result, kinds = EXPORTS[name]
        cc.export(name, f"{result}({', '.join(kinds)})")(_wrapper(name, source, len(kinds)))
    cc.export("build_key", "i8()")(_key_function(build_key()))
    cc.compile()
    return cc.output_file


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--force", action="store_true", help="compile even when the built module is current")
    args = parser.parse_args(argv)
    if not args.force and load_aot() is not None:
        return 0   # current: nothing to say (make runs this before every demo and test)
    from evopose import kernel_build   # by its name (not __main__'s): what the processes import

    start = time.perf_counter()
    package = ROOT / "evopose"
    # each module in its own process (a fresh interpreter: numba is never imported here), all at once
    with tempfile.TemporaryDirectory(prefix=".aot-build-", dir=package) as work, \
            ProcessPoolExecutor(len(AOT_MODULES), mp_context=multiprocessing.get_context("spawn")) as pool:
        jobs = {module: pool.submit(kernel_build.build, os.path.join(work, module), module, kernels)
                for module, kernels in AOT_MODULES.items()}
        for module, job in jobs.items():  # same file system: os.replace is atomic, a running process sees old or new
            name = job.result()
            os.replace(os.path.join(work, module, name), package / name)
    print(f"{', '.join(AOT_MODULES)}: built in {package} in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
