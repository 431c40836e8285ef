"""Writing a rendered dataset (docs/datasets.md): :class:`DatasetWriter` (the renderers' side; read back by
:func:`scenarios.dataset.open_dataset`)."""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np
import yaml
from pydantic import BaseModel

from evopose import Camera

from .camera_info_file import calibration_document
from .dataset_files import (CAMERA_INFO, FORMAT, FRAME_DIGITS, IMAGE_SUFFIXES, MANIFEST, MAX_POSES_BYTES,
                            MAX_POSES_LINE, MAX_TRUTH_BYTES, MAX_TRUTH_LINE, MODEL, POSES, TRUTH, WORLD, DatasetError,
                            ManifestSpec, MarkSpec, PosesLineSpec, TruthLineSpec, ViewTruthSpec,
                            check_camera, check_frame_numbers, dump_yaml, json_line, write_text,
                            image_name, read_json_lines)
from .documents import FullPoseSpec, StrictLoader, describe, read_mapping, validate
from .target import resolve_model_path
from .world import ScenarioSpec, build_scenario, load_scenario, read_world_document, resolve_scenario_path

T = TypeVar("T", bound=BaseModel)


def manifest_document(manifest: ManifestSpec) -> dict[str, Any]:
    """The manifest as written: the optional records of a look (``look``, ``developed_from``) only when set."""
    document = manifest.model_dump(mode="json")
    for key in ("look", "developed_from"):
        if document.get(key) is None:
            document.pop(key, None)
    return document


