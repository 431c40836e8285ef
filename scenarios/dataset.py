"""Rendered datasets (docs/datasets.md): the directory a renderer writes and an agent reads.

```
DIR/
  manifest.yaml      # format, world, engine, frames, fps, cameras, camera_model, target_visible
  world.yaml         # the world document, ``extends`` resolved, target.model -> model.yaml
  model.yaml         # the target model file
  truth.jsonl        # one line per frame: target pose, per camera world_from_camera and the visible marks
  H1/camera_info.yaml, H1/poses.jsonl, H1/000000.jpg, ...
```

:class:`DatasetWriter` creates the directory and appends frames (a frame is complete when every camera has its
image and its poses line and the truth line is written; :meth:`DatasetWriter.complete_frames` tells how many are,
for resuming). :func:`open_dataset` reads one back as a :class:`Dataset`: the manifest, each frame's image, camera
(intrinsics and ``world_from_camera``) and truth, and the world.

Every file is read with a size bound (YAML through :func:`scenarios.documents.read_mapping`, JSON lines by
:func:`read_json_lines`), and every malformed input is one :class:`DatasetError` line naming the file, the line
(``truth.jsonl:4``) and the field.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
from pydantic import BaseModel

from evopose import Camera
from geometry import matrix_from_pose

from .camera_info_file import CameraInfoSpec, calibration_document
from .dataset_files import (CAMERA_INFO, FORMAT, FRAME_DIGITS, IMAGE_SUFFIXES, MANIFEST, MAX_POSES_BYTES,
                            MAX_POSES_LINE, MAX_TRUTH_BYTES, MAX_TRUTH_LINE, POSES, TRUTH, WORLD,
                            DatasetError, ManifestSpec, PosesLineSpec, TruthLineSpec, check_frame_numbers,
                            IMAGE_NAME, image_name, read_camera_info_file, read_json_lines)
from .dataset_writer import DatasetWriter
from .documents import read_mapping, validate
from .errors import WorldError
from .world import Scenario, load_scenario

T = TypeVar("T", bound=BaseModel)


# -- the reader -------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MarkTruth:
    index: int
    uv: tuple[float, float]
    colour: str
    fully_visible: bool


@dataclass(frozen=True)
class ViewTruth:
    """One camera's truth at a frame: its ``world_from_camera`` (6,) and the marks whose centre it sees."""

    world_from_camera: np.ndarray
    marks: tuple[MarkTruth, ...]


@dataclass(frozen=True)
class DatasetTruth:
    """A frame's truth: ``target_pose`` (``world_from_target``, (6,)), whether the target is in the images, and per
    camera its view."""

    frame: int
    time: float
    target_pose: np.ndarray
    target_visible: bool
    cameras: dict[str, ViewTruth]


class Dataset:
    """A dataset directory read back (see :func:`open_dataset`)."""

    def __init__(self, root: Path, manifest: ManifestSpec, intrinsics: dict[str, Camera],
                 poses: dict[str, np.ndarray], images: dict[str, list[Path]], truth: list[TruthLineSpec] | None):
        self.root, self.manifest = root, manifest
        self._intrinsics, self._poses, self._images, self._truth = intrinsics, poses, images, truth

    @property
    def cameras(self) -> tuple[str, ...]:
        return tuple(self.manifest.cameras)

    @property
    def frames(self) -> int:
        return self.manifest.frames

    @property
    def fps(self) -> float:
        return self.manifest.fps

    @property
    def name(self) -> str:
        return self.manifest.world

    @property
    def target_visible(self) -> bool:
        return self.manifest.target_visible

    @property
    def has_truth(self) -> bool:
        """Whether the dataset has its truth.jsonl (a recording without ground truth has none)."""
        return self._truth is not None

    def _check(self, camera: str | None, k: int) -> None:
        if camera is not None:
            if camera not in self._intrinsics:
                raise DatasetError(f"{self.root}: no camera {camera!r} (cameras: {', '.join(self.cameras)})")
        if not 0 <= k < self.frames:
            raise DatasetError(f"{self.root}: frame {k} out of range: the dataset has frames 0..{self.frames - 1}")

    def image_path(self, camera: str, k: int) -> Path:
        """Frame ``k``'s image of ``camera``."""
        self._check(camera, k)
        return self._images[camera][k]

    def image_paths(self, camera: str) -> list[Path]:
        """``camera``'s images in frame order."""
        self._check(camera, 0)
        return list(self._images[camera])

    def intrinsics(self, camera: str) -> Camera:
        """``camera``'s intrinsics (camera_info.yaml), identity ``world_from_camera``."""
        self._check(camera, 0)
        return self._intrinsics[camera]

    def world_from_camera(self, camera: str, k: int) -> np.ndarray:
        """``camera``'s ``world_from_camera`` at frame ``k`` (poses.jsonl), ``(x, y, z, roll, pitch, yaw)``."""
        self._check(camera, k)
        return self._poses[camera][k].copy()

    def camera(self, camera: str, k: int) -> Camera:
        """``camera`` at frame ``k``: its intrinsics with that frame's ``world_from_camera``."""
        c = self.intrinsics(camera)
        return Camera(c.fx, c.fy, c.cx, c.cy, c.width, c.height, c.distortion,
                      matrix_from_pose(self.world_from_camera(camera, k)))

    def truth(self, k: int) -> DatasetTruth | None:
        """Frame ``k``'s truth (None when the dataset has no truth.jsonl)."""
        self._check(None, k)
        if self._truth is None:
            return None
        line = self._truth[k]
        cameras = {name: ViewTruth(view.world_from_camera.vector(),
                                   tuple(MarkTruth(m.index, (m.uv[0], m.uv[1]), m.colour, m.fully_visible)
                                         for m in view.marks))
                   for name, view in line.cameras.items()}
        return DatasetTruth(line.frame, line.time, line.target_pose.vector(), line.target_visible, cameras)

    def world(self) -> Scenario:
        """The world the dataset was rendered from (world.yaml with model.yaml)."""
        path = self.root / WORLD
        if not path.is_file():
            raise DatasetError(f"{path}: the dataset has no world.yaml (give the world explicitly)")
        try:
            return load_scenario(path)
        except WorldError as err:
            raise DatasetError(str(err)) from None


