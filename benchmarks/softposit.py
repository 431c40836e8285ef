"""SoftPOSIT (David, DeMenthon, Duraiswami and Samet, "SoftPOSIT: Simultaneous pose and correspondence
determination", IJCV 59(3), 2004) as a peer of EvoPose: pose and correspondences of a 3-D point model in one image
of unlabelled points, written here from the paper, vectorised over a batch of random starts.

The pose ``X_cam = R X + T`` is carried as the two pose vectors of POSIT under scaled orthographic projection
(SOP), ``Q1 = (R1, Tx) / Tz`` and ``Q2 = (R2, Ty) / Tz`` (normalised image, f = 1), and the perspective
corrections ``w_k = R3 . P_k / Tz + 1`` of each model point ``P_k`` (``S_k = (P_k, 1)``). Each step of the
deterministic annealing:

1. squared distances, in pixels, between the corrected image points and the SOP of the model points,
   ``d_jk^2 = f^2 ((Q1 . S_k - w_k x_j)^2 + (Q2 . S_k - w_k y_j)^2)`` (the paper's eq. 10);
2. the assignment ``m_jk = exp(-beta (d_jk^2 - alpha))`` with a slack row and column, made doubly stochastic over
   the non-slack rows and columns by Sinkhorn's alternate normalisations (the slack row and column are not
   normalised: clutter and occluded marks end there); ``alpha = 9.21 sigma^2 + 1`` px^2 is the 99 % chi-square
   bound of a true pair's squared distance at noise ``sigma``;
3. POSIT with the weights: ``L = sum_k m'_k S_k S_k^T`` (``m'_k`` the column sums), ``Q1 = L^-1 sum_jk m_jk w_k x_j
   S_k`` and ``Q2`` alike (eqs. 11-12); the closest orthonormal ``R1, R2`` (the SVD of the 3 x 2 pair, as
   Chang and Tsai do), ``Tz = 2 / (s1 + s2)``, ``R3 = R1 x R2``, then the ``w_k`` again (two POSIT iterations per
   step);
4. ``beta <- 1.05 beta`` until ``beta_final = 0.5``; the pose has converged once the assignment-weighted distance
   per model point is under ``sqrt(alpha) / 2`` after at least 20 steps.

``beta0`` is the documented cube example's 2e-4 scaled by the square of that example's image spread over this
image's (spread = RMS distance of the image points from their centroid): the constant belongs to an image spread of
154 px, and at 25 px it would leave the first assignments nearly uniform. Random starts (a random rotation, the
model's centre on the image points' centroid at the depth their spread gives) run in batches until one is accepted:
it converged and matched at least :data:`ACCEPT_SHARE` of ``min(M, N)`` points (or of the authors' ``numMatchable``
when given) one to one (an entry largest in its row and its column, the pair within ``alpha`` at the final pose),
the paper's acceptance by the number of matched points; after :data:`MAX_STARTS` the start with the most matches is
returned (not accepted). Our one extension, for self-occluding targets: given the marks' normals, a mark facing
away at the current pose takes only its slack (:func:`softposit`'s ``normals``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from geometry import pose_from_matrix, random_rotations

#: The documented cube example (the authors' demonstration code): beta0 at its image spread.
CUBE_BETA0 = 2.0e-4
CUBE_SPREAD_PX = 154.13
BETA_FINAL, BETA_UPDATE = 0.5, 1.05
MIN_BETA_STEPS, POSIT_ITERATIONS = 20, 2
SINKHORN_ITERATIONS, SINKHORN_TOLERANCE = 60, 1e-4
#: A converged start is accepted when this share of min(model points, image points) (or of the matchable points
#: given) is matched one to one (on ten telephoto boxes of another seed: 0.7 solved 3, 0.8, 0.9 and 1.0 solved 4).
ACCEPT_SHARE = 0.8
BATCH, MAX_STARTS = 8, 400


@dataclass
class SoftPositResult:
    """One SoftPOSIT run: ``rotation`` (B, 3, 3) and ``translation`` (B, 3) camera_from_target per start,
    ``matches`` (B,) one-to-one matches within the noise bound, ``converged`` (B,), ``steps`` annealing steps
    taken, ``assignment`` (B, N + 1, M + 1) with the slack row and column last, ``visible`` (B,) model points
    facing the camera at the final pose (all without normals)."""

    rotation: np.ndarray
    translation: np.ndarray
    matches: np.ndarray
    converged: np.ndarray
    steps: int
    assignment: np.ndarray
    visible: np.ndarray


def image_spread(points: np.ndarray) -> float:
    """RMS distance (px) of image points ``points`` (N, 2) from their centroid."""
    points = np.asarray(points, float)
    return float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))


def scaled_beta0(points: np.ndarray) -> float:
    """The cube example's beta0 for this image's spread: the same initial fuzziness relative to the image."""
    return CUBE_BETA0 * (CUBE_SPREAD_PX / max(image_spread(points), 1e-9)) ** 2


def sinkhorn_slack(m: np.ndarray) -> np.ndarray:
    """Alternate row and column normalisation of ``m`` (B, N + 1, M + 1) over its non-slack rows and columns
    (the last row and column are slack and are not normalised)."""
    m = m.copy()
    for _ in range(SINKHORN_ITERATIONS):
        before = m[:, :-1, :-1].copy()
        m[:, :-1, :] /= m[:, :-1, :].sum(axis=2, keepdims=True)
        m[:, :, :-1] /= m[:, :, :-1].sum(axis=1, keepdims=True)
        if np.max(np.abs(m[:, :-1, :-1] - before)) < SINKHORN_TOLERANCE:
            break
    return m


def one_to_one(m: np.ndarray, close: np.ndarray | None = None) -> np.ndarray:
    """Matches per start (B,): non-slack entries of ``m`` (B, N + 1, M + 1) largest in their row and column (and,
    given ``close`` (B, N, M), whose pair lies within the noise bound ``alpha`` at the final pose)."""
    row_max = m.max(axis=2, keepdims=True)
    col_max = m.max(axis=1, keepdims=True)
    best = ((m == row_max) & (m == col_max))[:, :-1, :-1]
    return (best if close is None else best & close).sum(axis=(1, 2))


def softposit(image: np.ndarray, model: np.ndarray, rotation: np.ndarray, translation: np.ndarray, *,
              focal: float, beta0: float, noise: float, normals: np.ndarray | None = None) -> SoftPositResult:
    """Anneal from a batch of starts.

    Parameters
    ----------
    image : (N, 2) image points, pixels relative to the principal point
    model : (M, 3) model points, target frame
    rotation, translation : (B, 3, 3), (B, 3) start poses (camera_from_target)
    focal : focal length, pixels
    beta0, noise : initial annealing parameter (1/px^2) and the image noise sigma (px)
    normals : (M, 3) outward normals, optional
        Our extension for self-occluding models (the paper's points are all visible): a model point whose normal
        faces away at the current pose takes no assignment but its slack, so marks on the far side of a box do
        not compete for the image points of the near side.
    """
    x = np.asarray(image, float) / focal                                   # (N, 2) normalised
    s = np.c_[np.asarray(model, float), np.ones(len(model))]               # (M, 4) homogeneous S_k
    rot = np.array(rotation, float)
    tz = np.array(translation, float)[:, 2]
    q1 = np.concatenate([rot[:, 0], translation[:, :1]], axis=1) / tz[:, None]   # (B, 4)
    q2 = np.concatenate([rot[:, 1], translation[:, 1:2]], axis=1) / tz[:, None]
    w = s[None, :, :3] @ rot[:, 2][:, :, None]                             # (B, M, 1)
    w = w[:, :, 0] / tz[:, None] + 1.0                                     # (B, M)
    alpha = 9.21 * noise ** 2 + 1.0
    max_delta = np.sqrt(alpha) / 2
    n, mm = len(x), len(s)
    scale = 1.0 / (max(n, mm) + 1)
    b = len(rot)
    converged = np.zeros(b, bool)
    done = np.zeros(b, bool)
    beta, steps = beta0, 0
    assign = np.full((b, n + 1, mm + 1), scale)
    r1 = rot[:, 0].copy(); r2 = rot[:, 1].copy(); r3 = rot[:, 2].copy()
    t = np.array(translation, float)
    while beta < BETA_FINAL and not done.all():
        active = ~done
        su, sv = q1[active] @ s.T, q2[active] @ s.T                        # (b, M) SOP of the model
        wk = w[active]
        dist = focal ** 2 * ((su[:, None, :] - wk[:, None, :] * x[None, :, :1]) ** 2
                             + (sv[:, None, :] - wk[:, None, :] * x[None, :, 1:]) ** 2)   # (b, N, M) px^2, eq. 10
        m = np.full((len(su), n + 1, mm + 1), scale)
        m[:, :n, :mm] = scale * np.exp(-beta * (dist - alpha))
        shown = np.full((len(su), mm), True)
        if normals is not None:
            shown = facing(model, normals, np.stack([r1, r2, r3], axis=1)[active], t[active])
            m[:, :n, :mm] *= shown[:, None, :]
        m = sinkhorn_slack(m)
        assign[active] = m
        mjk = m[:, :n, :mm]
        column = mjk.sum(axis=1)                                           # (b, M) m'_k
        lmat = np.einsum("bk,ki,kj->bij", column, s, s)                    # L (b, 4, 4)
        finite = np.isfinite(lmat).all(axis=(1, 2))
        bad = ~finite
        bad[finite] = np.linalg.cond(lmat[finite]) > 1e10
        lmat[bad] = np.eye(4)  # an ill-conditioned L ends that start (not converged), as the authors' code does
        linv = np.linalg.inv(lmat)
        a1, a2 = None, None
        for _ in range(POSIT_ITERATIONS):                                  # eqs. 11-12, then w_k
            xu = np.einsum("bjk,j->bk", mjk, x[:, 0]) * wk                 # sum_j m_jk w_k x_j  (b, M)
            xv = np.einsum("bjk,j->bk", mjk, x[:, 1]) * wk
            a1 = np.einsum("bij,bj->bi", linv, xu @ s)                     # Q1 (b, 4)
            a2 = np.einsum("bij,bj->bi", linv, xv @ s)
            pose_pair = np.stack([a1[:, :3], a2[:, :3]], axis=2)                 # (b, 3, 2)
            broken = ~np.isfinite(pose_pair).all(axis=(1, 2))
            bad |= broken
            pose_pair[broken] = np.eye(3)[:, :2]
            u, sing, vt = np.linalg.svd(pose_pair)
            pair = u[:, :, :2] @ vt                                        # closest orthonormal pair
            nr1, nr2 = pair[:, :, 0], pair[:, :, 1]
            nr3 = np.cross(nr1, nr2)
            ntz = 2.0 / np.maximum(sing[:, 0] + sing[:, 1], 1e-12)
            a1 = np.c_[nr1, a1[:, 3] * ntz] / ntz[:, None]
            a2 = np.c_[nr2, a2[:, 3] * ntz] / ntz[:, None]
            wk = (s[:, :3] @ nr3.T).T / ntz[:, None] + 1.0
        idx = np.nonzero(active)[0]
        q1[idx], q2[idx], w[idx] = a1, a2, wk
        r1[idx], r2[idx], r3[idx] = nr1, nr2, nr3
        t[idx] = np.c_[a1[:, 3] * ntz, a2[:, 3] * ntz, ntz]
        delta = np.sqrt(np.sum(mjk * dist, axis=(1, 2)) / np.maximum(shown.sum(axis=1), 1))   # per model point shown
        beta *= BETA_UPDATE
        steps += 1
        bad |= ~np.isfinite(delta) | ~np.isfinite(a1).all(axis=1) | ~np.isfinite(a2).all(axis=1)
        ok = (delta < max_delta) & (steps > MIN_BETA_STEPS) & ~bad
        converged[idx] = ok
        done[idx] = ok | bad
    rotation_out = np.stack([r1, r2, r3], axis=1)
    su, sv = q1 @ s.T, q2 @ s.T
    visible = np.ones((b, mm), bool) if normals is None else facing(model, normals, rotation_out, t)
    final = focal ** 2 * ((su[:, None, :] - w[:, None, :] * x[None, :, :1]) ** 2
                          + (sv[:, None, :] - w[:, None, :] * x[None, :, 1:]) ** 2)
    close = (final < alpha) & visible[:, None, :]
    return SoftPositResult(rotation_out, t, one_to_one(assign, close), converged, steps, assign, visible.sum(axis=1))


def facing(model: np.ndarray, normals: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Whether each model point (M,) faces the camera at each pose (``rotation`` (B, 3, 3), ``translation``
    (B, 3), camera_from_target), shape (B, M): its rotated normal points against the ray to it."""
    ray = np.einsum("bij,mj->bmi", rotation, model) + translation[:, None, :]
    normal = np.einsum("bij,mj->bmi", rotation, normals)
    return np.sum(ray * normal, axis=2) < 0


def starts(image: np.ndarray, model: np.ndarray, focal: float, count: int,
           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` random starts (camera_from_target): a uniform random rotation, the model's centre on the image
    points' centroid at the depth where the model's RMS radius spans the image points' spread."""
    from geometry import rotation_from_euler

    rotation = rotation_from_euler(random_rotations(count, rng))
    centre = np.asarray(model, float).mean(axis=0)
    radius = float(np.sqrt(np.mean(np.sum((model - centre) ** 2, axis=1))))
    depth = focal * radius / max(image_spread(image), 1e-9)
    mid = np.asarray(image, float).mean(axis=0) / focal
    ray = np.r_[mid, 1.0] * depth
    translation = ray[None, :] - rotation @ centre
    return rotation, translation


@dataclass
class SoftPositSolution:
    """Best pose (6,) world_from_target, whether a start was accepted, starts tried, CPU seconds."""

    pose: np.ndarray
    accepted: bool
    starts: int
    seconds: float
    matches: int


def solve_view(view, model_points: np.ndarray, *, noise: float, seed: int, normals: np.ndarray | None = None,
               matchable: int | None = None, max_starts: int = MAX_STARTS,
               accept_share: float | None = None) -> SoftPositSolution:
    """SoftPOSIT on one :class:`evopose.View` (its camera's intrinsics; points undistorted first when the camera
    has distortion): random starts in batches of :data:`BATCH` until one is accepted. ``normals`` (M, 3): the
    back-face extension of :func:`softposit` (and ``min(M, N)`` counts the model points facing the camera).
    ``matchable``: the authors' ``numMatchable``, an estimate of how many model points can be matched, in place of
    ``min(M, N)``."""
    t0 = time.process_time()
    cam = view.camera
    points = np.asarray(view.points, float)
    if np.any(np.asarray(cam.distortion) != 0):
        import cv2
        points = cv2.undistortPoints(points.reshape(-1, 1, 2), cam.matrix, cam.distortion, P=cam.matrix).reshape(-1, 2)
    focal = float(np.sqrt(cam.fx * cam.fy))
    image = (points - [cam.cx, cam.cy]) * [np.sqrt(cam.fy / cam.fx), np.sqrt(cam.fx / cam.fy)]
    model = np.asarray(model_points, float)
    rng = np.random.default_rng(seed)
    beta0 = scaled_beta0(image)
    share = ACCEPT_SHARE if accept_share is None else accept_share
    best = (-1, None, None)
    tried, accepted = 0, False
    while tried < max_starts:
        rotation, translation = starts(image, model, focal, BATCH, rng)
        out = softposit(image, model, rotation, translation, focal=focal, beta0=beta0, noise=noise, normals=normals)
        tried += BATCH
        expected = np.minimum(out.visible, len(image)) if matchable is None else matchable
        good = out.converged & (out.matches >= share * expected)
        score = out.matches + out.converged * 0.5
        i = int(np.argmax(np.where(good, score + 1000, score)))
        if score[i] + (1000 if good[i] else 0) > best[0]:
            best = (score[i] + (1000 if good[i] else 0), out.rotation[i], out.translation[i], int(out.matches[i]))
        if good.any():
            accepted = True
            break
    camera_from_target = np.eye(4)
    camera_from_target[:3, :3], camera_from_target[:3, 3] = best[1], best[2]
    pose = pose_from_matrix(cam.world_from_camera @ camera_from_target)
    return SoftPositSolution(pose, accepted, tried, time.process_time() - t0, best[3])


__all__ = ["SoftPositResult", "SoftPositSolution", "facing", "image_spread", "scaled_beta0", "sinkhorn_slack",
           "softposit", "solve_view", "starts"]
