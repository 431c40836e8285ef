"""Where the search starts: individuals sampled in the search box, guided by the image.

Rotations are uniform on SO(3) where the box allows every attitude (uniform in the
angle box otherwise). Positions are either uniform in the box or guessed from a view:
the target's centroid lies on the ray through the robust centre of the image points,
at the depth where the model's spread matches the points' spread, with a log-normal
jitter on that depth and a lateral one on the ray.
"""

from __future__ import annotations

import numpy as np

from .pose import random_rotations, rotation_from_euler
from .problem import Bounds, PoseProblem, View


def sample_rotations(bounds: Bounds, n: int, rng: np.random.Generator) -> np.ndarray:
    """Roll/pitch/yaw for ``n`` individuals within the bounds, shape (n, 3)."""
    rpy = random_rotations(n, rng)
    lo, hi = bounds.lo[3:], bounds.hi[3:]
    per = bounds.periodic[3:]
    inside = np.all(per | ((rpy >= lo) & (rpy <= hi)), axis=1)
    box = lo + rng.random((n, 3)) * (hi - lo)
    rpy = np.where(inside[:, None], rpy, box)
    return rpy


def view_centroid_guess(problem: PoseProblem, view: View, n: int, rng: np.random.Generator,
                        depth_jitter: float = 0.35, lateral_jitter: float = 0.15) -> np.ndarray:
    """World positions of the model centroid guessed from one view, shape (n, 3)."""
    pts = view.points
    cam = view.camera
    centre = np.median(pts, axis=0)
    spread_img = np.median(np.linalg.norm(pts - centre, axis=1)) if len(pts) > 1 else 0.0
    model_pts = problem.model.points
    spread_model = np.median(np.linalg.norm(model_pts - model_pts.mean(axis=0), axis=1))
    f = 0.5 * (cam.fx + cam.fy)
    if spread_img > 1.0 and spread_model > 0:
        depth = f * spread_model / spread_img
    else:  # one point or a degenerate model: the middle of the box seen from this camera
        mid = 0.5 * (problem.bounds.lo[:3] + problem.bounds.hi[:3])
        depth = max(float((cam.camera_from_world[:3, :3] @ mid + cam.camera_from_world[:3, 3])[2]), 1.0)
    # jitter the image centre by a fraction of the spread, the depth log-normally
    centres = centre + rng.standard_normal((n, 2)) * lateral_jitter * max(spread_img, 1.0)
    depths = depth * np.exp(depth_jitter * rng.standard_normal(n))
    rays = np.stack([(centres[:, 0] - cam.cx) / cam.fx, (centres[:, 1] - cam.cy) / cam.fy, np.ones(n)], axis=1)
    p_cam = rays * depths[:, None]
    return p_cam @ cam.world_from_camera[:3, :3].T + cam.world_from_camera[:3, 3]


def initial_poses(problem: PoseProblem, n: int, rng: np.random.Generator, guided_fraction: float = 0.8,
                  view_weights: np.ndarray | None = None) -> np.ndarray:
    """``n`` starting poses inside the search box, shape (n, 6).

    A fraction ``guided_fraction`` places the model centroid where a view suggests
    (views drawn in proportion to their weights); the rest is uniform in the box.
    """
    bounds = problem.bounds
    poses = bounds.uniform(n, rng)
    poses[:, 3:] = sample_rotations(bounds, n, rng)
    n_guided = int(round(guided_fraction * n))
    if n_guided and np.any(bounds.free[:3]):
        weights = np.array([v.weight for v in problem.views]) if view_weights is None else np.asarray(view_weights)
        p = weights / weights.sum()
        which = rng.choice(len(problem.views), size=n_guided, p=p)
        centroid_target = problem.model.points.mean(axis=0)
        R = rotation_from_euler(poses[:n_guided, 3:])
        for k in np.unique(which):
            sel = np.nonzero(which == k)[0]
            c_world = view_centroid_guess(problem, problem.views[k], len(sel), rng)
            poses[sel, :3] = c_world - R[sel] @ centroid_target
    return bounds.project(poses)
