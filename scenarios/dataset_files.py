"""The files of a rendered dataset (docs/datasets.md): their schemas, the camera_info format, bounded JSON-lines
reading, and :class:`DatasetError`. The writer is :mod:`scenarios.dataset_writer`, the reader :mod:`scenarios.dataset`.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator

from evopose import Camera

from .camera_info_file import CameraInfoSpec
from .documents import (MAX_DEPTH, FullPoseSpec, Strict, json_depth_ok, json_object, no_constant, describe, one_line,
                        read_bytes, read_mapping, validate)
from .errors import WorldError

T = TypeVar("T", bound=BaseModel)

#: The layout's version (``manifest.yaml``'s ``format``).
FORMAT = "evopose-dataset/1"
MANIFEST, WORLD, MODEL, TRUTH = "manifest.yaml", "world.yaml", "model.yaml", "truth.jsonl"
CAMERA_INFO, POSES = "camera_info.yaml", "poses.jsonl"
#: Image files a camera folder may hold (by suffix, lower case); frame ``k`` is ``{k:06d}<suffix>``.
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".webp")
#: Digits of an image's frame number.
FRAME_DIGITS = 6
#: Most frames a dataset may have (frame numbers have :data:`FRAME_DIGITS` digits).
MAX_FRAMES = 10 ** FRAME_DIGITS - 1
#: Most cameras a dataset may have.
MAX_CAMERAS = 64
#: Most marks a camera's truth may list in one frame.
MAX_MARKS = 10_000
#: Largest ``truth.jsonl`` and ``poses.jsonl`` read, bytes; longest line of each.
MAX_TRUTH_BYTES, MAX_TRUTH_LINE = 256 * 1024 * 1024, 2 * 1024 * 1024
MAX_POSES_BYTES, MAX_POSES_LINE = 64 * 1024 * 1024, 4096
#: A camera (vehicle) name: a folder name, as the fleet's vehicle names (protocol.keys).
CAMERA_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}")
IMAGE_NAME = re.compile(rf"(\d{{{FRAME_DIGITS}}})(\.[A-Za-z]+)")


class DatasetError(WorldError):
    """A dataset directory that cannot be written or read; one line naming the file, the line and the field."""


# -- the schemas ----------------------------------------------------------------------------------------------

CameraName = Annotated[str, Field(pattern=rf"^{CAMERA_NAME.pattern}$")]


class EngineSpec(Strict):
    """The renderer that wrote the dataset: its ``name`` and its settings (``samples``, ``blender``, any other
    setting the engine records; they are kept as written)."""

    model_config = ConfigDict(extra="allow", allow_inf_nan=False, frozen=True)

    name: Literal["cycles", "opencv"]


class ManifestSpec(Strict):
    """``manifest.yaml``."""

    format: Literal["evopose-dataset/1"]
    world: Annotated[str, Field(min_length=1)]
    engine: EngineSpec
    frames: Annotated[int, Field(ge=1, le=MAX_FRAMES)]
    fps: Annotated[float, Field(gt=0)]
    cameras: Annotated[list[CameraName], Field(min_length=1, max_length=MAX_CAMERAS)]
    camera_model: dict[str, Any] | None = None
    target_visible: bool = True
    #: The named look the images were developed with (scenarios/looks.py; ``custom`` for a mapping of fields).
    look: Annotated[str, Field(min_length=1, max_length=200)] | None = None
    #: A dataset developed again from another's raw EXRs (``evopose develop``): that dataset's directory.
    developed_from: Annotated[str, Field(min_length=1, max_length=4096)] | None = None

    @field_validator("cameras")
    @classmethod
    def _unique(cls, cameras: list[str]) -> list[str]:
        repeated = sorted({c for c in cameras if cameras.count(c) > 1})
        if repeated:
            raise ValueError(f"camera names must be unique; repeated: {', '.join(repeated)}")
        return cameras


class MarkSpec(Strict):
    """A mark whose centre is visible: model index, projected centre (pixels), colour name, whole disc visible."""

    index: Annotated[int, Field(ge=0)]
    uv: Annotated[list[float], Field(min_length=2, max_length=2)]
    colour: str
    fully_visible: bool


class ViewTruthSpec(Strict):
    world_from_camera: FullPoseSpec
    marks: Annotated[list[MarkSpec], Field(max_length=MAX_MARKS)] = []


class TruthLineSpec(Strict):
    """A line of ``truth.jsonl``."""

    frame: Annotated[int, Field(ge=0)]
    time: Annotated[float, Field(ge=0)]
    target_pose: FullPoseSpec
    target_visible: bool
    cameras: Annotated[dict[CameraName, ViewTruthSpec], Field(max_length=MAX_CAMERAS)]


class PosesLineSpec(Strict):
    """A line of a camera's ``poses.jsonl``."""

    frame: Annotated[int, Field(ge=0)]
    world_from_camera: FullPoseSpec


