"""The pose-problem file of docs/design.md §3: its schema, loading it into an :class:`evopose.PoseProblem`, and the output.

A problem file (YAML or JSON) holds a model, one or more views (eq. 4), the search box,
optional eq. (3) constraints, hint poses, a seed and search options. Angles are radians,
lengths metres, image points pixels. :func:`load_problem` validates every field and
raises :class:`ProblemFileError` with one line naming the first offending field.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import (AfterValidator, BeforeValidator, Field, ValidationError,
                      ValidationInfo, create_model, field_validator, model_validator)

from evopose import Bounds, Camera, Model, PoseProblem, SearchOptions, Solution, View
from geometry import PARAM_NAMES, pose_from_matrix, quaternion_from_euler
from evopose_errors import EvoPoseError

from scenarios.errors import WorldError
from scenarios.target import TargetModel, load_model, resolve_model_path
from scenarios.documents import FullPoseSpec, Spec, describe, read_mapping, validation_message

from vision.images import detect_marks, read_image

#: Problem-size limits (docs/security.md, "Untrusted input"): each breach is one line naming the field.
MAX_MODEL_POINTS = 4096
MAX_IMAGE_POINTS = 16384  # as many as a feature set may carry on the wire
MAX_VIEWS = 32
MAX_HINTS = 256
#: Largest coordinate accepted: metres in the model and the search box, pixels in the images.
MAX_COORDINATE = 1e6
#: Largest search sizes accepted in ``options``.
MAX_POPULATION, MAX_OFFSPRING, MAX_SCREENING = 4096, 16384, 64
#: Range searched for an angle the file does not mention: a full turn.
FULL_TURN = (-math.pi, math.pi)
#: Shortest normal evopose.Model accepts.
MIN_NORMAL_LENGTH = 1e-12


class ProblemFileError(EvoPoseError, ValueError):
    """A pose-problem file that cannot be used; the message is one line naming the file or the field."""


def _fixed_length(n: int, what: str) -> BeforeValidator:
    """Check that a value is a list of ``n`` entries before its numbers are validated."""

    def check(value: Any) -> Any:
        if not isinstance(value, list):
            raise ValueError(f"expected a list of {n} numbers {what}, got {describe(value)}")
        if len(value) != n:
            raise ValueError(f"expected {n} numbers {what}, got {len(value)}")
        return value

    return BeforeValidator(check)


def _ordered(value: list[float]) -> list[float]:
    if value[0] > value[1]:
        raise ValueError(f"lo {value[0]} > hi {value[1]}")
    return value


def _non_zero(value: list[float]) -> list[float]:
    if math.hypot(*value) < MIN_NORMAL_LENGTH:
        raise ValueError("a normal must be a non-zero vector")
    return value


def _moderate(value: list[float]) -> list[float]:
    if any(abs(v) > MAX_COORDINATE for v in value):
        raise ValueError(f"coordinates must be within +-{MAX_COORDINATE:g}")
    return value


Point2 = Annotated[list[float], _fixed_length(2, "[u, v]"), AfterValidator(_moderate)]
Point3 = Annotated[list[float], _fixed_length(3, "[x, y, z]"), AfterValidator(_moderate)]
#: A point's class (its mark colour), our extension of eq. (1): a point matches only marks of its label.
Label = Annotated[int, Field(ge=0, le=255)]
Normal = Annotated[Point3, AfterValidator(_non_zero)]
Range = Annotated[list[float], _fixed_length(2, "[lo, hi]"), AfterValidator(_moderate), AfterValidator(_ordered)]
Distortion = Annotated[list[float], _fixed_length(5, "[k1, k2, p1, p2, k3]")]


class ModelSpec(Spec):
    """The target's feature points in the target frame, optionally with outward normals; or a model ``file``
    (``scenarios/models`` format: marks with colours, relative to the problem file, or a shipped model name)."""

    points: Annotated[list[Point3], Field(min_length=1, max_length=MAX_MODEL_POINTS)] | None = None
    normals: Annotated[list[Normal], Field(max_length=MAX_MODEL_POINTS)] | None = None
    labels: Annotated[list[Label], Field(max_length=MAX_MODEL_POINTS)] | None = None
    file: str | None = None

    @field_validator("normals", "labels")
    @classmethod
    def _one_per_point(cls, values: list | None, info: ValidationInfo) -> list | None:
        points = info.data.get("points")
        if values is not None and points is not None and len(values) != len(points):
            raise ValueError(f"expected one {info.field_name[:-1]} per point ({len(points)}), got {len(values)}")
        return values

    @model_validator(mode="after")
    def _points_or_file(self) -> "ModelSpec":
        if (self.points is None) == (self.file is None):
            raise ValueError("give either points or file")
        if self.file is not None and (self.normals is not None or self.labels is not None):
            raise ValueError("normals and labels come from the model file; leave them out")
        return self

    def to_model(self) -> Model:
        return Model(np.array(self.points), None if self.normals is None else np.array(self.normals),
                     None if self.labels is None else np.array(self.labels, np.int64))


class CameraSpec(Spec):
    """Intrinsics (pixels), optional plumb_bob distortion and optional ``world_from_camera`` pose."""

    fx: Annotated[float, Field(gt=0)]
    fy: Annotated[float, Field(gt=0)]
    cx: float
    cy: float
    width: Annotated[int, Field(gt=0)]
    height: Annotated[int, Field(gt=0)]
    distortion: Distortion | None = None
    world_from_camera: FullPoseSpec | None = None

    def to_camera(self) -> Camera:
        extrinsic = None if self.world_from_camera is None else self.world_from_camera.vector()
        return Camera.from_pose(self.fx, self.fy, self.cx, self.cy, self.width, self.height,
                                distortion=self.distortion, world_from_camera_pose=extrinsic)


class ViewSpec(Spec):
    """One camera's unordered image points (or an ``image`` file to extract them from) and its weight in eq. (4)."""

    camera: CameraSpec
    points: Annotated[list[Point2], Field(min_length=1, max_length=MAX_IMAGE_POINTS)] | None = None
    labels: Annotated[list[Label], Field(max_length=MAX_IMAGE_POINTS)] | None = None
    image: str | None = None
    weight: Annotated[float, Field(ge=0)] = 1.0

    @model_validator(mode="after")
    def _points_or_image(self) -> "ViewSpec":
        if (self.points is None) == (self.image is None):
            raise ValueError("give either points or image")
        if self.labels is not None and (self.points is None or len(self.labels) != len(self.points)):
            raise ValueError(f"labels: expected one per point ({0 if self.points is None else len(self.points)}), "
                             f"got {len(self.labels)}")
        return self

    def to_view(self) -> View:
        return View(self.camera.to_camera(), np.array(self.points), self.weight,
                    None if self.labels is None else np.array(self.labels, np.int64))


