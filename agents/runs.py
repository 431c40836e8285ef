"""A run's records, typed: each pose an agent published, as its summary keeps it (docs/design.md §6).

An agent's summary (``evopose agent``'s last JSON line, and each vehicle of a scenario run's record) keeps its last
published poses under ``"poses"``, one JSON array per frame in the order of ``"pose_columns"``
(:data:`POSE_COLUMNS`: ``[frame, x, y, z, roll, pitch, yaw, good]``, metres and radians, ``good`` the verdict it
published). Code reads them as :class:`PoseRow` by name, never by position; a summary written before the column
header existed (the same eight columns) reads the same.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from geometry import PARAM_NAMES

#: The columns of a pose row on disk (the summary's ``"pose_columns"``).
POSE_COLUMNS: tuple[str, ...] = ("frame", *PARAM_NAMES, "good")


@dataclass(frozen=True)
class PoseRow:
    """One published pose: the frame on the fleet's clock, ``world_from_target`` (6,) and the verdict."""

    frame: int
    pose: tuple[float, float, float, float, float, float]
    good: bool

    def to_json(self) -> list:
        """The on-disk row, in :data:`POSE_COLUMNS` order."""
        return [int(self.frame), *(float(v) for v in self.pose), bool(self.good)]

    @classmethod
    def from_json(cls, row: Sequence) -> "PoseRow":
        """A row read back; ValueError (one line) when it is not :data:`POSE_COLUMNS`."""
        if isinstance(row, (str, bytes, Mapping)) or len(row) != len(POSE_COLUMNS):
            raise ValueError(f"a pose row is [{', '.join(POSE_COLUMNS)}], got {row!r:.120}")
        return cls(int(row[0]), tuple(float(v) for v in row[1:7]), bool(row[7]))  # type: ignore[arg-type]


def pose_rows(summary: Mapping) -> list[PoseRow]:
    """The published poses of an agent's summary (empty without any)."""
    columns = tuple(summary.get("pose_columns") or POSE_COLUMNS)
    if columns != POSE_COLUMNS:
        raise ValueError(f"pose rows with columns {list(columns)} are not readable here (expected "
                         f"{list(POSE_COLUMNS)})")
    return [PoseRow.from_json(row) for row in summary.get("poses") or []]


def pose_table(rows: Iterable[PoseRow]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames (K,), poses (K, 6) and verdicts (K,) of rows, for vectorised use."""
    rows = list(rows)
    frames = np.array([r.frame for r in rows], dtype=int)
    poses = np.array([r.pose for r in rows], dtype=float).reshape(-1, 6)
    good = np.array([r.good for r in rows], dtype=bool)
    return frames, poses, good


__all__ = ["POSE_COLUMNS", "PoseRow", "pose_rows", "pose_table"]
