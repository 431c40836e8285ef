"""The renderer's ground (scenarios/ground.py) and the drawn path's sensor noise (scenarios/sensor_noise.py), by their
effect: the rolled texture draws the ground the texture itself draws, and the noise is what a sensor's would be."""

from __future__ import annotations

import cv2
import numpy as np

from scenarios.ground import ROLL_STEP, TEXTURE_SIZE, ground_texture, rolled_texture
from scenarios.sensor_noise import gain_and_noise
from scenarios.world import load_scenario


def _texture_homography(scenario, vehicle: str, t: float) -> np.ndarray:
    camera, ground = scenario.vehicle(vehicle).camera_at(t), scenario.render.ground
    c = camera.camera_from_world
    return camera.matrix @ np.column_stack([c[:3, 0], c[:3, 1], c[:3, 3]]) @ np.diag([ground.texel, ground.texel, 1.0])


def test_a_rolled_texture_draws_the_ground_the_texture_draws():
    """Warped with the shift it was rolled by, the rolled texture gives the unrolled texture's image (both wrap), but
    for OpenCV's 1/32-texel rounding; every roll of the tile is the same tiling."""
    scenario = load_scenario("exp2")
    ground = scenario.render.ground
    args = (scenario.seed, tuple(ground.colour), float(ground.contrast))
    tex = ground_texture(*args)
    for vehicle, t in (("H1", 0.0), ("H2", 1.3)):
        H = _texture_homography(scenario, vehicle, t)
        plain = cv2.warpPerspective(tex, H, (640, 480), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        for cols, rows in ((0, 3 * ROLL_STEP), (5 * ROLL_STEP, TEXTURE_SIZE - ROLL_STEP)):
            shift = np.array([[1.0, 0.0, -cols], [0.0, 1.0, -rows], [0.0, 0.0, 1.0]])
            rolled = cv2.warpPerspective(rolled_texture(*args, cols, rows), H @ shift, (640, 480),
                                         flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            differ = np.abs(rolled.astype(int) - plain)
            assert differ.max() <= 2 and np.count_nonzero(differ) < 0.01 * differ.size
        assert not np.array_equal(rolled_texture(*args, ROLL_STEP, 0), tex)  # a roll does move the texels


def test_sensor_noise_has_its_sigma_and_each_frame_its_own_draw():
    """On a flat grey image: the noise's sd is sigma in every channel, its mean 0; the same seed gives the same
    image, and two seeds' noise is uncorrelated (each frame a window of one field at its own offset)."""
    grey = np.full((480, 640, 3), 128, np.uint8)
    a, b = gain_and_noise(grey, 1.0, 3.0, 11), gain_and_noise(grey, 1.0, 3.0, 12)
    assert np.array_equal(a, gain_and_noise(grey, 1.0, 3.0, 11))
    da, db = a.astype(float) - 128, b.astype(float) - 128
    for channel in range(3):
        assert abs(da[..., channel].std() - 3.0) < 0.05 and abs(da[..., channel].mean()) < 0.05
    assert abs(np.corrcoef(da.ravel(), db.ravel())[0, 1]) < 0.01
    # neighbours within a frame are independent too
    assert abs(np.corrcoef(da[:, 1:].ravel(), da[:, :-1].ravel())[0, 1]) < 0.01
    # the gain, and no noise at sigma 0
    assert np.array_equal(gain_and_noise(grey, 0.5, 0.0, 11), np.full_like(grey, 64))
