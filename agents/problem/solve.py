"""Service functions behind the CLI commands: each does one command's work and returns plain data."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from evopose import PoseProblem, SearchOptions, View, solve
from evopose.fitness import FitnessKind

from agents.problem.camera_info import read_camera_file
from vision.extract import FEATURE_KINDS, feature_extractor, resolve_features
from agents.problem.problem_file import ProblemFileError, ProblemInputs, read_problem, solution_to_dict


def solve_file(path: str | Path, *, seed: int | None = None, time_budget: float | None = None,
               fitness: FitnessKind | None = None, overlay: str | Path | None = None) -> dict:
    """Solve the pose-problem file at ``path`` (docs/design.md §3) and return the output object.

    ``seed``, ``time_budget`` and ``fitness`` override the file's ``seed`` and ``options`` when given.
    Views may give an ``image`` instead of ``points`` (marks are extracted first). ``overlay`` writes a
    PNG of the first view: its image points and the model projected at the estimated pose.

    Raises
    ------
    ProblemFileError
        The file is unreadable or malformed.
    """
    return _solve_inputs(read_problem(path), seed, time_budget, fitness, overlay)


def solve_image(image: str | Path, model: str | Path, camera: str | Path, *, seed: int | None = None,
                time_budget: float | None = None, fitness: FitnessKind | None = None,
                overlay: str | Path | None = None, features: str = "auto") -> dict:
    """Solve from one image: extract the points of ``model`` (a model file), search inside ``camera``'s view.

    ``camera`` is a YAML/JSON file with the problem file's camera fields (intrinsics, optional distortion
    and ``world_from_camera``) or a ROS ``camera_info`` YAML (:mod:`agents.problem.camera_info`). ``features``:
    the model's colour ``marks`` or a chessboard's inner ``corners`` (:mod:`vision.extract`). The search
    box is the camera's view at the depth the points' spread gives.
    """
    from scenarios.errors import WorldError
    from scenarios.target import load_model

    from vision.images import frustum_bounds, read_image

    cam = read_camera_file(camera)
    target = load_model(model)
    picture = read_image(image)
    if picture.shape[:2] != (cam.height, cam.width):
        raise WorldError(f"{image}: image is {picture.shape[1]}x{picture.shape[0]}, "
                         f"the camera is {cam.width}x{cam.height}")
    if features not in FEATURE_KINDS:
        raise ProblemFileError(f"--features must be one of {', '.join(FEATURE_KINDS)}, got {features!r}")
    kind = resolve_features(features, camera_images=True)   # a picture file is a camera's
    points, labels = feature_extractor(kind, target)(picture, cam)
    if len(points) < 3:
        raise WorldError(f"{image}: {len(points)} {features} found; at least 3 are needed")
    evo_model = target.evopose_model()
    problem = PoseProblem(evo_model, (View(cam, points, labels=labels),), frustum_bounds(cam, evo_model, points))
    inputs = ProblemInputs(problem, SearchOptions(), None, [picture], target)
    return _solve_inputs(inputs, seed, time_budget, fitness, overlay)


def _solve_inputs(inputs: ProblemInputs, seed, time_budget, fitness, overlay) -> dict:
    overrides = {name: value for name, value in (("time_budget", time_budget), ("fitness", fitness))
                 if value is not None}
    options = dataclasses.replace(inputs.options, **overrides)
    solution = solve(inputs.problem, options, seed=inputs.seed if seed is None else seed)
    result = solution_to_dict(solution)
    if overlay is not None:
        from vision.images import draw_overlay, write_image

        view = inputs.problem.views[0]
        canvas = draw_overlay(inputs.images[0], view.camera, inputs.problem.model, np.asarray(solution.pose),
                              view.points, inputs.target)
        result["overlay"] = str(write_image(overlay, canvas))
    return result