def locate_dataset(path: str | Path) -> tuple[Path, str | None] | None:
    """Where a path is in a dataset: ``(root, None)`` for a dataset root (it has manifest.yaml), ``(root, camera)``
    for a camera's folder in one (its parent has manifest.yaml), None otherwise."""
    path = Path(path)
    if (path / MANIFEST).is_file():
        return path, None
    if path.is_dir() and (path.parent / MANIFEST).is_file():
        return path.parent, path.resolve().name
    return None


def _camera_images(folder: Path, frames: int) -> list[Path]:
    """Frame ``k``'s image for ``k`` in ``0..frames - 1``: exactly one ``{k:06d}.<image suffix>`` each."""
    found: dict[int, Path] = {}
    for entry in sorted(folder.iterdir()):
        match = IMAGE_NAME.fullmatch(entry.name)
        if match is None or entry.suffix.lower() not in IMAGE_SUFFIXES or not entry.is_file():
            continue
        k = int(match.group(1))
        if k in found:
            raise DatasetError(f"{folder}: two images of frame {k}: {found[k].name} and {entry.name}")
        found[k] = entry
    for k in range(frames):
        if k not in found:
            raise DatasetError(f"{folder}: no image of frame {k} ({k:0{FRAME_DIGITS}d}.jpg or another image "
                               f"suffix); the manifest says {frames} frames")
    return [found[k] for k in range(frames)]


def _lines_of(path: Path, schema: type[T], frames: int, max_bytes: int, max_line: int) -> list[T]:
    lines = read_json_lines(path, schema, max_bytes=max_bytes, max_line=max_line)
    check_frame_numbers(path, lines)
    if len(lines) != frames:
        raise DatasetError(f"{path}: {len(lines)} lines, the manifest says {frames} frames")
    return lines


def open_dataset(path: str | Path) -> Dataset:
    """Read a dataset directory (a camera's folder in it opens the whole dataset): the manifest, every camera's
    camera_info.yaml, poses.jsonl and images, and truth.jsonl when present.

    Raises
    ------
    DatasetError
        One line naming the file, the line and the field.
    """
    path = Path(path)
    where = locate_dataset(path)
    if where is None:
        kind = "no such directory" if not path.exists() else "not a dataset directory (no manifest.yaml)"
        raise DatasetError(f"{path}: {kind}")
    root = where[0]
    manifest = validate(ManifestSpec, read_mapping(root / MANIFEST, DatasetError), root / MANIFEST, DatasetError)
    intrinsics, poses, images = {}, {}, {}
    for camera in manifest.cameras:
        folder = root / camera
        if not folder.is_dir():
            raise DatasetError(f"{root / MANIFEST}: cameras: no folder {camera}/ for camera {camera!r}")
        intrinsics[camera] = read_camera_info_file(folder / CAMERA_INFO)
        lines = _lines_of(folder / POSES, PosesLineSpec, manifest.frames, MAX_POSES_BYTES, MAX_POSES_LINE)
        poses[camera] = np.array([line.world_from_camera.vector() for line in lines])
        images[camera] = _camera_images(folder, manifest.frames)
    truth = None
    if (root / TRUTH).exists():
        truth = _lines_of(root / TRUTH, TruthLineSpec, manifest.frames, MAX_TRUTH_BYTES, MAX_TRUTH_LINE)
        for n, line in enumerate(truth, 1):
            if sorted(line.cameras) != sorted(manifest.cameras):
                raise DatasetError(f"{root / TRUTH}:{n}: cameras: expected {', '.join(sorted(manifest.cameras))}, "
                                   f"got {', '.join(sorted(line.cameras)) or 'none'}")
    if where[1] is not None and where[1] not in manifest.cameras:
        raise DatasetError(f"{path}: not a camera of the dataset {root} (cameras: {', '.join(manifest.cameras)})")
    return Dataset(root, manifest, intrinsics, poses, images, truth)


__all__ = ["CameraInfoSpec", "Dataset", "DatasetError", "DatasetTruth", "DatasetWriter", "FORMAT",
           "IMAGE_SUFFIXES", "ManifestSpec", "MarkTruth", "PosesLineSpec", "TruthLineSpec", "ViewTruth", "calibration_document",
           "image_name", "locate_dataset", "open_dataset", "read_camera_info_file", "read_json_lines"]
