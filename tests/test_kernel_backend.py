"""The kernels compiled ahead of time against numba's JIT (docs/design.md §2, "Compiled kernels"): the same results
on the same arrays (to the last bit, :data:`LAST_BITS`), every call of a search replayed, and the same answer of the
search; the choice between them; the types every call is brought to.

The tests that need the compiled module skip when it is not built (``python -m evopose.kernel_build``) unless
``EVOPOSE_REQUIRE_AOT`` is set, as ``make test`` sets it after building: there a missing module fails.
"""

from __future__ import annotations

from dataclasses import replace
import importlib
import os

import numpy as np
import pytest

from benchmarks.problems import make_problem
from evopose import kernel_backend
from evopose.fitness import PoseObjective
from evopose.kernel_abi import EXPORTS, WRITTEN
from evopose.options import SearchOptions
from evopose.refine import match_residuals
from evopose.solver import solve

AOT = kernel_backend.load_aot()
needs_aot = pytest.mark.skipif(AOT is None and not os.environ.get("EVOPOSE_REQUIRE_AOT"),
                               reason="the compiled kernels are not built (python -m evopose.kernel_build)")


def _copied(args) -> list:
    """A copy of a call's arguments, read-only arrays read-only (numba compiles those apart)."""
    out = []
    for a in args:
        if isinstance(a, np.ndarray):
            writeable, a = a.flags.writeable, a.copy()
            a.flags.writeable = writeable
        out.append(a)
    return out


class Recorder:
    """Forwards every kernel call to ``impl`` and keeps a copy of its arguments."""

    def __init__(self, impl):
        self.impl = impl
        self.calls: list[tuple[str, list]] = []

    def __getattr__(self, name):
        kernel = getattr(self.impl, name)

        def recorded(*args):
            self.calls.append((name, _copied(args)))
            return kernel(*args)

        return recorded


def _problem(seed: int, labelled: bool):
    rng = np.random.default_rng(seed)
    problem = make_problem("box", rng, n_views=2, noise=1.0, clutter=0.2, missing=0.1).problem
    if labelled:  # typed points: the (u, v, label) loops of the kernels
        views = tuple(replace(v, labels=rng.integers(0, 3, len(v.points))) for v in problem.views)
        model = replace(problem.model, labels=rng.integers(0, 3, len(problem.model.points)))
        problem = replace(problem, views=views, model=model)
    return problem


def _solve_with(impl, problem, monkeypatch):
    monkeypatch.setattr(kernel_backend, "_impl", impl)
    options = SearchOptions(max_generations=3, min_starts=1)
    solution = solve(problem, options, seed=3)
    return solution, match_residuals(PoseObjective(problem), solution.pose)


