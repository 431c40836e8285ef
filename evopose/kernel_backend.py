"""Which compiled kernels run, once per process: the modules compiled ahead of time, or numba's JIT.

docs/design.md §2, "Compiled kernels": numba's JIT costs an agent about 110 MB resident (numba itself, LLVM's code
generator and its registries) for kernels that never change while it runs. ``make install`` compiles them ahead of
time (:mod:`evopose.kernel_build`, numba's ``pycc``) into :data:`evopose.kernel_abi.AOT_MODULES`, extension
modules that need neither numba nor llvmlite. They are used when they are there and *current*: each one's
:func:`build_key` (the text of :data:`evopose.kernel_abi.SOURCES` and this machine's processor, for which it was
compiled) is this checkout's. Otherwise, or with ``EVOPOSE_KERNELS=jit`` in the environment, the same kernels run
through numba's JIT (imported then, and only then), so an edited kernel is never run stale and a fresh checkout works
before a build.

Every kernel of :data:`evopose.kernel_abi.EXPORTS` is a function here, and callers use these, never the numba
modules: a compiled module has no dispatcher to adapt to what it is given and would read an array of another type
as garbage, so each call first brings its arrays to the one type the kernel is compiled for (a C-contiguous copy of
the declared dtype when they differ; an array the kernel writes must already have its type, or ``TypeError``).
Both backends get the same arrays, so both run the same specialisation (how closely they agree: docs/design.md §2).
"""

from __future__ import annotations

import hashlib
import importlib
import os
import platform
import types
from pathlib import Path

import numpy as np

from .kernel_abi import AOT_MODULES, EXPORTS, SOURCES, WRITTEN

ROOT = Path(__file__).resolve().parents[1]
#: ``EVOPOSE_KERNELS=jit`` runs numba's JIT even when the compiled module is current (comparisons, debugging).
ENV = "EVOPOSE_KERNELS"
_DTYPES = {"f8": np.dtype(np.float64), "b1": np.dtype(np.bool_), "i8": np.dtype(np.int64)}
_SCALARS = {"f8": float, "b1": bool, "i8": int}


def machine() -> str:
    """The processor a compiled module is built for and must run on: its architecture and, on Linux, its
    instruction-set flags (the compiled code uses this processor's instructions, as numba's JIT does)."""
    flags = ""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        with cpuinfo.open(errors="replace") as lines:
            flags = next((line.split(":", 1)[1] for line in lines if line.startswith(("flags", "Features"))), "")
    return f"{platform.machine()} {' '.join(sorted(flags.split()))}"


def build_key() -> int:
    """A 60-bit key of this checkout's kernel sources and this machine: a compiled module holds the key it was
    built with (its ``build_key()``) and is used only when the two agree."""
    digest = hashlib.sha256(machine().encode())
    for name in SOURCES:
        digest.update(name.encode() + b"\0" + (ROOT / name).read_bytes())
    return int(digest.hexdigest()[:15], 16)


def load_aot() -> types.SimpleNamespace | None:
    """The compiled modules' kernels when every module is built and current, else None (never imports numba)."""
    key, kernels = build_key(), {}
    for name, exported in AOT_MODULES.items():
        try:
            module = importlib.import_module(name)
            if module.build_key() != key:
                return None
            kernels.update({kernel: getattr(module, kernel) for kernel in exported})
        except (ImportError, OSError, AttributeError):  # not built (or for another Python, or an older layout), or a
            return None                                  # source not readable: the JIT
    return types.SimpleNamespace(**kernels)


def load_jit() -> types.SimpleNamespace:
    """The kernels through numba's JIT (imports numba)."""
    modules = {name: importlib.import_module(name) for name in {module for module, _, _ in EXPORTS.values()}}
    return types.SimpleNamespace(**{name: getattr(modules[module], name) for name, (module, _, _) in EXPORTS.items()})


def _choose() -> tuple[str, object]:
    if os.environ.get(ENV, "").lower() != "jit" and (module := load_aot()) is not None:
        return "aot", module
    return "jit", None


#: "aot" or "jit": the backend this process runs (the JIT's modules are imported at its first call).
BACKEND, _aot = _choose()
_impl = _aot


def implementation() -> object:
    """The module or namespace whose kernels the functions below call."""
    global _impl
    if _impl is None:
        _impl = load_jit()
    return _impl


def _parse(kind: str) -> tuple[type, None] | tuple[np.dtype, int]:
    """``"f8"`` -> (float, None); ``"f8[:, ::1]"`` -> (float64, 2)."""
    return (_SCALARS[kind], None) if kind in _SCALARS else (_DTYPES[kind[:2]], kind.count(",") + 1)


#: name -> per argument: (scalar type, None) or (dtype, dimensions), and whether the kernel writes it
_SPECS = {name: tuple((*_parse(kind), i in WRITTEN.get(name, ())) for i, kind in enumerate(kinds))
          for name, (_, _, kinds) in EXPORTS.items()}


def _argument(value, dtype, ndim: int | None, written: bool, name: str, position: int):
    if ndim is None:
        return dtype(value)
    if type(value) is np.ndarray and value.dtype == dtype and value.ndim == ndim and value.flags.c_contiguous:
        return value
    if written:
        raise TypeError(f"{name}: argument {position} is written in place and must be a C-contiguous {dtype} array "
                        f"of {ndim} dimensions, got {getattr(value, 'dtype', type(value))} {np.shape(value)}")
    out = np.ascontiguousarray(value, dtype=dtype)
    if out.ndim != ndim:
        raise ValueError(f"{name}: argument {position} must have {ndim} dimensions, got shape {out.shape}")
    return out


def _typed(name: str, args: tuple) -> list:
    spec = _SPECS[name]
    if len(args) != len(spec):
        raise TypeError(f"{name} takes {len(spec)} arguments, got {len(args)}")
    return [_argument(a, dtype, ndim, written, name, i)
            for i, (a, (dtype, ndim, written)) in enumerate(zip(args, spec))]


def call(name: str, *args, impl: object | None = None):
    """Kernel ``name`` of :data:`evopose.kernel_abi.EXPORTS` on ``args`` brought to its types; ``impl`` another
    backend's module or namespace (:func:`load_aot`, :func:`load_jit`) than this process's."""
    return getattr(implementation() if impl is None else impl, name)(*_typed(name, args))


def _kernel(name: str):
    module, _, _ = EXPORTS[name]

    def kernel(*args):
        return getattr(_impl or implementation(), name)(*_typed(name, args))

    kernel.__name__ = kernel.__qualname__ = name
    kernel.__doc__ = f"``{module}.{name}`` (compiled ahead of time or through numba's JIT: :mod:`{__name__}`)."
    return kernel


project_points = _kernel("project_points")
project_poses = _kernel("project_poses")
project_pose = _kernel("project_pose")
is_typed = _kernel("is_typed")
view_terms = _kernel("view_terms")
chamfer_matches = _kernel("chamfer_matches")
nearest_row = _kernel("nearest_row")
nearest_sorted = _kernel("nearest_sorted")
refine_population = _kernel("refine_population")
robust_irls = _kernel("robust_irls")
align_positions = _kernel("align_positions")

__all__ = ["BACKEND", "build_key", "call", "implementation", "load_aot", "load_jit", "machine", *EXPORTS]
