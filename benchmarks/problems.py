"""Seeded generator of synthetic pose problems with ground truth (benchmarks and tests).

Targets: a marked box like the Pioneer-2 DX (0.44 x 0.38 x 0.22 m), an airship-like
ellipsoid (1.85 m) with marks, random 3-D points, and a planar 9 x 6 grid (a chessboard's
inner corners). The camera is the world frame (paper Fig. 1); the target stands 5-30 m
away somewhere in the field of view. The focal length is chosen per problem so that the
target spans 150-350 px (a zoom lens, as a UAV would use at 30 m): without it a 44 cm robot
at 30 m is 12 px wide and no method recovers its attitude. Image points are the visible
projected marks with Gaussian noise, a fraction missing (occlusion) and false points
(clutter) scattered around the target.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from evopose import Bounds, Camera, Model, PoseProblem, View
from evopose.fitness import project_into_view
from geometry import euler_from_rotation, random_rotations, rotation_angle, rotation_from_euler

KINDS = ("box", "ellipsoid", "random", "grid")
WIDTH, HEIGHT = 640, 480


def box_model(rng: np.random.Generator | None = None) -> tuple[Model, list[np.ndarray]]:
    """Pioneer-like box with 20 marks (asymmetric layout) and outward normals."""
    a, b, c = 0.22, 0.19, 0.11  # half sizes (m)
    pts, nrm = [], []
    # top face: 6 marks (asymmetric)
    for x, y in [(-0.18, -0.15), (0.18, -0.15), (0.18, 0.15), (-0.18, 0.15), (0.05, 0.0), (-0.08, 0.07)]:
        pts.append((x, y, c)); nrm.append((0, 0, 1))
    # front (+x) and back (-x)
    for y, z in [(-0.15, 0.05), (0.15, 0.05), (0.0, -0.06), (0.09, -0.02)]:
        pts.append((a, y, z)); nrm.append((1, 0, 0))
    for y, z in [(-0.12, 0.04), (0.12, -0.05), (-0.03, 0.0)]:
        pts.append((-a, y, z)); nrm.append((-1, 0, 0))
    # sides (+y, -y)
    for x, z in [(-0.15, 0.05), (0.15, -0.04), (0.02, 0.0)]:
        pts.append((x, b, z)); nrm.append((0, 1, 0))
    for x, z in [(-0.12, -0.05), (0.14, 0.05), (-0.01, 0.03), (0.07, -0.03)]:
        pts.append((x, -b, z)); nrm.append((0, -1, 0))
    return Model(np.array(pts), np.array(nrm, float)), [np.eye(3)]


def ellipsoid_model(rng: np.random.Generator | None = None) -> tuple[Model, list[np.ndarray]]:
    """Airship-like ellipsoid 1.85 m long with 18 marks on its hull and a fin mark."""
    A, B = 0.925, 0.30
    angles = [(-0.8, 0.0), (-0.4, 1.2), (0.0, 2.5), (0.4, -2.0), (0.75, -0.6), (-0.6, -1.4), (0.2, 0.6),
              (0.55, 1.9), (-0.2, -2.8), (0.0, -0.9), (-0.85, 2.2), (0.85, 2.9), (0.3, -3.0), (-0.45, 0.5),
              (0.6, 0.3), (-0.1, 1.7), (0.45, -1.2), (-0.7, -2.4)]
    pts, nrm = [], []
    for u, phi in angles:  # u = x / A, phi around the long axis
        x = u * A
        r = B * np.sqrt(max(1 - u * u, 0.0))
        p = np.array([x, r * np.cos(phi), r * np.sin(phi)])
        n = np.array([x / A**2, p[1] / B**2, p[2] / B**2])
        pts.append(p); nrm.append(n / np.linalg.norm(n))
    return Model(np.array(pts), np.array(nrm)), [np.eye(3)]


def random_model(rng: np.random.Generator) -> tuple[Model, list[np.ndarray]]:
    """12-20 random points in a 0.6 m cube, no normals (all always visible)."""
    n = int(rng.integers(12, 21))
    return Model(rng.uniform(-0.3, 0.3, (n, 3))), [np.eye(3)]


def grid_model(rng: np.random.Generator | None = None, cols: int = 9, rows: int = 6,
               square: float = 0.1) -> tuple[Model, list[np.ndarray]]:
    """A chessboard's inner corners, centred, normal +z (visible from the front only).

    Its symmetry: a half turn about the normal maps the corners onto themselves.
    """
    xs = (np.arange(cols) - (cols - 1) / 2) * square
    ys = (np.arange(rows) - (rows - 1) / 2) * square
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    normals = np.tile([0.0, 0.0, -1.0], (len(pts), 1))
    half_turn = rotation_from_euler(np.array([0.0, 0.0, np.pi]))
    return Model(pts, normals), [np.eye(3), half_turn]


MODEL_BUILDERS = {"box": box_model, "ellipsoid": ellipsoid_model, "random": random_model, "grid": grid_model}


@dataclass
class SyntheticProblem:
    """A generated problem with its ground truth.

    Attributes
    ----------
    problem : PoseProblem
    true_pose : array (6,)
    correspondences : list of (model_index (K,), image_points (K, 2)) per view, true matches only
    symmetries : list of (3, 3) rotations of the model onto itself (target frame)
    """

    kind: str
    problem: PoseProblem
    true_pose: np.ndarray
    correspondences: list
    symmetries: list
    distance: float
    noise: float
    clutter: float
    missing: float
    meta: dict = field(default_factory=dict)


def _random_attitude(kind: str, rng: np.random.Generator) -> np.ndarray:
    if kind == "grid":  # board facing the camera (normal -z towards it), tilted up to 55 deg
        tilt = rng.uniform(0, np.deg2rad(55))
        axis_angle = rng.uniform(0, 2 * np.pi)
        spin = rng.uniform(-np.pi, np.pi)
        from scipy.spatial.transform import Rotation
        r = Rotation.from_rotvec(tilt * np.array([np.cos(axis_angle), np.sin(axis_angle), 0])) * \
            Rotation.from_euler("z", spin)
        return r.as_euler("xyz")
    return random_rotations(1, rng)[0]


def make_problem(kind: str, rng: np.random.Generator, *, distance: float | None = None,
                 noise: float | None = None, clutter: float | None = None, missing: float | None = None,
                 n_views: int = 1, size_px: float | None = None, min_visible: int = 6,
                 scene_points: int = 0) -> SyntheticProblem:
    """One random problem of ``kind``; unspecified difficulty parameters are drawn at random.

    ``scene_points`` adds that many false points anywhere in each image (other corners of the
    scene), beside the ``clutter`` fraction scattered around the target.
    """
    distance = rng.uniform(5, 30) if distance is None else distance
    noise = rng.uniform(0.5, 2.0) if noise is None else noise
    clutter = rng.uniform(0, 0.3) if clutter is None else clutter
    missing = rng.uniform(0, 0.2) if missing is None else missing
    size_px = rng.uniform(150, 350) if size_px is None else size_px
    model, symmetries = MODEL_BUILDERS[kind](rng)
    extent = 2 * model.radius
    f = size_px * distance / extent
    for _ in range(200):
        # target centre within the middle of the field of view
        u = rng.uniform(0.3, 0.7) * WIDTH
        v = rng.uniform(0.3, 0.7) * HEIGHT
        ray = np.array([(u - WIDTH / 2) / f, (v - HEIGHT / 2) / f, 1.0])
        centre = ray / np.linalg.norm(ray) * distance
        rpy = _random_attitude(kind, rng)
        R = rotation_from_euler(rpy)
        true_pose = np.r_[centre - R @ model.points.mean(axis=0), rpy]
        cams = [Camera(f, f, WIDTH / 2, HEIGHT / 2, WIDTH, HEIGHT)]
        for k in range(1, n_views):  # other cameras look at the target from another side
            az = rng.uniform(np.deg2rad(30), np.deg2rad(80)) * rng.choice([-1, 1])
            pos = centre + distance * np.array([np.sin(az), -0.3, -np.cos(az)])
            z_axis = (centre - pos) / np.linalg.norm(centre - pos)
            x_axis = np.cross([0, 1.0, 0], z_axis); x_axis /= np.linalg.norm(x_axis)
            y_axis = np.cross(z_axis, x_axis)
            T = np.eye(4); T[:3, :3] = np.stack([x_axis, y_axis, z_axis], axis=1); T[:3, 3] = pos
            cams.append(Camera(f, f, WIDTH / 2, HEIGHT / 2, WIDTH, HEIGHT, world_from_camera=T))
        views, corr, ok = [], [], True
        for cam in cams:
            seen = observe(model, cam, true_pose, rng, noise=noise, clutter=clutter, missing=missing,
                           scene_points=scene_points, min_visible=min_visible)
            if seen is None:
                ok = False
                break
            views.append(seen[0])
            corr.append(seen[1])
        if ok:
            break
    else:
        raise RuntimeError("could not place a visible target")
    bounds = Bounds(np.array([-25, -20, 1, -np.pi, -np.pi, -np.pi]), np.array([25, 20, 45, np.pi, np.pi, np.pi]))
    problem = PoseProblem(model, tuple(views), bounds)
    return SyntheticProblem(kind, problem, true_pose, corr, symmetries, distance, noise, clutter, missing,
                            {"focal": f})


#: The telephoto marked-box problems of issue 35: a focal length of 2400 px at 20-30 m (the box ~50 px wide).
TELEPHOTO_FOCAL = 2400.0


def make_telephoto_box_problem(rng: np.random.Generator, *, noise: float = 1.0, clutter: float = 0.25,
                               missing: float = 0.1) -> SyntheticProblem:
    """A marked box (:func:`box_model`) 20-30 m away through a fixed ``TELEPHOTO_FOCAL`` px lens: 1 px noise,
    25 % false points, 10 % marks missing by default (issue 35's problems; 6-14 marks in the image)."""
    distance = rng.uniform(20, 30)
    extent = 2 * box_model()[0].radius
    return make_problem("box", rng, distance=distance, noise=noise, clutter=clutter, missing=missing,
                        size_px=TELEPHOTO_FOCAL * extent / distance)


def observe(model: Model, camera: Camera, pose: np.ndarray, rng: np.random.Generator, *, noise: float,
            clutter: float, missing: float, scene_points: int = 0,
            min_visible: int = 6, labelled: bool = False) -> tuple[View, tuple[np.ndarray, np.ndarray]] | None:
    """What ``camera`` sees of ``model`` at ``pose`` (world_from_target, (6,)): a view and its true matches.

    ``labelled``: the points carry colour labels (the model's must be set), as a colour-mark detector gives them:
    a mark its own colour, a false point any of the model's colours (distractors in the mark colours).

    Visible marks get Gaussian pixel ``noise``, a fraction ``missing`` is dropped, false points
    make up a fraction ``clutter`` of the result (scattered around the target), and
    ``scene_points`` more fall anywhere in the image. None when fewer than ``min_visible`` marks remain.

    Returns
    -------
    view : View with the shuffled points, shape (P, 2)
    correspondences : (model indices (K,), their noisy image points (K, 2))
    """
    proj = project_into_view(model, View(camera, np.zeros((1, 2))), np.asarray(pose, float)[None])
    uv, vis = proj.uv[0], proj.usable[0] & camera.in_image(proj.uv[0])
    idx = np.nonzero(vis)[0]
    keep = idx[rng.random(len(idx)) >= missing]
    if len(keep) < min_visible:
        return None
    pts = uv[keep] + noise * rng.standard_normal((len(keep), 2))
    n_false = int(round(clutter * len(keep) / max(1 - clutter, 1e-9)))
    lo_box = uv[idx].min(axis=0) - 0.25 * np.ptp(uv[idx], axis=0)
    hi_box = uv[idx].max(axis=0) + 0.25 * np.ptp(uv[idx], axis=0)
    false_pts = rng.uniform(lo_box, hi_box, (n_false, 2))
    all_pts = np.concatenate([pts, false_pts])
    if scene_points:
        scene = rng.uniform([0, 0], [camera.width, camera.height], (scene_points, 2))
        all_pts = np.concatenate([all_pts, scene])
    perm = rng.permutation(len(all_pts))
    if not labelled:
        return View(camera, all_pts[perm]), (keep, pts)
    classes = np.unique(model.labels)
    label_rng = np.random.Generator(rng.bit_generator.jumped())  # draws nothing from rng: the same problem either way
    labels = np.concatenate([model.labels[keep], label_rng.choice(classes, len(all_pts) - len(keep))])
    return View(camera, all_pts[perm], labels=labels[perm]), (keep, pts)


def pose_errors(estimate: np.ndarray, truth: np.ndarray, symmetries: list[np.ndarray],
                model_centroid: np.ndarray | None = None) -> tuple[float, float]:
    """Rotation error (rad) and position error (m) modulo the model's symmetries.

    A symmetry ``S`` (rotation about the model centroid) makes ``R_true @ S`` an equally right answer.
    """
    R_est = rotation_from_euler(estimate[3:])
    R_true = rotation_from_euler(truth[3:])
    c = np.zeros(3) if model_centroid is None else model_centroid
    best = (np.inf, np.inf)
    for S in symmetries:
        R_alt = R_true @ S
        t_alt = truth[:3] + R_true @ c - R_alt @ c
        rot = float(rotation_angle(R_est, R_alt))
        pos = float(np.linalg.norm(estimate[:3] - t_alt))
        if rot < best[0]:
            best = (rot, pos)
    return best


def is_success(rot_err: float, pos_err: float, distance: float) -> bool:
    """Accurate: rotation error < 5 deg and position error < 5 % of the distance."""
    return rot_err < np.deg2rad(5) and pos_err < 0.05 * distance


# --- the paper's image scale (issue 11) ---------------------------------------------------------------------

#: The exp2-paper-scale helicopters: name -> (world file's vehicle, focal length); the Pioneer ~25 px wide.
PAPER_SCALE_WORLD = "exp2-paper-scale"
PAPER_SCALE_CAMERAS = ("H1", "H2")
#: The Pioneer drives on the ground within this square (metres, world frame of exp2-paper-scale).
PAPER_SCALE_AREA = 1.5


@lru_cache(maxsize=1)
def _paper_scale_world():
    from scenarios.target import load_model
    from scenarios.world import load_scenario

    world = load_scenario(PAPER_SCALE_WORLD)
    cameras = {name: world.camera(name, 0) for name in PAPER_SCALE_CAMERAS}
    return load_model("pioneer").evopose_model(), cameras, world.bounds()


def make_paper_scale_problem(rng: np.random.Generator, *, cameras: tuple[str, ...] = ("H1",),
                             noise: float | None = None, clutter: float | None = None, missing: float = 0.1,
                             min_visible: int = 6, labelled: bool = False) -> SyntheticProblem:
    """A Pioneer-2 DX (``scenarios/models/pioneer.yaml``, 18 marks) on the ground, seen by exp2-paper-scale's
    cameras (H1: f = 1700 px at 30 m, H2: f = 1150 px at 20 m; the robot ~25 px wide, marks 3-5 px apart).

    The robot stands anywhere in a 3 m square with any heading (roll = pitch = 0); the search box is the
    world's (x, y within 3 m, z -0.2..0.5 m, every attitude). Noise 0.5-2 px and clutter 0-30 % when not given.
    ``labelled``: the points carry the marks' colours (:func:`observe`); the same seed gives the same problem
    with and without them.
    """
    model, all_cameras, bounds = _paper_scale_world()
    noise = rng.uniform(0.5, 2.0) if noise is None else noise
    clutter = rng.uniform(0.0, 0.3) if clutter is None else clutter
    for _ in range(200):
        pose = np.r_[rng.uniform(-PAPER_SCALE_AREA, PAPER_SCALE_AREA, 2), 0.0, 0.0, 0.0, rng.uniform(-np.pi, np.pi)]
        seen = [observe(model, all_cameras[c], pose, rng, noise=noise, clutter=clutter, missing=missing,
                        min_visible=min_visible, labelled=labelled) for c in cameras]
        if all(x is not None for x in seen):
            break
    else:
        raise RuntimeError("could not place a visible target")
    centre = pose[:3] + rotation_from_euler(pose[3:]) @ model.points.mean(axis=0)
    distance = float(np.mean([np.linalg.norm(all_cameras[c].center_world - centre) for c in cameras]))
    problem = PoseProblem(model, tuple(v for v, _ in seen), bounds)
    return SyntheticProblem("pioneer", problem, pose, [c for _, c in seen], [np.eye(3)], distance, noise, clutter,
                            missing, {"cameras": cameras, "focal": [all_cameras[c].fx for c in cameras]})


def absent_target(sp: SyntheticProblem, rng: np.random.Generator, mode: str) -> SyntheticProblem:
    """The same cameras and search box without the target: only false points.

    ``mode`` "clutter": as many points as ``sp`` has, uniform over the region the target and its clutter
    covered (marks-like density where the target would be); "noise": 10-40 points uniform over each image.
    Labelled views stay labelled: each false point gets one of the model's colours at random.
    """
    views = []
    for view in sp.problem.views:
        if mode == "clutter":
            lo, hi = view.points.min(axis=0), view.points.max(axis=0)
            pts = rng.uniform(lo, hi, (len(view.points), 2))
        elif mode == "noise":
            cam = view.camera
            pts = rng.uniform([0, 0], [cam.width, cam.height], (int(rng.integers(10, 41)), 2))
        else:
            raise ValueError(f"absent-target mode must be 'clutter' or 'noise', got {mode!r}")
        labels = None if view.labels is None else rng.choice(np.unique(sp.problem.model.labels), len(pts))
        views.append(View(view.camera, pts, labels=labels))
    problem = PoseProblem(sp.problem.model, tuple(views), sp.problem.bounds)
    return SyntheticProblem(sp.kind, problem, sp.true_pose, [(np.zeros(0, int), np.zeros((0, 2)))] * len(views),
                            sp.symmetries, sp.distance, sp.noise, 1.0, 1.0, {**sp.meta, "absent": mode})


def marks_identified(sp: SyntheticProblem, pose: np.ndarray, tau: float | None = None) -> float:
    """Share of the true marks in the images whose mutual nearest projected model point at ``pose`` (6,) is
    their own mark, within ``tau`` (the solver's automatic tau per view when None), modulo the model's symmetries.

    Scale-free "right basin": a flipped or mirrored pose, or a grid shifted by a row, identifies few marks
    however small its angle error; a right pose identifies most of them even when noise makes it inaccurate.
    """
    from evopose.fitness import PoseObjective

    objective = PoseObjective(sp.problem, "mutual", tau)
    model = sp.problem.model
    centroid = model.points.mean(axis=0)
    best = 0.0
    for S in sp.symmetries:  # the symmetric pose R S shows model point m where the truth shows relabel[m]
        moved = (model.points - centroid) @ S.T + centroid
        relabel = np.array([int(np.argmin(np.linalg.norm(model.points - q, axis=1))) for q in moved])
        hits = total = 0
        for k, (model_idx, image_pts) in enumerate(sp.correspondences):
            view = sp.problem.views[k]
            proj = project_into_view(model, view, np.asarray(pose, float)[None])
            usable = np.nonzero(proj.usable[0])[0]
            total += len(model_idx)
            if not len(usable) or not len(model_idx):
                continue
            d = np.linalg.norm(view.points[:, None, :] - proj.uv[0, usable][None, :, :], axis=2)  # (P, n)
            for j, q in zip(model_idx, image_pts):
                p = int(np.argmin(np.linalg.norm(view.points - q, axis=1)))
                a = int(np.argmin(d[p]))
                if int(np.argmin(d[:, a])) == p and d[p, a] < objective.taus[k] and relabel[usable[a]] == j:
                    hits += 1
        best = max(best, hits / total if total else 0.0)
    return best


def in_true_basin(sp: SyntheticProblem, pose: np.ndarray, tau: float | None = None) -> bool:
    """The right basin: at least half of the true marks identified (:func:`marks_identified`)."""
    return marks_identified(sp, pose, tau) >= 0.5


__all__ = ["KINDS", "TELEPHOTO_FOCAL", "SyntheticProblem", "absent_target", "euler_from_rotation", "in_true_basin",
           "is_success", "make_paper_scale_problem", "make_problem", "make_telephoto_box_problem", "marks_identified",
           "pose_errors"]
