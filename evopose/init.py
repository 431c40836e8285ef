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
    poses = np.zeros((n, 6))
    poses[:, 3:] = random_rotations(n, rng)
    poses[:, :3] = 0.5 * (bounds.lo[:3] + bounds.hi[:3])
    poses = bounds.nearest_turn(poses)
    inside = bounds.contains(poses)
    box = bounds.lo[3:] + rng.random((n, 3)) * bounds.width[3:]
    return np.where(inside[:, None], poses[:, 3:], box)


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


def _masked_median(values: np.ndarray, mask: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Row-wise (lower) median of ``values`` (n, m) over entries where ``mask``; rows with none give 0."""
    ordered = np.sort(np.where(mask, values, np.inf), axis=1)
    idx = np.maximum(count - 1, 0) // 2
    out = ordered[np.arange(len(values)), idx]
    return np.where(count > 0, out, 0.0)


def align_to_view(problem: PoseProblem, view: View, poses: np.ndarray, rng: np.random.Generator,
                  scale_jitter: float = 0.15, shift_jitter: float = 0.1, iterations: int = 2) -> np.ndarray:
    """Move each pose's position so its projection covers the view's points (attitude kept).

    For every individual the visible projected model is shifted onto the robust centre
    of the image points and scaled (through depth) to their robust spread: a
    weak-perspective moment match, jittered for diversity. Shapes (n, 6) -> (n, 6).
    """
    from .fitness import project_into_view  # local: fitness imports init's siblings only

    cam = view.camera
    pts = view.points
    centre_img = np.median(pts, axis=0)
    spread_img = max(float(np.median(np.linalg.norm(pts - centre_img, axis=1))), 1.0)
    n = len(poses)
    target_centre = centre_img + rng.standard_normal((n, 2)) * shift_jitter * spread_img
    target_spread = spread_img * np.exp(scale_jitter * rng.standard_normal(n))
    centroid_target = problem.model.points.mean(axis=0)
    R = rotation_from_euler(poses[:, 3:])
    poses = poses.copy()
    for _ in range(iterations):
        proj = project_into_view(problem.model, view, poses)
        count = proj.usable.sum(axis=1)
        ok = count >= 2
        if not np.any(ok):
            break
        cu = _masked_median(proj.uv[..., 0], proj.usable, count)
        cv = _masked_median(proj.uv[..., 1], proj.usable, count)
        spread = _masked_median(np.hypot(proj.uv[..., 0] - cu[:, None], proj.uv[..., 1] - cv[:, None]),
                                proj.usable, count)
        ok &= spread > 0.5
        c_world = poses[:, :3] + R @ centroid_target
        c_cam = c_world @ cam.camera_from_world[:3, :3].T + cam.camera_from_world[:3, 3]
        ok &= c_cam[:, 2] > 0
        z = np.where(ok, c_cam[:, 2], 1.0)
        u_c = cam.fx * c_cam[:, 0] / z + cam.cx
        v_c = cam.fy * c_cam[:, 1] / z + cam.cy
        new_u = target_centre[:, 0] + (u_c - cu)
        new_v = target_centre[:, 1] + (v_c - cv)
        new_z = z * spread / target_spread
        new_cam = np.stack([(new_u - cam.cx) / cam.fx * new_z, (new_v - cam.cy) / cam.fy * new_z, new_z], axis=1)
        new_world = new_cam @ cam.world_from_camera[:3, :3].T + cam.world_from_camera[:3, 3]
        new_t = new_world - R @ centroid_target
        poses[ok, :3] = new_t[ok]
    return poses


def initial_poses(problem: PoseProblem, n: int, rng: np.random.Generator, guided_fraction: float = 0.9,
                  view_weights: np.ndarray | None = None) -> np.ndarray:
    """``n`` starting poses inside the search box, shape (n, 6).

    A fraction ``guided_fraction`` places the model where a view suggests (views
    drawn in proportion to their weights): a centroid guess, then a moment match of
    the projected model to the image points; the rest is uniform in the box.
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
            view = problem.views[k]
            c_world = view_centroid_guess(problem, view, len(sel), rng)
            poses[sel, :3] = c_world - R[sel] @ centroid_target
            poses[sel] = align_to_view(problem, view, poses[sel], rng)
    return bounds.project(poses)