class DatasetWriter:
    """Writes a dataset directory (docs/datasets.md) for a world: the fixed files at once, then frame by frame.

    Parameters
    ----------
    root : path
        The dataset directory; created. An existing non-empty one is an error unless ``resume``.
    world : str or path
        A world file or a shipped world's name, as ``evopose render WORLD`` takes it.
    engine : mapping
        ``{"name": "cycles" | "opencv", ...settings}``, recorded in the manifest.
    frames, fps : the dataset's frame count and rate (default: the world's); world.yaml gets them too, so the
        world the dataset carries has the dataset's frames.
    cameras : the vehicles whose cameras are rendered (default: every vehicle of the world).
    camera_model : the camera model as applied (the world's ``render.camera_model``), recorded in the manifest.
    target_visible : False for a dataset rendered without the target.
    intrinsics : per camera, a camera whose intrinsics replace the world's in its camera_info.yaml.
    look : the named look the images are developed with (recorded in the manifest).
    world_camera_model : replaces the world document's ``render.camera_model`` in world.yaml (a look's camera model:
        the dataset's world then carries the camera its images were taken with).
    resume : continue an existing dataset of the same manifest and world: the frames after the last complete one
        are cut from the JSON-lines files (:attr:`next_frame` is where to go on).

    Attributes
    ----------
    scenario : Scenario
        The world as the dataset's reader will load it (from the written world.yaml and model.yaml): render it.
    manifest : ManifestSpec
    next_frame : int
        The first frame not yet complete.

    A frame is complete when each camera has its image and its poses line and the truth line is written; write a
    frame's images and poses first and its truth line last (:meth:`add_frame` does).
    """

    def __init__(self, root: str | Path, world: str | Path, *, engine: Mapping[str, Any],
                 frames: int | None = None, fps: float | None = None, cameras: Sequence[str] | None = None,
                 camera_model: Mapping[str, Any] | None = None, target_visible: bool = True,
                 intrinsics: Mapping[str, Camera] | None = None, resume: bool = False, look: str | None = None,
                 world_camera_model: Mapping[str, Any] | None = None) -> None:
        self.root = Path(root)
        world_path = resolve_scenario_path(world)
        document = read_world_document(world_path)
        spec = validate(ScenarioSpec, document, world_path, DatasetError)
        scenario = build_scenario(spec, world_path.parent, world_path)
        names = [v.name for v in scenario.vehicles]
        cameras = list(names if cameras is None else cameras)
        for camera in cameras:
            if camera not in names:
                raise DatasetError(f"{world_path}: no vehicle {camera!r} to render (vehicles: {', '.join(names)})")
        self.manifest = validate(ManifestSpec, {
            "format": FORMAT, "world": spec.name, "engine": dict(engine),
            "frames": spec.frames if frames is None else frames, "fps": spec.fps if fps is None else fps,
            "cameras": cameras, "camera_model": None if camera_model is None else dict(camera_model),
            "target_visible": target_visible, "look": look}, self.root / MANIFEST, DatasetError)
        model_path = resolve_model_path(spec.target.model, world_path.parent)
        world_doc = {**document, "frames": self.manifest.frames, "fps": self.manifest.fps,
                     "target": {**document["target"], "model": MODEL}}
        if world_camera_model is not None:
            world_doc["render"] = {**(document.get("render") or {}), "camera_model": dict(world_camera_model)}
        camera_infos = {}
        for camera in cameras:
            k = (intrinsics or {}).get(camera) or scenario.vehicle(camera).camera_at(0.0)
            camera_infos[camera] = calibration_document(k, camera)
        if resume and (self.root / MANIFEST).exists():
            self._check_same(world_doc)
        else:
            if self.root.exists() and (not self.root.is_dir() or any(self.root.iterdir())):
                raise DatasetError(f"{self.root}: exists and is not an empty directory (resume to continue it)")
            self.root.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(model_path, self.root / MODEL)
            write_text(self.root / WORLD, dump_yaml(world_doc))
            for camera in cameras:
                (self.root / camera).mkdir(exist_ok=True)
                write_text(self.root / camera / CAMERA_INFO, dump_yaml(camera_infos[camera]))
            write_text(self.root / MANIFEST, dump_yaml(manifest_document(self.manifest)))
        self.scenario = load_scenario(self.root / WORLD)
        self.next_frame = self._cut_to_complete()
        self._poses_next = {c: self.next_frame for c in cameras}

    @property
    def cameras(self) -> list[str]:
        return list(self.manifest.cameras)

    @property
    def frames(self) -> int:
        return self.manifest.frames

    def _check_same(self, world_doc: dict) -> None:
        """Resuming: the existing manifest and world must be the ones this writer would write."""
        old = validate(ManifestSpec, read_mapping(self.root / MANIFEST, DatasetError), self.root / MANIFEST,
                       DatasetError).model_dump(mode="json")
        new = self.manifest.model_dump(mode="json")
        for key in new:
            if old.get(key) != new[key]:
                raise DatasetError(f"{self.root / MANIFEST}: {key}: the dataset has {describe(old.get(key))}, "
                                   f"resuming would write {describe(new[key])} (start a new dataset)")
        written = yaml.load(dump_yaml(world_doc), Loader=StrictLoader)  # noqa: S506 - a SafeLoader subclass
        if read_mapping(self.root / WORLD, DatasetError) != written:
            raise DatasetError(f"{self.root / WORLD}: differs from the world being rendered (start a new dataset)")

    # -- paths and state

    def image_path(self, camera: str, k: int, suffix: str = ".jpg") -> Path:
        """Where frame ``k``'s image of ``camera`` goes: ``DIR/<camera>/<k:06d><suffix>``."""
        check_camera(camera, self.manifest.cameras)
        return self.root / camera / image_name(k, suffix)

    def _lines(self, path: Path, schema: type[T], max_bytes: int, max_line: int) -> list[T]:
        if not path.exists():
            return []
        lines = read_json_lines(path, schema, max_bytes=max_bytes, max_line=max_line, complete_only=True)
        check_frame_numbers(path, lines)
        return lines

    def _has_image(self, camera: str, k: int) -> bool:
        return any((self.root / camera / f"{k:0{FRAME_DIGITS}d}{s}").is_file() for s in IMAGE_SUFFIXES)

    def complete_frames(self) -> int:
        """How many frames, from frame 0 on, are complete (every camera's image and poses line, and the truth line)."""
        n = len(self._lines(self.root / TRUTH, TruthLineSpec, MAX_TRUTH_BYTES, MAX_TRUTH_LINE))
        for camera in self.manifest.cameras:
            n = min(n, len(self._lines(self.root / camera / POSES, PosesLineSpec, MAX_POSES_BYTES, MAX_POSES_LINE)))
        for k in range(n):
            if not all(self._has_image(camera, k) for camera in self.manifest.cameras):
                return k
        return n

    def _cut_to_complete(self) -> int:
        """Cut the JSON-lines files to the complete frames (a resumed run appends after them); their count."""
        n = self.complete_frames()
        for path in [self.root / TRUTH, *(self.root / c / POSES for c in self.manifest.cameras)]:
            if path.exists():
                with open(path, "rb") as f:
                    keep = b"".join(f.readlines()[:n])
                with open(path, "wb") as f:
                    f.write(keep)
        return n

    @property
    def done(self) -> bool:
        return self.next_frame >= self.manifest.frames

    # -- appending

    def write_image(self, camera: str, k: int, image: np.ndarray, suffix: str = ".jpg", *,
                    jpeg_quality: int = 95) -> Path:
        """Write frame ``k``'s image of ``camera`` (BGR uint8) with OpenCV (JPEG 4:2:0 at ``jpeg_quality``, or the
        format of ``suffix``), through a temporary file; returns its path."""
        path = self.image_path(camera, k, suffix)
        tmp = path.with_name(f".tmp-{path.name}")
        params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)] if suffix.lower() in (".jpg", ".jpeg") else []
        if suffix.lower() in (".jpg", ".jpeg") and hasattr(cv2, "IMWRITE_JPEG_SAMPLING_FACTOR"):
            params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
        if not cv2.imwrite(str(tmp), image, params):
            raise DatasetError(f"{path}: OpenCV could not write the image")
        os.replace(tmp, path)
        return path

    def append_pose(self, camera: str, k: int, world_from_camera: np.ndarray) -> None:
        """Append frame ``k``'s ``world_from_camera`` (a pose (6,) or a transform (4, 4)) to ``camera``'s poses.jsonl;
        frames go in order."""
        check_camera(camera, self.manifest.cameras)
        if k != self._poses_next[camera]:
            raise DatasetError(f"{self.root / camera / POSES}: frame {k} out of order: frame "
                               f"{self._poses_next[camera]} is next")
        line = PosesLineSpec(frame=k, world_from_camera=FullPoseSpec.of(world_from_camera))
        with open(self.root / camera / POSES, "a", encoding="utf-8") as f:
            f.write(json_line(line))
        self._poses_next[camera] = k + 1

    def append_truth(self, k: int, target_pose: np.ndarray, views: Mapping[str, Any], *,
                     time: float | None = None, target_visible: bool | None = None) -> None:
        """Append frame ``k``'s truth line: the target pose (6,), and per camera a view with ``camera_pose``
        (``world_from_camera`` (6,)) and the visible marks as :class:`scenarios.render.FrameTruth` has them
        (``mark_index``, ``mark_uv``, ``mark_colour``, ``fully_visible``). It completes the frame: the cameras'
        images and poses lines must be written first."""
        if k != self.next_frame or k >= self.manifest.frames:
            raise DatasetError(f"{self.root / TRUTH}: frame {k} out of order: frame {self.next_frame} is next "
                               f"(of {self.manifest.frames})")
        if sorted(views) != sorted(self.manifest.cameras):
            raise DatasetError(f"{self.root / TRUTH}: frame {k}: views of {', '.join(sorted(views)) or 'no camera'}, "
                               f"the dataset's cameras are {', '.join(self.manifest.cameras)}")
        for camera in self.manifest.cameras:
            if self._poses_next[camera] <= k or not self._has_image(camera, k):
                raise DatasetError(f"{self.root / camera}: frame {k}: write the image and the poses line before the "
                                   "truth line")
        cameras = {}
        for camera in self.manifest.cameras:
            view = views[camera]
            marks = [MarkSpec(index=int(i), uv=[float(uv[0]), float(uv[1])], colour=str(c), fully_visible=bool(f))
                     for i, uv, c, f in zip(view.mark_index, view.mark_uv, view.mark_colour, view.fully_visible)]
            cameras[camera] = ViewTruthSpec(world_from_camera=FullPoseSpec.of(view.camera_pose), marks=marks)
        line = TruthLineSpec(frame=k, time=k / self.manifest.fps if time is None else float(time),
                             target_pose=FullPoseSpec.of(target_pose),
                             target_visible=self.manifest.target_visible if target_visible is None else target_visible,
                             cameras=cameras)
        with open(self.root / TRUTH, "a", encoding="utf-8") as f:
            f.write(json_line(line))
        self.next_frame = k + 1

    def add_frame(self, k: int, rendered: Mapping[str, Any], suffix: str = ".jpg", **image_options: Any) -> None:
        """Write a whole frame from each camera's rendered frame (``image``, ``camera``, ``truth`` as
        :class:`scenarios.render.RenderedFrame`): images, poses lines (``camera.world_from_camera``), then the truth
        line (the target pose and the marks of ``truth``)."""
        for camera in self.manifest.cameras:
            frame = rendered[camera]
            self.write_image(camera, k, frame.image, suffix, **image_options)
            self.append_pose(camera, k, frame.camera.world_from_camera)
        first = rendered[self.manifest.cameras[0]].truth
        self.append_truth(k, first.target_pose, {c: rendered[c].truth for c in self.manifest.cameras},
                          time=first.time)


__all__ = ["DatasetWriter"]
