"""EvoPose: correspondence-free 6-DOF pose estimation by evolutionary search (the paper's eq. 1-4)."""

from geometry import PARAM_NAMES, matrix_from_pose, pose_from_matrix, quaternion_from_euler, rotation_from_euler

from .camera import Camera
from .fitness import Match, PoseObjective, step_weights
from .local import LocalSearch, LocalState
from .loop import Evaluator, evolve
from .options import SearchOptions
from .pose_filter import FilteredPose, PoseFilter
from .problem import Bounds, Model, PoseProblem, View
from .refine import refine
from .search import Ask, EvoPose, EvoPoseState, Told
from .solver import Solution, pose_mismatch, solve, track
from .trust import Confidence, ConfidenceRules, Trust, assess, judge

__all__ = [
    "Ask", "Bounds", "Camera", "Confidence", "ConfidenceRules", "Evaluator", "EvoPose", "EvoPoseState", "FilteredPose",
    "LocalSearch", "LocalState", "Match", "Model", "PARAM_NAMES", "PoseFilter", "PoseObjective", "PoseProblem",
    "SearchOptions", "Solution", "Told", "Trust",
    "View", "assess", "evolve", "matrix_from_pose", "pose_from_matrix", "pose_mismatch", "quaternion_from_euler",
    "judge", "refine", "rotation_from_euler", "solve", "step_weights", "track",
]
