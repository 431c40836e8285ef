"""Target models with their coloured feature marks, loaded from YAML files (``scenarios/models/*.yaml``).

A model file gives, in the target frame (metres; x forward, y left, z up):

```yaml
name: pioneer-2dx
mark_radius: 0.03                   # radius of every mark disc, metres
mark_roughness: 0.35                # optional: the marks' paint roughness (photoreal renderer)
colours: {yellow: [0, 220, 240]}    # mark colour name -> BGR 0-255
parts:                              # the body, for drawing and self-occlusion
  - {box: {centre: [0, 0, 0.13], size: [0.44, 0.32, 0.18]}, colour: [40, 40, 120], roughness: 0.45}
  - {ellipsoid: {centre: [0, 0, 0], semi_axes: [0.9, 0.3, 0.3], segments: [24, 12]}, colour: [230, 230, 230]}
  - {polygon: [[x, y, z], ...], colour: [...], two_sided: true}
marks:                              # the features EvoPose matches
  - {position: [0.1, 0.0, 0.22], normal: [0, 0, 1], colour: yellow}
motion: {speed: 0.5, climb: 0.05, tilt: 0.05, turn: 0.5}   # optional: 1-sigma rates, m/s and rad/s
good_within: {rotation_deg: 5.0}    # optional: a good published pose lies within this at two sigmas
```

``motion`` is what the target can do between two frames, for the tracking gate
(:class:`evopose.uncertainty.TrackReference`): 1-sigma rates of horizontal speed, vertical speed, tilt (turning
about a horizontal axis) and turn (about the vertical). Without it the gate allows 0.1 m and 0.1 rad per frame on
every axis (:class:`evopose.trust.ConfidenceRules`).

``good_within`` is what the target's user calls right: a vehicle publishes its track (:mod:`evopose.pose_filter`)
as good only once the track knows its rotation to half of ``rotation_deg`` (1 sigma), so that a good pose lies
within it at two sigmas (``ConfidenceRules.max_published_rotation_sigma``). Without it any track a precise frame
joined is good.

:func:`load_model` validates the file (one-line errors naming the field) and returns a :class:`TargetModel`.
"""

from __future__ import annotations

from functools import cached_property

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field, field_validator, model_validator

from evopose import Model
from evopose.trust import ConfidenceRules

from .documents import Strict, read_mapping, validate
from .errors import ModelFileError
from .mesh import Mesh, box_mesh, ellipsoid_mesh, polygon_mesh

#: Directory of the shipped models (``pioneer.yaml``, ``airship.yaml``).
MODELS_DIR = Path(__file__).resolve().parent / "models"

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
BGR = Annotated[list[Annotated[int, Field(ge=0, le=255)]], Field(min_length=3, max_length=3)]


class BoxSpec(Strict):
    centre: Vec3
    size: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=3, max_length=3)]


class EllipsoidSpec(Strict):
    centre: Vec3
    semi_axes: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=3, max_length=3)]
    segments: Annotated[list[Annotated[int, Field(ge=3, le=128)]], Field(min_length=2, max_length=2)] = [24, 12]


class PartSpec(Strict):
    """One body part: exactly one of ``box``, ``ellipsoid``, ``polygon``."""

    box: BoxSpec | None = None
    ellipsoid: EllipsoidSpec | None = None
    polygon: Annotated[list[Vec3], Field(min_length=3)] | None = None
    colour: BGR
    two_sided: bool = True
    #: Paint roughness (0 mirror, 1 matte) for a physically based renderer (:mod:`scenarios.photoreal`).
    roughness: Annotated[float, Field(ge=0, le=1)] = 0.45

    @model_validator(mode="after")
    def _one_shape(self) -> "PartSpec":
        given = [k for k in ("box", "ellipsoid", "polygon") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"a part needs exactly one of box, ellipsoid, polygon; got {given or 'none'}")
        return self

    def mesh(self) -> Mesh:
        if self.box is not None:
            return box_mesh(self.box.centre, self.box.size, tuple(self.colour))
        if self.ellipsoid is not None:
            e = self.ellipsoid
            return ellipsoid_mesh(e.centre, e.semi_axes, tuple(self.colour), tuple(e.segments))
        return polygon_mesh(self.polygon, tuple(self.colour), self.two_sided)