def _assert_same(a, b):
    if isinstance(a, tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _assert_same(x, y)
    elif np.asarray(a).dtype.kind == "f":
        # to the last bits of the array's largest value: an element that is a difference of large ones (a distance
        # between nearby pixels) keeps their rounding, not its own (measured: 0.2907061105550 against ...557 in an
        # array of values up to 341, the JIT compiled in a process with an empty numba cache)
        scale = float(np.max(np.abs(b), initial=0.0))
        np.testing.assert_allclose(a, b, rtol=LAST_BITS, atol=LAST_BITS * scale, strict=True)
    else:
        np.testing.assert_array_equal(a, b, strict=True)


#: Relative agreement of a kernel's floating-point results, compiled ahead of time and through numba's JIT: the
#: same code, inlined and optimised as one module (with fastmath's contractions and reassociations) rather than one
#: library per kernel, can differ in the last bit (numba's JIT differs from itself so between a kernel compiled in
#: the process and the same kernel loaded from its cache). Integer and boolean results are equal.
LAST_BITS = 1e-12
#: The refinement's poses: the last bits of its sums over pairs (the compiled module's code and the JIT's may order
#: them otherwise) move a pose by 1e-11 to 1e-10 over a schedule (measured); its Jacobian is analytic, so nothing
#: amplifies them (a finite-difference one did, to 1e-3). The search's answer is compared too (below).
REFINED = 1e-8


def jit_as_cached():
    """numba's JIT kernels as an agent runs them: loaded from numba's on-disk cache. A kernel numba compiles in the
    running process can differ from the code it caches in the last bits of a result (its in-process code is
    linked and inlined otherwise); the cached code is what the compiled module's is. So the kernels' modules are
    imported afresh, their dispatchers then load what this process (or an earlier one) compiled and cached."""
    callees_first = ("evopose.projection", "evopose.kernels", "evopose.refine_kernel", "evopose.align_kernel")
    for name in callees_first:
        importlib.reload(importlib.import_module(name))
    return kernel_backend.load_jit()


@needs_aot
@pytest.mark.parametrize("labelled", [False, True], ids=["untyped", "typed"])
def test_every_kernel_call_of_a_search_gives_the_same_results_compiled_ahead_of_time(labelled, monkeypatch):
    assert AOT is not None, "the compiled kernels are not built: make install (python -m evopose.kernel_build)"
    problem = _problem(1, labelled)
    recorder = Recorder(kernel_backend.load_jit())
    _solve_with(recorder, problem, monkeypatch)  # every call's arguments; numba compiles and caches each kernel
    assert {name for name, *_ in recorder.calls} >= {"project_poses", "view_terms", "refine_population",
                                                      "project_pose", "nearest_row", "is_typed"}
    jit = jit_as_cached()
    for name, args in recorder.calls:  # each call again, through both, on its own inputs
        aot_args, jit_args = _copied(args), _copied(args)
        aot_out, jit_out = getattr(AOT, name)(*aot_args), getattr(jit, name)(*jit_args)
        if name == "refine_population":
            for i in WRITTEN[name]:
                np.testing.assert_allclose(aot_args[i], jit_args[i], rtol=REFINED, atol=REFINED)
            continue
        _assert_same(aot_out, jit_out)
        for i in WRITTEN.get(name, ()):
            _assert_same(aot_args[i], jit_args[i])
    jit_solution, jit_residuals = _solve_with(jit, problem, monkeypatch)  # and the whole search
    aot_solution, aot_residuals = _solve_with(AOT, problem, monkeypatch)
    np.testing.assert_allclose(aot_solution.pose, jit_solution.pose, rtol=0, atol=1e-6)
    assert aot_solution.fitness == pytest.approx(jit_solution.fitness, rel=1e-9)
    for (a_img, a_mod), (j_img, j_mod) in zip(aot_residuals, jit_residuals):
        np.testing.assert_allclose(a_img, j_img, rtol=1e-6)
        np.testing.assert_allclose(a_mod, j_mod, rtol=1e-6)


@needs_aot
def test_the_projections_and_the_neighbour_kernel_give_the_same_results_compiled_ahead_of_time():
    assert AOT is not None
    jit = jit_as_cached()
    rng = np.random.default_rng(5)
    intr = np.array([800.0, 790.0, 320.0, 240.0, -0.2, 0.05, 1e-3, -2e-3, 0.01])
    points = rng.normal(size=(500, 3)) + [0, 0, 2.0]
    points[:5, 2] = [-1.0, 0.0, 1e-4, 1e-3, 2e-3]  # behind, on and just in front of the camera plane
    _assert_same(kernel_backend.call("project_points", points, intr, impl=AOT),
                 kernel_backend.call("project_points", points, intr, impl=jit))
    queries, cloud = rng.normal(size=(300, 2)), rng.normal(size=(400, 2))
    cloud[7] = cloud[3]  # a tie
    order = np.argsort(cloud[:, 0], kind="stable")
    for exclude_self, q in ((False, queries), (True, cloud)):
        _assert_same(kernel_backend.call("nearest_sorted", q, cloud, order, exclude_self, impl=AOT),
                     kernel_backend.call("nearest_sorted", q, cloud, order, exclude_self, impl=jit))


def test_every_exported_kernel_is_a_function_of_the_backend():
    assert set(EXPORTS) <= set(kernel_backend.__all__)
    for name in EXPORTS:
        assert callable(getattr(kernel_backend, name))
    if AOT is not None:
        assert all(callable(getattr(AOT, name)) for name in EXPORTS)


def test_a_stale_or_missing_module_leaves_the_jit(monkeypatch):
    monkeypatch.setattr(kernel_backend, "build_key", lambda: -1)  # the sources changed since the build
    assert kernel_backend.load_aot() is None
    monkeypatch.undo()
    assert kernel_backend.load_aot() is not None or not os.environ.get("EVOPOSE_REQUIRE_AOT")
    missing = {**kernel_backend.AOT_MODULES, "evopose.no_such_module": ("is_typed",)}   # one of them not built
    monkeypatch.setattr(kernel_backend, "AOT_MODULES", missing)
    assert kernel_backend.load_aot() is None


def test_the_build_key_names_the_sources_and_the_processor():
    assert kernel_backend.build_key() == kernel_backend.build_key()
    assert 0 <= kernel_backend.build_key() < 2 ** 60
    assert kernel_backend.machine().split()[0]


def test_inputs_are_brought_to_the_compiled_types_and_outputs_must_have_them():
    rng = np.random.default_rng(2)
    intr = np.array([800.0, 790.0, 320.0, 240.0, 0, 0, 0, 0, 0])
    points = rng.normal(size=(20, 3)) + [0, 0, 3.0]
    uv, front = kernel_backend.project_points(points, intr)
    other = np.asfortranarray(points)
    uv2, front2 = kernel_backend.project_points(other, list(intr))  # Fortran order, a list: converted
    np.testing.assert_array_equal(uv, uv2)
    np.testing.assert_array_equal(front, front2)
    with pytest.raises(ValueError, match="dimensions"):
        kernel_backend.project_points(points[0], intr)
    with pytest.raises(TypeError, match="arguments"):
        kernel_backend.project_points(points)
    u, v, mz = rng.normal(size=4), rng.normal(size=4), np.zeros(4)
    usable = np.ones(4, bool)
    px, py, pz = rng.normal(size=3), rng.normal(size=3), np.zeros(3)
    img_d2, mod_nn, mod_d2 = np.empty(3), np.empty(4, np.int64), np.empty(4)
    with pytest.raises(TypeError, match="written in place"):  # a copy would be written, not the caller's array
        kernel_backend.nearest_row(u, v, mz, usable, px, py, pz, False, np.empty(3, np.int32), img_d2, mod_nn, mod_d2)
