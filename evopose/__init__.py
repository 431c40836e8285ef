"""EvoPose: correspondence-free 6-DOF pose estimation by evolutionary search (the paper's eq. 1-4)."""

from .camera import Camera
from .fitness import PoseObjective, step_weights
from .pose import PARAM_NAMES, matrix_from_pose, pose_from_matrix, quaternion_from_euler, rotation_from_euler
from .problem import Bounds, Model, PoseProblem, View
from .refine import refine
from .search import EvoPose, EvoPoseState, SearchOptions, Solution
from .solver import match_quality, solve, track

__all__ = [
    "Bounds", "Camera", "EvoPose", "EvoPoseState", "Model", "PARAM_NAMES", "PoseObjective", "PoseProblem",
    "SearchOptions", "Solution", "View", "match_quality", "matrix_from_pose", "pose_from_matrix",
    "quaternion_from_euler", "refine", "rotation_from_euler", "solve", "step_weights", "track",
]