class MarkSpec(Strict):
    position: Vec3
    normal: Vec3
    colour: str

    @field_validator("normal")
    @classmethod
    def _non_zero(cls, n: list[float]) -> list[float]:
        if float(np.linalg.norm(n)) < 1e-9:
            raise ValueError("a normal must be a non-zero vector")
        return n


class MotionSpec(Strict):
    """The target's 1-sigma rates between frames: metres per second horizontally and vertically, radians per
    second about a horizontal axis (tilt) and about the vertical (turn)."""

    speed: Annotated[float, Field(gt=0)]
    climb: Annotated[float, Field(gt=0)]
    tilt: Annotated[float, Field(gt=0)]
    turn: Annotated[float, Field(gt=0)]

    def per_frame(self, period_s: float) -> tuple[float, float, float, float, float, float]:
        """The 1-sigma change per frame of ``period_s`` seconds, in the covariance's coordinates (x, y, z, then
        rotations about the fixed X, Y, Z axes): :attr:`evopose.trust.ConfidenceRules.track_motion`."""
        s = float(period_s)
        return (self.speed * s, self.speed * s, self.climb * s, self.tilt * s, self.tilt * s, self.turn * s)


class GoodWithinSpec(Strict):
    """How close to the truth a good published pose must lie, at two sigmas: its worst rotation axis, degrees."""

    rotation_deg: Annotated[float, Field(gt=0, le=180)]


class ModelFileSpec(Strict):
    name: str
    description: str = ""
    mark_radius: Annotated[float, Field(gt=0, le=1)]
    #: Roughness of the marks' paint (0 mirror, 1 matte), for a physically based renderer.
    mark_roughness: Annotated[float, Field(ge=0, le=1)] = 0.35
    colours: Annotated[dict[str, BGR], Field(min_length=1)]
    parts: list[PartSpec] = []
    marks: Annotated[list[MarkSpec], Field(min_length=1)]
    motion: MotionSpec | None = None
    good_within: GoodWithinSpec | None = None

    @model_validator(mode="after")
    def _known_colours(self) -> "ModelFileSpec":
        for i, mark in enumerate(self.marks):
            if mark.colour not in self.colours:
                raise ValueError(f"marks[{i}].colour: unknown colour {mark.colour!r} "
                                 f"(colours: {', '.join(self.colours)})")
        return self


