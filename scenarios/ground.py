"""The renderer's ground and sky (:mod:`scenarios.render`, step 1): a seeded procedural ground texture that tiles,
warped onto the ground plane ``z = 0`` by its homography, and the sky where rays miss the ground.

The texture repeats every :data:`TEXTURE_SIZE` texels. Before the warp it is rolled (by whole texels, a multiple of
:data:`ROLL_STEP`) so that the texel under the image's centre lies near the texture's middle: a view smaller than
the tile then reads no texel across its edge, where OpenCV's wrapped border takes a slow path (a telephoto view of
exp2: 5.0 -> 2.4 ms a frame, the same image but for 1/32-texel rounding). A view larger than the tile (a wide lens)
wraps either way."""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from evopose import Camera

from .camera_model import linear_from_srgb
from .sensors import stream_rng
from .world import GroundSpec

#: Side of the square ground texture, texels (a power of two: the FFT noise tiles seamlessly).
TEXTURE_SIZE = 1024
#: Largest HSV saturation (0-255) of the ground texture.
MAX_GROUND_SATURATION = 60
#: Stream number of the ground texture's random draws (see :func:`scenarios.sensors.stream_rng`).
STREAM_GROUND = 101
#: The texture is rolled by multiples of this many texels (:func:`rolled_texture`): a camera that sways keeps
#: one rolled copy for many frames.
ROLL_STEP = 128


@lru_cache(maxsize=8)
def ground_texture(seed: int, colour: tuple[int, int, int], contrast: float) -> np.ndarray:
    """Seamless procedural ground texture, shape (TEXTURE_SIZE, TEXTURE_SIZE, 3) uint8.

    1/f noise made in the frequency domain (so it tiles), plus a little per-channel variation.
    """
    rng = stream_rng(seed, STREAM_GROUND)
    n = TEXTURE_SIZE
    f = np.fft.fftfreq(n)[:, None] ** 2 + np.fft.rfftfreq(n)[None, :] ** 2
    amplitude = 1.0 / np.maximum(np.sqrt(f), 1.0 / n) ** 1.1
    layers = []
    for _ in range(2):
        spectrum = amplitude * (rng.standard_normal(f.shape) + 1j * rng.standard_normal(f.shape))
        layer = np.fft.irfft2(spectrum, s=(n, n))
        layers.append((layer - layer.mean()) / layer.std())
    grain = rng.standard_normal((n, n)) * 0.35
    base = np.asarray(colour, float)
    tex = base + contrast * (layers[0] + grain)[..., None] + 0.3 * contrast * layers[1][..., None] * [1.0, -0.5, -0.5]
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    # earth, gravel and asphalt are dull: keep the saturation well below that of paint (the marks)
    hsv = cv2.cvtColor(tex, cv2.COLOR_BGR2HSV)
    hsv[..., 1] = np.minimum(hsv[..., 1], MAX_GROUND_SATURATION)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


@lru_cache(maxsize=2)
def rolled_texture(seed: int, colour: tuple[int, int, int], contrast: float, cols: int, rows: int) -> np.ndarray:
    """:func:`ground_texture` rolled by ``cols`` and ``rows`` texels: its texel (c, r) is the original's
    ((c - cols) mod n, (r - rows) mod n). The same tiling; two kept (a process draws for one camera or two)."""
    return np.roll(ground_texture(seed, colour, contrast), (rows, cols), axis=(0, 1))


def ground_and_sky(camera: Camera, ground: GroundSpec, seed: int, shade: float, linear: bool = False) -> np.ndarray:
    """Sky and textured ground plane ``z = 0`` seen by ``camera`` (distortion ignored for the background):
    uint8 (H, W, 3), or with ``linear`` float32 linear light (the sky's colour is its radiance)."""
    w, h = camera.width, camera.height
    c_from_w = camera.camera_from_world
    K = camera.matrix
    texel = ground.texel
    # image ~ K [r1 r2 t] [x y 1]^T and texture pixel (col, row) = (x, y) / texel
    H = K @ np.column_stack([c_from_w[:3, 0], c_from_w[:3, 1], c_from_w[:3, 3]]) @ np.diag([texel, texel, 1.0])
    colour, contrast = tuple(ground.colour), float(ground.contrast)
    centre = np.linalg.solve(H, [(w - 1) / 2, (h - 1) / 2, 1.0])
    if abs(centre[2]) > 1e-12:   # the image's centre sees the ground: roll its texel toward the texture's middle
        roll = np.round((TEXTURE_SIZE / 2 - centre[:2] / centre[2]) / ROLL_STEP) % (TEXTURE_SIZE // ROLL_STEP)
        cols, rows = (int(r) * ROLL_STEP for r in roll)
        tex = rolled_texture(seed, colour, contrast, cols, rows)
        H = H @ np.array([[1.0, 0.0, -cols], [0.0, 1.0, -rows], [0.0, 0.0, 1.0]])
    else:
        tex = ground_texture(seed, colour, contrast)
    image = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    if linear:  # texture colours are sRGB-encoded reflectances: light them in linear light
        image = linear_from_srgb(image)
        if shade != 1.0:
            image *= np.float32(shade)
    elif shade != 1.0:
        image = cv2.convertScaleAbs(image, alpha=shade)
    # rays that do not reach the ground in front of the camera see the sky; the ray's world z is linear in (u, v),
    # so where no corner's ray rises, none does
    ray_z = (camera.world_from_camera[:3, :3] @ np.linalg.inv(K))[2]  # world z of the ray through (u, v, 1)
    height = camera.world_from_camera[2, 3]
    corners_z = ray_z[0] * np.array([0, w - 1, 0, w - 1]) + ray_z[1] * np.array([0, 0, h - 1, h - 1]) + ray_z[2]
    if height > 0 and corners_z.max() < -1e-5:
        return image
    u = np.arange(w, dtype=np.float32)
    v = np.arange(h, dtype=np.float32)
    dz = ray_z[0] * u[None, :] + ray_z[1] * v[:, None] + ray_z[2]
    sky = (dz >= -1e-6) if height > 0 else np.ones((h, w), bool)
    if sky.any():
        gradient = np.clip(0.75 + 0.25 * (v / h), 0, 1)[:, None, None] * np.asarray(ground.sky, np.float32)
        sky_img = np.broadcast_to(gradient, (h, w, 3)).astype(np.uint8)
        image[sky] = linear_from_srgb(sky_img[sky]) if linear else sky_img[sky]
    return image


__all__ = ["MAX_GROUND_SATURATION", "ROLL_STEP", "STREAM_GROUND", "TEXTURE_SIZE", "ground_and_sky", "ground_texture",
           "rolled_texture"]
