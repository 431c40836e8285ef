"""``--source DIR`` on a rendered dataset (docs/datasets.md): a camera vehicle plays one camera's images.

``DIR`` is a dataset's root (the camera is ``--vehicle``'s folder) or one camera's folder in it. The camera of
frame ``k`` is the dataset's: the intrinsics of the camera's camera_info.yaml and the ``world_from_camera`` of its
poses.jsonl line ``k``, unless ``--camera-info`` / ``--camera-pose`` replace them. When the dataset has its
truth.jsonl, each frame carries the target's true pose (``Frame.truth``), so the agent's frame records and summary
carry errors exactly as on the renderer; on a dataset rendered without the target (``target_visible: false``) the
truth is None (nothing to be right about), and every frame the agent marks good is a false positive (the summary's
``false_positives``). The world (the target model, the search box) is the dataset's world.yaml unless
``--scenario`` names one (:func:`dataset_world`).

A dataset is a recording: its frame ``k`` was taken at its own instant, whichever fleet tick a vehicle gets to it
at. A vehicle plays one frame per frame processed (a slow one falls behind, it skips nothing), and stamps frame
``k`` with the fleet clock's stamp of the tick it was taken at: tick ``k`` when the fleet has a common clock
(``--epoch-ns``, which a scenario run sets: frame 0 of the run is frame 0 of the dataset), else the vehicle's first
tick plus ``k``. So team-mates playing the same dataset stamp the same instant alike, and their views of it pair
(eq. 4) even when one is late: a view is never paired with a team-mate's view of another instant of the recording.
A team that plays slower than the recording was taken falls behind the wall clock; a team-mate's data are judged
stale at the instant the vehicle plays (:class:`agents.transport.playback.PlaybackClock`), not on the wall
clock, where after a second behind every view of the very instant played would be refused.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from evopose import Camera
from geometry import matrix_from_pose, pose_from_matrix
from scenarios.dataset import Dataset, locate_dataset, open_dataset
from scenarios.world import Scenario

from vision.extract import FeatureExtractor
from agents.vehicle.frames import Frame, FrameClock
from agents.vehicle.sources import FileListReader, SourceCamera, SourceError


def dataset_location(source: str | None) -> tuple[Path, str | None] | None:
    """``(root, camera folder or None)`` when ``--source`` is a dataset or a camera's folder in one, else None."""
    if source is None or str(source).startswith("ros2:"):
        return None
    return locate_dataset(source)


def dataset_world(source: str) -> Scenario | None:
    """The world of the dataset ``--source`` is in (its world.yaml), or None when ``source`` is no dataset."""
    located = dataset_location(source)
    return None if located is None else open_dataset(located[0]).world()


class DatasetCamera(SourceCamera):
    """One camera of a dataset, played in frame order: its images, its per-frame camera, the truth."""

    def __init__(self, dataset: Dataset, camera_name: str, scenario: Scenario, vehicle: str,
                 extract: FeatureExtractor, clock: FrameClock, *, first_tick: int | None = None,
                 intrinsics: Camera | None = None, world_from_camera: np.ndarray | None = None,
                 intrinsics_from: str | None = None) -> None:
        reader = FileListReader(dataset.image_paths(camera_name), str(dataset.root / camera_name))
        super().__init__(reader, scenario, vehicle, extract,
                         intrinsics=None if intrinsics is None else (lambda: intrinsics),
                         world_from_camera=None if world_from_camera is None else (lambda _stamp: world_from_camera),
                         intrinsics_from=intrinsics_from or f"dataset {dataset.root} camera {camera_name}")
        self.dataset, self.camera_name = dataset, camera_name
        # the fleet tick frame 0 was taken at (None: the first tick a frame is asked at), on ``clock``
        self.clock, self.first_tick = clock, first_tick

    def camera(self, k: int, image_stamp_ns: int | None = None) -> Camera:
        """The dataset's camera of frame ``k`` (intrinsics and pose), each replaced by the file given instead."""
        pose = self.dataset.world_from_camera(self.camera_name, k)
        k_cam = self.dataset.intrinsics(self.camera_name) if self.intrinsics is None else self.intrinsics()
        world_from_camera = (self._world_matrix(pose, k) if self.world_from_camera is None
                             else self.world_from_camera(None))
        return Camera(k_cam.fx, k_cam.fy, k_cam.cx, k_cam.cy, k_cam.width, k_cam.height, k_cam.distortion,
                      world_from_camera)

    def _world_matrix(self, pose: np.ndarray, k: int) -> np.ndarray:
        """``world_from_camera`` of the dataset's pose (6,). When the pose is exactly (to the bit) the world vehicle's
        camera pose at this frame, the world's own transform is taken: the one the dataset was rendered with, which
        the six numbers only round to (a pose's angles turned back into a rotation differ in the last bits, and
        the searches would then not repeat the renderer's to the bit)."""
        vehicle = self.scenario.vehicle(self.vehicle)
        if k < self.scenario.frames:
            exact = vehicle.world_from_camera(self.scenario.time(k))
            if np.array_equal(pose_from_matrix(exact), pose):
                return exact
        return matrix_from_pose(pose)

    def acquire(self, index: int, stamp_ns: int, near: np.ndarray | None = None) -> Frame:
        """The dataset's next frame, processed at fleet tick ``index``, stamped with the tick it was taken at:
        ``first_tick`` plus its number, never after ``index``."""
        if self.first_tick is None:
            self.first_tick = index
        frame = super().acquire(index, stamp_ns, near)
        if frame.skipped is not None:
            return frame
        taken = min(self.first_tick + frame.scene_frame, index)  # never after it is processed
        return replace(frame, stamp_ns=self.clock.stamp_ns(taken), truth=self.truth(frame.scene_frame))

    def first_stamp_ns(self) -> int | None:
        """The instant of the first frame it plays, when the fleet has a common clock (``first_tick`` known), else
        None: a team-mate's view of it arriving before this vehicle plays it is judged there, not on the wall clock."""
        return None if self.first_tick is None else self.clock.stamp_ns(self.first_tick)

    def truth(self, k: int) -> np.ndarray | None:
        """The target's true pose at frame ``k``; None without truth.jsonl or when the target is not in the images."""
        truth = self.dataset.truth(k)
        return None if truth is None or not truth.target_visible else truth.target_pose

    def summary_fields(self) -> dict:
        """What the vehicle's summary says about its source."""
        return {"dataset": str(self.dataset.root), "dataset_camera": self.camera_name,
                "target_visible": self.dataset.target_visible}


def open_dataset_camera(source: str, located: tuple[Path, str | None], scenario: Scenario, vehicle: str,
                        extract: FeatureExtractor, clock: FrameClock, *, first_tick: int | None = None,
                        intrinsics: Camera | None = None, world_from_camera: np.ndarray | None = None,
                        intrinsics_from: str | None = None) -> DatasetCamera:
    """The camera of ``--source`` (a dataset root: ``vehicle``'s folder; a camera's folder: that camera), its frames
    stamped on ``clock`` from ``first_tick`` (:class:`DatasetCamera`)."""
    root, folder = located
    dataset = open_dataset(root)
    name = folder or vehicle
    if name not in dataset.cameras:
        raise SourceError(f"--source {source}: the dataset has no camera {name!r} (cameras: "
                          f"{', '.join(dataset.cameras)})")
    return DatasetCamera(dataset, name, scenario, vehicle, extract, clock, first_tick=first_tick,
                         intrinsics=intrinsics, world_from_camera=world_from_camera, intrinsics_from=intrinsics_from)


__all__ = ["DatasetCamera", "dataset_location", "dataset_world", "open_dataset_camera"]
