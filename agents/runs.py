"""A run's records, typed: each pose an agent published, as its summary keeps it (docs/design.md §6).

An agent's summary (``evopose agent``'s last JSON line, and each vehicle of a scenario run's record) keeps its last
published poses under ``"poses"``, one JSON array per frame in the order of ``"pose_columns"``
(:data:`POSE_COLUMNS`: ``[frame, x, y, z, roll, pitch, yaw, good, scene_frame]``, metres and radians, ``good`` the
verdict it published, ``scene_frame`` the source's frame the pose is of). Code reads them as :class:`PoseRow` by
name, never by position; a summary written before ``scene_frame`` existed (the first eight columns, with or without
the header) reads the same, with ``scene_frame`` None.

``frame`` is the fleet clock's tick the pose was published at. ``scene_frame`` is the instant of the world it shows:
for a rendered world the scenario frame of that tick, for a dataset the dataset's frame, which a vehicle plays one
per frame processed and so, when it is late, at a later tick than a team-mate does (:func:`instant_key`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from geometry import PARAM_NAMES

#: The columns of a pose row on disk (the summary's ``"pose_columns"``).
POSE_COLUMNS: tuple[str, ...] = ("frame", *PARAM_NAMES, "good", "scene_frame")
#: The columns before ``scene_frame`` was recorded (read back with ``scene_frame`` None).
POSE_COLUMNS_WITHOUT_SCENE: tuple[str, ...] = POSE_COLUMNS[:-1]


@dataclass(frozen=True)
class PoseRow:
    """One published pose: the frame on the fleet's clock, ``world_from_target`` (6,), the verdict, and the
    source's frame it shows (None in a record written before it was kept)."""

    frame: int
    pose: tuple[float, float, float, float, float, float]
    good: bool
    scene_frame: int | None = None

    def to_json(self) -> list:
        """The on-disk row, in :data:`POSE_COLUMNS` order."""
        scene = None if self.scene_frame is None else int(self.scene_frame)
        return [int(self.frame), *(float(v) for v in self.pose), bool(self.good), scene]

    @classmethod
    def from_json(cls, row: Sequence) -> "PoseRow":
        """A row read back (:data:`POSE_COLUMNS`, or the eight of :data:`POSE_COLUMNS_WITHOUT_SCENE`); ValueError
        (one line) otherwise."""
        if isinstance(row, (str, bytes, Mapping)) or len(row) not in (len(POSE_COLUMNS),
                                                                      len(POSE_COLUMNS_WITHOUT_SCENE)):
            raise ValueError(f"a pose row is [{', '.join(POSE_COLUMNS)}], got {row!r:.120}")
        scene = row[8] if len(row) == len(POSE_COLUMNS) else None
        return cls(int(row[0]), tuple(float(v) for v in row[1:7]), bool(row[7]),  # type: ignore[arg-type]
                   None if scene is None else int(scene))


def pose_rows(summary: Mapping) -> list[PoseRow]:
    """The published poses of an agent's summary (empty without any)."""
    columns = tuple(summary.get("pose_columns") or POSE_COLUMNS)
    if columns not in (POSE_COLUMNS, POSE_COLUMNS_WITHOUT_SCENE):
        raise ValueError(f"pose rows with columns {list(columns)} are not readable here (expected "
                         f"{list(POSE_COLUMNS)})")
    return [PoseRow.from_json(row) for row in summary.get("poses") or []]


def instant_key(summary: Mapping) -> Callable[[PoseRow], int]:
    """What tells two vehicles' poses of the same instant of the world apart in ``summary``'s rows: the dataset's
    frame when the vehicle played a dataset (``"dataset"`` in its summary; each plays its frames in order, one per
    frame processed, so the ticks differ once one is late), else the fleet clock's frame (a rendered world's scene
    frame repeats when a run is longer than the scenario). A dataset row written without its ``scene_frame`` falls
    back to the tick."""
    if summary.get("dataset"):
        return lambda row: row.frame if row.scene_frame is None else row.scene_frame
    return lambda row: row.frame


def pose_table(rows: Iterable[PoseRow]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames (K,), poses (K, 6) and verdicts (K,) of rows, for vectorised use."""
    rows = list(rows)
    frames = np.array([r.frame for r in rows], dtype=int)
    poses = np.array([r.pose for r in rows], dtype=float).reshape(-1, 6)
    good = np.array([r.good for r in rows], dtype=bool)
    return frames, poses, good


__all__ = ["POSE_COLUMNS", "POSE_COLUMNS_WITHOUT_SCENE", "PoseRow", "instant_key", "pose_rows", "pose_table"]