def read_camera_info_file(path: Path) -> Camera:
    """The intrinsics of a dataset camera's ``camera_info.yaml`` (identity ``world_from_camera``)."""
    return validate(CameraInfoSpec, read_mapping(path, DatasetError), path, DatasetError).to_camera()


# -- JSON lines -------------------------------------------------------------------------------------------------


def read_json_lines(path: Path, schema: type[T], *, max_bytes: int, max_line: int,
                    complete_only: bool = False) -> list[T]:
    """The lines of a JSON-lines file validated by ``schema``, read with a size bound (the file, each line).

    A line that is not one JSON object or does not fit ``schema`` raises :class:`DatasetError`
    (``<file>:<line>: <field>: <problem>``). With ``complete_only`` a last line without its newline (a write cut
    short) is left out instead.
    """
    data = read_bytes(path, DatasetError, max_bytes)
    lines = data.split(b"\n")
    tail = lines.pop()  # after the last newline: b"" when the file ends with one
    if tail and not complete_only:
        lines.append(tail)
    out = []
    for n, raw in enumerate(lines, 1):
        where = f"{path}:{n}"
        if len(raw) > max_line:
            raise DatasetError(f"{where}: line is {len(raw)} bytes, more than the limit of {max_line}")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise DatasetError(f"{where}: not UTF-8 text") from None
        if not text.strip():
            raise DatasetError(f"{where}: empty line (expected one JSON object)")
        if not json_depth_ok(text):
            raise DatasetError(f"{where}: invalid JSON: nesting deeper than {MAX_DEPTH} levels")
        try:
            document = json.loads(text, object_pairs_hook=json_object, parse_constant=no_constant)
        except json.JSONDecodeError as err:
            raise DatasetError(f"{where}:{err.colno}: invalid JSON: {err.msg}") from None
        except (ValueError, RecursionError) as err:
            raise DatasetError(f"{where}: invalid JSON: {one_line(err)}") from None
        if not isinstance(document, dict):
            raise DatasetError(f"{where}: expected a JSON object, got {describe(document)}")
        out.append(validate(schema, document, where, DatasetError))
    return out


def check_frame_numbers(path: Path, lines: Sequence[Any]) -> None:
    """Line ``n`` (1-based) must be frame ``n - 1``."""
    for n, line in enumerate(lines, 1):
        if line.frame != n - 1:
            raise DatasetError(f"{path}:{n}: frame: expected {n - 1} (frames in order from 0), got {line.frame}")


def json_line(model: BaseModel) -> str:
    return json.dumps(model.model_dump(mode="json"), separators=(",", ":"), allow_nan=False) + "\n"


def dump_yaml(document: Any) -> str:
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=120)


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file (a reader never sees half a file)."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)




def check_camera(camera: str, cameras: Sequence[str]) -> None:
    if camera not in cameras:
        raise DatasetError(f"no camera {camera!r} in the dataset (cameras: {', '.join(cameras)})")


def image_name(k: int, suffix: str) -> str:
    """``000042.jpg``: the file name of frame ``k``'s image."""
    if not 0 <= k <= MAX_FRAMES:
        raise DatasetError(f"frame {k} out of range 0..{MAX_FRAMES}")
    if suffix.lower() not in IMAGE_SUFFIXES:
        raise DatasetError(f"image suffix {suffix!r} is not one of {', '.join(IMAGE_SUFFIXES)}")
    return f"{k:0{FRAME_DIGITS}d}{suffix}"
