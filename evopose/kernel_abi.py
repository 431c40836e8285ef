"""What the compiled kernels are, without compiling anything: their constants and the types they are called with.

The kernels (:mod:`evopose.projection`, :mod:`evopose.kernels`, :mod:`evopose.refine_kernel`,
:mod:`evopose.align_kernel`, :mod:`evopose.robust_kernel`) are numba functions;
an agent runs them from a module compiled ahead of time (:mod:`evopose.kernel_build`) when one is built and current,
else through numba's JIT, and :mod:`evopose.kernel_backend` makes that choice (docs/design.md §2, "Compiled kernels").
This module holds what both sides share and imports neither numba nor a kernel, so that the choice costs nothing:

* the constants of the kernels (their callers and the kernels read them here);
* :data:`EXPORTS`, the kernels called from Python, each with the one set of argument types it is compiled for
  (numba's type names: ``f8[:, ::1]`` a C-contiguous float64 matrix, ``b1`` a bool, ``i8`` an int64): a compiled
  module has no dispatcher, so the backend brings every call to exactly these types first;
* :data:`SOURCES`, the modules whose text is the compiled code (a change to one makes a built module stale).
"""

from __future__ import annotations

#: Points closer than this to the camera plane (metres, along the optical axis) are not projected.
MIN_DEPTH = 1e-3
#: Image coordinate given to points that cannot be projected (behind the camera); far from any pixel.
FAR_AWAY_PX = 1e6
#: Relaxed floating point (no NaN/inf assumptions, which the sentinels above would break).
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
#: Squared distance reported when no candidate exists (no usable model point, or unusable model point).
NO_MATCH_D2 = 1e30
#: View-term modes (:func:`evopose.kernels.view_term_row`): the paper's eq. (1), the robust two-sided mean, the
#: mutual RMS.
PAPER, ROBUST, MUTUAL = 0, 1, 2


_F1, _F2, _F3 = "f8[::1]", "f8[:, ::1]", "f8[:, :, ::1]"
_B1, _B2, _I1, _I2 = "b1[::1]", "b1[:, ::1]", "i8[::1]", "i8[:, ::1]"

#: name -> (module defining it, return type, argument types): every kernel called from Python. Arrays written in
#: place (outputs, scratch) are passed as they are and must already have their type; inputs are converted.
EXPORTS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "project_points": ("evopose.projection", f"Tuple(({_F2}, {_B1}))", (_F2, _F1)),
    "project_poses": ("evopose.projection", f"Tuple(({_F2}, {_F2}, {_B2}))", (_F2, _F2, _F2, "b1", _F1, _F2)),
    "project_pose": ("evopose.projection", "none",
                     (_F1, _F2, _F2, "b1", _F1, _F2, _F1, _F1, _B1, _F2, _F2)),
    "is_typed": ("evopose.kernels", "b1", (_F1, _F1)),
    "view_terms": ("evopose.kernels", _F1, (_F2, _F2, _F1, _B2, _F1, _F1, _F1, "f8", "i8")),
    "chamfer_matches": ("evopose.kernels", f"Tuple(({_I2}, {_F2}, {_I2}, {_F2}))",
                        (_F2, _F2, _F1, _B2, _F1, _F1, _F1)),
    "nearest_row": ("evopose.kernels", "none", (_F1, _F1, _F1, _B1, _F1, _F1, _F1, "b1", _I1, _F1, _I1, _F1)),
    "nearest_sorted": ("evopose.kernels", f"Tuple(({_F1}, {_I1}, {_B1}))", (_F2, _F2, _I1, "b1")),
    "align_positions": ("evopose.align_kernel", "none",
                        (_F2, _F2, _F2, "b1", _F1, _F2, _F2, _F1, _F2, _F1, "i8")),
    "robust_irls": ("evopose.robust_kernel", "i8",
                    (_F1, _F1, _F1, _B1, _B1, _F2, _F2, "b1", _F2, _F3, _F1, _F1, _F2, _F1, _F2, _I1, _F1, "b1", "i8",
                     "f8", "f8")),
    "refine_population": ("evopose.refine_kernel", "none",
                          (_F2, _F1, _F1, _F1, _B1, _B1, _F2, _F2, "b1", _F2, _F3, _F1, _F1, _F2, _F2, _F1, _F2, _I1,
                           "i8", _I1, _F1, "f8", "f8")),
}
#: The compiled modules (built next to this file by :mod:`evopose.kernel_build`; never committed) and the kernels of
#: :data:`EXPORTS` each holds. Each is compiled in its own process, the two at once: ``refine_population`` alone takes
#: as long to compile as all the others (~20 s and ~10 s here).
AOT_MODULES: dict[str, tuple[str, ...]] = {
    "evopose.kernels_aot": tuple(name for name in EXPORTS if name != "refine_population"),
    "evopose.kernels_aot_refine": ("refine_population",),
}
#: Arguments written in place, by kernel (positions in :data:`EXPORTS`' argument types).
WRITTEN: dict[str, tuple[int, ...]] = {
    "project_pose": (6, 7, 8, 9, 10),
    "align_positions": (0,),
    "nearest_row": (8, 9, 10, 11),
    "refine_population": (0, 1),
    "robust_irls": (0,),
}

#: The project's files whose text is the compiled code (relative to the repository root), this one included: its
#: constants are compiled in. A built module carries a key made from them (:func:`evopose.kernel_backend.build_key`).
SOURCES = ("geometry/__init__.py", "evopose/kernel_abi.py", "evopose/kernel_build.py", "evopose/projection.py",
           "evopose/kernels.py", "evopose/refine_kernel.py", "evopose/align_kernel.py", "evopose/robust_kernel.py")