class SearchSpec(Spec):
    """The search box ``[lo, hi]`` per pose parameter; angles default to a full turn."""

    x: Range
    y: Range
    z: Range
    roll: Range = list(FULL_TURN)
    pitch: Range = list(FULL_TURN)
    yaw: Range = list(FULL_TURN)

    def to_bounds(self) -> Bounds:
        return Bounds.from_dict({name: tuple(getattr(self, name)) for name in PARAM_NAMES})


class ConstraintSpec(Spec):
    """Eq. (3): the parameter lies within ``value +- tolerance`` (tolerance 0 fixes it)."""

    value: float
    tolerance: Annotated[float, Field(ge=0)]


class ConstraintsSpec(Spec):
    """Constraints by pose parameter name."""

    x: ConstraintSpec | None = None
    y: ConstraintSpec | None = None
    z: ConstraintSpec | None = None
    roll: ConstraintSpec | None = None
    pitch: ConstraintSpec | None = None
    yaw: ConstraintSpec | None = None

    def given(self) -> dict[str, ConstraintSpec]:
        """The constraints present in the file, in parameter order."""
        return {name: c for name in PARAM_NAMES if (c := getattr(self, name)) is not None}


#: ``options``: any field of :class:`evopose.SearchOptions`, validated against its type annotation.
_OPTION_TYPES = typing.get_type_hints(SearchOptions)
OptionsSpec = create_model(
    "OptionsSpec", __base__=Spec, __doc__="Overrides of evopose.SearchOptions fields.",
    **{f.name: (_OPTION_TYPES[f.name], None) for f in dataclasses.fields(SearchOptions)},
)


