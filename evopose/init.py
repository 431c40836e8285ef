"""Where the search starts: individuals sampled in the search box, guided by the image.

Rotations are uniform on SO(3) where the box allows every attitude (uniform in the
angle box otherwise). Positions are either uniform in the box or guessed from a view:
the target's centroid lies on the ray through the robust centre of the image points,
at the depth where the model's spread matches the points' spread, with a log-normal
jitter on that depth and a lateral one on the ray.

Which image points are "the target" is itself a guess: with clutter spread over the whole
image (other corners of the scene), the centre and spread of all points describe the
scene, not the target. So part of the guided starts take a local cluster instead, a random
image point and its nearest neighbours, as many as the model might show
(:func:`image_regions`).
"""

from __future__ import annotations

import numpy as np

from geometry import random_rotations, rotation_from_euler

from .kernel_backend import align_positions
from .neighbours import k_nearest
from .problem import Bounds, PoseProblem, View

#: Fraction of the guided starts that moment-match a local cluster of image points rather than all of them.
LOCAL_FRACTION = 0.5


def sample_rotations(bounds: Bounds, n: int, rng: np.random.Generator) -> np.ndarray:
    """Roll/pitch/yaw for ``n`` individuals within the bounds, shape (n, 3)."""
    poses = np.zeros((n, 6))
    poses[:, 3:] = random_rotations(n, rng)
    poses[:, :3] = 0.5 * (bounds.lo[:3] + bounds.hi[:3])
    poses = bounds.nearest_turn(poses)
    inside = bounds.contains(poses)
    box = bounds.lo[3:] + rng.random((n, 3)) * bounds.width[3:]
    return np.where(inside[:, None], poses[:, 3:], box)


def _robust_centre_spread(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Median centre (2,) and median distance to it (pixels) of a point set (K, 2)."""
    centre = np.median(points, axis=0)
    spread = float(np.median(np.linalg.norm(points - centre, axis=1))) if len(points) > 1 else 0.0
    return centre, spread


def image_regions(points: np.ndarray, n: int, n_model: int, rng: np.random.Generator,
                  local_fraction: float = LOCAL_FRACTION) -> tuple[np.ndarray, np.ndarray]:
    """Where the target may be in the image: a centre and a spread per start.

    The first ``n - round(local_fraction * n)`` starts use all points; the others a
    random point and its ``k`` nearest neighbours, ``k`` between 40 % and 100 % of the
    model's point count.

    Parameters
    ----------
    points : array, shape (P, 2)
    n : int
    n_model : int
        Number of model points.

    Returns
    -------
    centres : array, shape (n, 2)
    spreads : array, shape (n,)
        Pixels (0 when a region has a single point).
    """
    centre, spread = _robust_centre_spread(points)
    centres = np.tile(centre, (n, 1))
    spreads = np.full(n, spread)
    n_local = int(round(local_fraction * n))
    if n_local and len(points) > n_model:
        k_max = min(len(points), max(n_model, 2))
        seeds = rng.integers(0, len(points), n_local)
        ks = rng.integers(max(int(0.4 * n_model), 2), k_max + 1, n_local)
        neighbours = k_nearest(points[seeds], points, k_max)  # only the seeds' (all points' cost O(P k) memory)
        cluster = points[neighbours]  # (n_local, k_max, 2), nearest first
        member = np.arange(k_max)[None, :] < ks[:, None]
        cu = _masked_median(cluster[..., 0], member, ks)
        cv = _masked_median(cluster[..., 1], member, ks)
        dist = np.hypot(cluster[..., 0] - cu[:, None], cluster[..., 1] - cv[:, None])
        centres[n - n_local:] = np.stack([cu, cv], axis=1)
        spreads[n - n_local:] = _masked_median(dist, member, ks)
    return centres, spreads


def view_centroid_guess(problem: PoseProblem, view: View, n: int, rng: np.random.Generator,
                        depth_jitter: float = 0.35, lateral_jitter: float = 0.15,
                        regions: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """World positions of the model centroid guessed from one view, shape (n, 3).

    ``regions`` (centres (n, 2), spreads (n,)) are where the target is assumed to be in the
    image (:func:`image_regions`); all the view's points by default.
    """
    cam = view.camera
    if regions is None:
        c, sp = _robust_centre_spread(view.points)
        regions = (np.tile(c, (n, 1)), np.full(n, sp))
    centre, spread_img = regions
    model_pts = problem.model.points
    spread_model = np.median(np.linalg.norm(model_pts - model_pts.mean(axis=0), axis=1))
    f = 0.5 * (cam.fx + cam.fy)
    mid = 0.5 * (problem.bounds.lo[:3] + problem.bounds.hi[:3])
    # one point or a degenerate model: the middle of the box seen from this camera
    fallback = max(float((cam.camera_from_world[:3, :3] @ mid + cam.camera_from_world[:3, 3])[2]), 1.0)
    ok = (spread_img > 1.0) & (spread_model > 0)
    depth = np.where(ok, f * spread_model / np.where(ok, spread_img, 1.0), fallback)
    # jitter the image centre by a fraction of the spread, the depth log-normally
    centres = centre + rng.standard_normal((n, 2)) * lateral_jitter * np.maximum(spread_img, 1.0)[:, None]
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
                  scale_jitter: float = 0.15, shift_jitter: float = 0.1, iterations: int = 2,
                  regions: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Move each pose's position so its projection covers the view's points (attitude kept).

    For every individual the visible projected model is shifted onto the robust centre
    of the image points (or of its region, see :func:`image_regions`) and scaled (through
    depth) to their robust spread: a weak-perspective moment match, jittered for
    diversity (compiled: :func:`evopose.align_kernel.align_positions`). Shapes (n, 6) -> (n, 6).
    """
    cam, model = view.camera, problem.model
    n = len(poses)
    if regions is None:
        c, sp = _robust_centre_spread(view.points)
        regions = (np.tile(c, (n, 1)), np.full(n, sp))
    centre_img, spread_img = regions[0], np.maximum(regions[1], 1.0)
    target_centre = centre_img + rng.standard_normal((n, 2)) * shift_jitter * spread_img[:, None]
    target_spread = spread_img * np.exp(scale_jitter * rng.standard_normal(n))
    poses = np.array(poses, dtype=float, order="C")
    with_normals = model.normals is not None
    align_positions(poses, model.points, model.normals if with_normals else np.zeros((1, 3)), with_normals,
                    cam.intrinsics, cam.camera_from_world, cam.world_from_camera, model.points.mean(axis=0),
                    target_centre, target_spread, iterations)
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
            regions = image_regions(view.points, len(sel), len(problem.model.points), rng)
            c_world = view_centroid_guess(problem, view, len(sel), rng, regions=regions)
            poses[sel, :3] = c_world - R[sel] @ centroid_target
            poses[sel] = align_to_view(problem, view, poses[sel], rng, regions=regions)
    return bounds.project(poses)
