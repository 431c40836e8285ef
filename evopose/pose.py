"""Pose parametrisation ``s = (x, y, z, roll, pitch, yaw)`` as ``world_from_target``: a face of :mod:`geometry`.

The convention (``R = Rz(yaw) Ry(pitch) Rx(roll)``, quaternions, wrapping, pose errors) is written once, in
:mod:`geometry` (docs/design.md §2); this module only re-exports it for code that imports ``evopose.pose``.
"""

from __future__ import annotations

from geometry import (ANGLE_PARAMS, PARAM_NAMES, angle_difference, euler_from_rotation, invert_transform,
                      matrix_from_pose, pose_from_matrix, quaternion_from_euler, random_rotations, rotation_angle,
                      rotation_from_euler, wrap_angle)

__all__ = ["ANGLE_PARAMS", "PARAM_NAMES", "angle_difference", "euler_from_rotation", "invert_transform",
           "matrix_from_pose", "pose_from_matrix", "quaternion_from_euler", "random_rotations", "rotation_angle",
           "rotation_from_euler", "wrap_angle"]