@dataclass(frozen=True, eq=False)
class TargetModel:
    """A target: its marks (the features) and its body (for drawing and self-occlusion), target frame.

    Attributes
    ----------
    name : str
    mark_points : array, shape (M, 3)
        Mark centres, metres.
    mark_normals : array, shape (M, 3)
        Unit outward normals of the marks.
    mark_colours : tuple of str, length M
        Colour name of each mark (key of ``palette``).
    palette : dict str -> (B, G, R)
    mark_radius : float
        Metres.
    body : Mesh
    motion : MotionSpec or None
        What the target can do between frames (1-sigma rates), for the tracking gate; None: the gate's default.
    good_within : GoodWithinSpec or None
        How close a good published pose lies at two sigmas; None: any track a precise frame joined is good.
    """

    name: str
    mark_points: np.ndarray
    mark_normals: np.ndarray
    mark_colours: tuple[str, ...]
    palette: dict[str, tuple[int, int, int]]
    mark_radius: float
    body: Mesh
    description: str = ""
    #: The body's parts as in the file (shapes, colours, roughness), for a physically based renderer.
    parts: tuple[PartSpec, ...] = ()
    mark_roughness: float = 0.35
    motion: MotionSpec | None = None
    good_within: GoodWithinSpec | None = None

    def confidence_rules(self, period_s: float) -> ConfidenceRules:
        """The confidence rules for this target filmed every ``period_s`` s: the tracking gate's motion allowance
        from ``motion`` (:meth:`MotionSpec.per_frame`) and the published track's rotation sigma from
        ``good_within`` (half its rotation: two sigmas), the defaults without them."""
        rules = ConfidenceRules()
        if self.motion is not None:
            rules = replace(rules, track_motion=self.motion.per_frame(period_s))
        if self.good_within is not None:
            rules = replace(rules, max_published_rotation_sigma=float(np.deg2rad(self.good_within.rotation_deg)) / 2)
        return rules

    @property
    def size(self) -> float:
        """Largest extent of the body (or the marks), metres."""
        pts = self.body.vertices if len(self.body.vertices) else self.mark_points
        return float(np.max(np.ptp(pts, axis=0)))

    @cached_property
    def body_colour(self) -> tuple[int, int, int] | None:
        """The colour (BGR) covering most of the body's surface, or None without a body: the paint a camera sees
        around the marks (the contrast front-end's context, :func:`vision.blobs.detect_contrast_marks`). Computed
        once per model (the second robot's mesh took ~90 ms, and the front-end's callers read it per image)."""
        if not len(self.body):
            return None
        area: dict[tuple[int, int, int], float] = {}
        for face, colour in zip(self.body.faces, self.body.colours):
            p = self.body.vertices[face]
            # a convex planar polygon's area: half the norm of the sum of its fan's cross products
            a = 0.5 * float(np.linalg.norm(np.cross(p[1:-1] - p[0], p[2:] - p[0]).sum(axis=0)))
            key = tuple(int(c) for c in colour)
            area[key] = area.get(key, 0.0) + a
        return max(area, key=area.get)

    def evopose_model(self) -> Model:
        """The marks as an :class:`evopose.Model` for the solver: points, normals, and each mark's colour as its
        label (:meth:`colour_labels`; used by views whose points carry colour labels too)."""
        return Model(self.mark_points.copy(), self.mark_normals.copy(), self.colour_labels())

    def colour_labels(self) -> np.ndarray:
        """Index of each mark's colour in ``palette`` order, shape (M,)."""
        names = list(self.palette)
        return np.array([names.index(c) for c in self.mark_colours])


def model_from_spec(spec: ModelFileSpec) -> TargetModel:
    normals = np.array([m.normal for m in spec.marks], float)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    body = Mesh.empty()
    for part in spec.parts:
        body = body + part.mesh()
    return TargetModel(spec.name, np.array([m.position for m in spec.marks], float), normals,
                       tuple(m.colour for m in spec.marks), {k: tuple(v) for k, v in spec.colours.items()},
                       spec.mark_radius, body, spec.description, tuple(spec.parts), spec.mark_roughness,
                       spec.motion, spec.good_within)


def resolve_model_path(name_or_path: str | Path, base: Path | None = None) -> Path:
    """A model reference: a path (relative to ``base``) or the name of a shipped model (``pioneer``, ``airship``)."""
    p = Path(name_or_path)
    if base is not None and not p.is_absolute() and (base / p).exists():
        return base / p
    if p.exists():
        return p
    shipped = MODELS_DIR / (p.name if p.suffix else f"{p.name}.yaml")
    return shipped if shipped.exists() else (base / p if base is not None and not p.is_absolute() else p)


def load_model(path: str | Path) -> TargetModel:
    """Read and validate a target-model file.

    Raises
    ------
    ModelFileError
        One line naming the file and the offending field.
    """
    path = resolve_model_path(path)
    document = read_mapping(path, ModelFileError)
    return model_from_spec(validate(ModelFileSpec, document, path, ModelFileError))
