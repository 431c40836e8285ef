"""The world's clutter objects (``render.clutter``): their schema, shared by both renderers.

The OpenCV renderer draws them (:mod:`scenarios.clutter`) and the photoreal one builds them in Blender
(:mod:`scenarios.photoreal.shapes`); in both they hide the marks behind them, in the image and in the truth.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .documents import Strict

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
BGR = Annotated[list[Annotated[int, Field(ge=0, le=255)]], Field(min_length=3, max_length=3)]


class ClutterSpec(Strict):
    """An object lying about in the world (a bucket, a ball, a box, a lid), world frame, metres.

    ``centre`` is the object's centre; ``size`` a box's sides, or a cylinder's, disc's or sphere's diameters along
    x and y and its height (an elliptic cylinder, an ellipsoid); ``yaw`` a turn about the vertical through the
    centre; ``colour`` sRGB BGR; ``roughness`` its paint's (0 mirror, 1 matte) for the photoreal renderer.
    """

    shape: Literal["box", "cylinder", "sphere", "disc"]
    centre: Vec3
    size: Annotated[list[Annotated[float, Field(gt=0, le=100)]], Field(min_length=3, max_length=3)]
    colour: BGR
    roughness: Annotated[float, Field(ge=0, le=1)] = 0.5
    yaw: float = 0.0
