"""The ground truth of a photoreal image: which marks it shows, by the OpenCV renderer's visibility rules.

:func:`scenarios.render.render_frame` (``clean=True``) decides which marks face the camera, lie in the image
and are not hidden by the target's own body; the photoreal scene also has the occluders and the clutter objects,
so the rays from the camera to each mark's centre and outline (lifted off the face as the renderer lifts them)
are cast against those too, with the very faces Blender renders (:mod:`scenarios.photoreal.shapes`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from evopose import Camera
from geometry import matrix_from_pose, pose_from_matrix

from ..mesh import Mesh, box_mesh, hits
from ..render import MARK_LIFT, mark_outlines, render_frame
from ..target import TargetModel
from ..world import Scenario
from .shapes import clutter_solid


@dataclass(frozen=True)
class ViewTruth:
    """One camera's truth at a frame, as :class:`scenarios.render.FrameTruth` names its fields."""

    camera_pose: np.ndarray
    mark_index: np.ndarray
    mark_uv: np.ndarray
    mark_colour: list[str]
    fully_visible: np.ndarray
    target_pose: np.ndarray
    time: float


def world_obstacles(scenario: Scenario, t: float) -> Mesh:
    """The occluders (where they are at ``t``) and the clutter objects, world frame."""
    mesh = Mesh.empty()
    for occ in scenario.render.occluders:
        mesh = mesh + box_mesh(np.asarray(occ.centre) + t * np.asarray(occ.velocity), occ.size, tuple(occ.colour))
    for item in scenario.render.clutter:
        mesh = mesh + clutter_solid(item).mesh(item.colour)
    return mesh


def hidden_by(camera: Camera, model: TargetModel, world_from_target: np.ndarray, index: np.ndarray,
              obstacles: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """For the marks ``index``: whether an obstacle hides the centre, and whether it hides any of the outline."""
    if len(index) == 0 or len(obstacles) == 0:
        return np.zeros(len(index), bool), np.zeros(len(index), bool)
    R, p = world_from_target[:3, :3], world_from_target[:3, 3]
    normals = model.mark_normals[index] @ R.T
    centres = model.mark_points[index] @ R.T + p
    samples = np.concatenate([centres[:, None], mark_outlines(centres, normals, model.mark_radius)], axis=1)
    samples = samples + MARK_LIFT * normals[:, None, :]
    blocked = hits(camera.center_world, samples.reshape(-1, 3), obstacles.triangles()).any(axis=1)
    blocked = blocked.reshape(len(index), -1)
    return blocked[:, 0], blocked[:, 1:].any(axis=1)


def absent_target(scenario: Scenario) -> Scenario:
    """The world without its target: no body, no marks (for absent-target frames)."""
    model = replace(scenario.model, body=Mesh.empty(), mark_points=np.zeros((0, 3)),
                    mark_normals=np.zeros((0, 3)), mark_colours=(), parts=())
    return replace(scenario, model=model)


def view_truth(scenario: Scenario, frame: int, vehicle: str, *, target: bool = True) -> ViewTruth:
    """What ``vehicle``'s photoreal image at ``frame`` shows: its pose and the visible marks (none without the
    target)."""
    t = scenario.time(frame)
    veh = scenario.vehicle(vehicle)
    camera = veh.camera_at(t)
    pose = scenario.target_pose(frame)
    empty = ViewTruth(pose_from_matrix(camera.world_from_camera), np.zeros(0, int), np.zeros((0, 2)), [],
                      np.zeros(0, bool), pose, t)
    if not target:
        return empty
    truth = render_frame(scenario, frame, vehicle, clean=True).truth
    index = np.asarray(truth.mark_index, int)
    centre_hidden, edge_hidden = hidden_by(camera, scenario.model, matrix_from_pose(pose), index,
                                           world_obstacles(scenario, t))
    keep = ~centre_hidden
    return replace(empty, mark_index=index[keep], mark_uv=np.asarray(truth.mark_uv).reshape(-1, 2)[keep],
                   mark_colour=[c for c, k in zip(truth.mark_colour, keep) if k],
                   fully_visible=np.asarray(truth.fully_visible, bool)[keep] & ~edge_hidden[keep])