class ProblemSpec(Spec):
    """A whole pose-problem file (docs/design.md §3)."""

    model: ModelSpec
    views: Annotated[list[ViewSpec], Field(min_length=1, max_length=MAX_VIEWS)]
    search: SearchSpec
    constraints: ConstraintsSpec = ConstraintsSpec()
    hints: Annotated[list[FullPoseSpec], Field(max_length=MAX_HINTS)] = []
    seed: Annotated[int, Field(ge=0)] | None = None
    options: OptionsSpec = OptionsSpec()

    @field_validator("views")
    @classmethod
    def _some_weight(cls, views: list[ViewSpec]) -> list[ViewSpec]:
        if not any(view.weight > 0 for view in views):
            raise ValueError("all view weights are 0; at least one must be > 0")
        return views


def _bounds(spec: ProblemSpec) -> Bounds:
    """The search box with the eq. (3) constraints applied."""
    bounds = spec.search.to_bounds()
    for name, constraint in spec.constraints.given().items():
        try:
            bounds = bounds.constrained(name, constraint.value, constraint.tolerance)
        except ValueError as err:
            raise ProblemFileError(f"constraints.{name}: {err}") from None
    return bounds


def _search_options(spec: ProblemSpec) -> SearchOptions:
    for name, limit in (("population", MAX_POPULATION), ("offspring", MAX_OFFSPRING), ("screening", MAX_SCREENING)):
        value = getattr(spec.options, name, None)
        if value is not None and value > limit:
            raise ProblemFileError(f"options.{name}: at most {limit}, got {value}")
    try:
        return SearchOptions(**spec.options.model_dump(exclude_unset=True))
    except ValueError as err:
        raise ProblemFileError(f"options: {err}") from None


@dataclasses.dataclass
class ProblemInputs:
    """A loaded problem with what it was made from: the images of image views and the target-model file."""

    problem: PoseProblem
    options: SearchOptions
    seed: int | None
    images: list[np.ndarray | None]
    target: TargetModel | None


def _model(spec: ProblemSpec, base: Path | None) -> tuple[Model, TargetModel | None]:
    if spec.model.file is None:
        return spec.model.to_model(), None
    try:
        target = load_model(resolve_model_path(spec.model.file, base))
    except WorldError as err:
        raise ProblemFileError(f"model.file: {err}") from None
    return target.evopose_model(), target


def _views(spec: ProblemSpec, base: Path | None, target: TargetModel | None):
    views, images = [], []
    for i, view in enumerate(spec.views):
        if view.image is None:
            views.append(view.to_view())
            images.append(None)
            continue
        path = Path(view.image)
        if base is not None and not path.is_absolute():
            path = base / path
        try:
            image = read_image(path)
        except WorldError as err:
            raise ProblemFileError(f"views[{i}].image: {err}") from None
        camera = view.camera.to_camera()
        if image.shape[:2] != (camera.height, camera.width):
            raise ProblemFileError(f"views[{i}].image: {path} is {image.shape[1]}x{image.shape[0]}, "
                                   f"the camera is {camera.width}x{camera.height}")
        marks = detect_marks(image, None if target is None else target.palette)
        if len(marks) == 0:
            raise ProblemFileError(f"views[{i}].image: no marks found in {path}")
        # with the model file's palette, a mark's label is its colour's index there: the model's own labels
        views.append(View(camera, marks.points, view.weight, None if target is None else marks.labels))
        images.append(image)
    return tuple(views), images


def parse_inputs(document: dict, base: str | Path | None = None) -> ProblemInputs:
    """Validate a problem-file mapping and build the evopose objects; paths are relative to ``base``.

    Raises
    ------
    ProblemFileError
        With one line naming the first offending field.
    """
    try:
        spec = ProblemSpec.model_validate(document)
    except ValidationError as err:
        raise ProblemFileError(validation_message(err)) from None
    base = None if base is None else Path(base)
    model, target = _model(spec, base)
    views, images = _views(spec, base, target)
    hints = np.array([hint.vector() for hint in spec.hints]).reshape(-1, 6)
    problem = PoseProblem(model, views, _bounds(spec), hints)
    return ProblemInputs(problem, _search_options(spec), spec.seed, images, target)


def parse_problem(document: dict, base: str | Path | None = None) -> tuple[PoseProblem, SearchOptions, int | None]:
    """Validate a problem-file mapping and build the evopose objects (see :func:`parse_inputs`).

    Returns
    -------
    problem : PoseProblem
    options : SearchOptions
    seed : int or None

    Raises
    ------
    ProblemFileError
        With one line naming the first offending field.
    """
    inputs = parse_inputs(document, base)
    return inputs.problem, inputs.options, inputs.seed


def read_problem(path: str | Path) -> ProblemInputs:
    """Read a YAML or JSON pose-problem file with its images; see :func:`parse_inputs`."""
    return parse_inputs(read_mapping(path, ProblemFileError), Path(path).parent)


def load_problem(path: str | Path) -> tuple[PoseProblem, SearchOptions, int | None]:
    """Read a YAML or JSON pose-problem file (docs/design.md §3); see :func:`parse_problem`.

    Raises
    ------
    ProblemFileError
        The file cannot be read, is not YAML/JSON, its top level is not a mapping, or a field is invalid.
    """
    inputs = read_problem(path)
    return inputs.problem, inputs.options, inputs.seed


def _pose_dict(pose: np.ndarray) -> dict[str, float]:
    return {name: float(v) for name, v in zip(PARAM_NAMES, pose)}


def problem_to_dict(problem: PoseProblem, constraints: dict[str, tuple[float, float]] | None = None,
                    seed: int | None = None) -> dict:
    """The problem-file mapping of ``problem`` (inverse of :func:`parse_problem`).

    Parameters
    ----------
    problem : PoseProblem
        Its bounds are written as the search box; angles spanning ``[-pi, pi]`` are left out (the default).
    constraints : dict name -> (value, tolerance), optional
        Eq. (3) constraints to write (applied when the file is loaded).
    seed : int, optional
    """
    model: dict[str, Any] = {"points": problem.model.points.tolist()}
    if problem.model.normals is not None:
        model["normals"] = problem.model.normals.tolist()
    if problem.model.labels is not None:
        model["labels"] = problem.model.labels.tolist()
    views = []
    for view in problem.views:
        cam = view.camera
        camera: dict[str, Any] = {"fx": float(cam.fx), "fy": float(cam.fy), "cx": float(cam.cx), "cy": float(cam.cy),
                                  "width": int(cam.width), "height": int(cam.height)}
        if np.any(cam.distortion):
            camera["distortion"] = cam.distortion.tolist()
        if not np.array_equal(cam.world_from_camera, np.eye(4)):
            camera["world_from_camera"] = _pose_dict(pose_from_matrix(cam.world_from_camera))
        entry: dict[str, Any] = {"camera": camera, "points": view.points.tolist()}
        if view.labels is not None:
            entry["labels"] = view.labels.tolist()
        if view.weight != 1.0:
            entry["weight"] = float(view.weight)
        views.append(entry)
    lo, hi = problem.bounds.lo, problem.bounds.hi
    search = {name: [float(lo[i]), float(hi[i])] for i, name in enumerate(PARAM_NAMES)
              if i < 3 or (lo[i], hi[i]) != FULL_TURN}
    out: dict[str, Any] = {"model": model, "views": views, "search": search}
    if constraints:
        out["constraints"] = {name: {"value": float(v), "tolerance": float(t)} for name, (v, t) in constraints.items()}
    if len(problem.hints):
        out["hints"] = [_pose_dict(h) for h in problem.hints]
    if seed is not None:
        out["seed"] = int(seed)
    return out


def solution_to_dict(solution: Solution) -> dict:
    """The solver's output object (docs/design.md §3), plus ``stop_reason``, ``view_terms`` and ``view_weights``.

    ``confident`` is the calibrated verdict (:attr:`evopose.Solution.confident`: the right basin), ``precise``
    whether the covariance places the pose within the target's own size (:attr:`evopose.Solution.precise`;
    a pose to act on is converged, confident and precise); ``covariance`` the 6x6
    covariance in the ROS ``PoseWithCovariance`` convention (docs/protocol.md, "Covariance"), row by row;
    an entry that is not finite (no covariance could be computed) is null, never NaN or Infinity.
    """
    pose = np.asarray(solution.pose, float)
    covariance = np.asarray(solution.covariance, float).reshape(6, 6)
    return {
        "pose": {**_pose_dict(pose), "quaternion": quaternion_from_euler(pose[3:]).tolist()},
        "fitness": float(solution.fitness),
        "generations": int(solution.generations),
        "evaluations": int(solution.evaluations),
        "seconds": float(solution.seconds),
        "converged": bool(solution.converged),
        "confident": bool(solution.confident),
        "precise": bool(solution.precise),
        "covariance": [[float(c) if math.isfinite(c) else None for c in row] for row in covariance.tolist()],
        "stop_reason": solution.stop_reason,
        "view_terms": np.asarray(solution.view_terms, float).tolist(),
        "view_weights": np.asarray(solution.view_weights, float).tolist(),
    }
