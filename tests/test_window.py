"""The contrast front-end in a window of the image (vision.window, vision.extract): around the projection of the last
good pose, or around the body's paint found at half resolution when there is no pose; the same marks as the whole
image gives, and the whole image again when the window holds too few."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from scenarios.dataset import open_dataset
from vision.blobs import crop_margin, detect_contrast_marks, mark_prior
from vision.camera_look import estimate_look
from vision.extract import feature_extractor
from vision.window import MIN_WINDOW_PX, WINDOW_SLACK_PX, grown, locate_body, target_window

DATA = Path(__file__).parent / "data" / "photoreal"


def _frames(name: str):
    """(image, camera, true pose, world) of every frame of a committed Cycles fixture, both cameras."""
    data = open_dataset(DATA / name)
    world = data.world()
    for cam in data.cameras:
        for k in range(data.frames):
            truth = data.truth(k)
            yield (cv2.imread(str(data.image_path(cam, k)), cv2.IMREAD_COLOR), data.camera(cam, k),
                   None if truth is None or not truth.target_visible else truth.target_pose, world)


def _whole_image(image, camera, world) -> np.ndarray:
    """The marks :func:`detect_contrast_marks` finds in the whole image, its look estimated there."""
    area, model = world.bounds(), world.model
    prior = mark_prior(camera, model.mark_radius, model.size, area.lo[:3], area.hi[:3])
    return detect_contrast_marks(image, model.palette, prior, body=model.body_colour,
                                 look=estimate_look(image, model.body_colour, prior.extent_px)).points


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """The same marks: in a window a mark's position is found relative to its corner, to ~1e-13 px of the whole
    image's."""
    return a.shape == b.shape and np.allclose(a, b, rtol=0, atol=1e-9)


def test_a_window_holds_the_body_with_the_margin_and_starts_on_even_pixels():
    image, camera, pose, world = next(_frames("telephoto"))
    body = world.model.body.vertices
    y0, y1, x0, x1 = target_window(camera, pose, body, 48)
    uv, _ = camera.project_population(pose[None], body)
    lo, hi = uv[0].min(axis=0), uv[0].max(axis=0)
    assert y0 % 2 == 0 and x0 % 2 == 0   # a JPEG's 2 x 2 chroma blocks stay aligned
    reach = 48 + WINDOW_SLACK_PX
    assert x0 <= max(lo[0] - reach, 0) + 1 and y0 <= max(lo[1] - reach, 0) + 1
    assert x1 >= min(hi[0] + reach, camera.width) and y1 >= min(hi[1] + reach, camera.height)
    assert 0 <= x0 < x1 <= camera.width and 0 <= y0 < y1 <= camera.height
    # the telephoto body fills a fraction of the frame: the window is well under the whole image
    assert (y1 - y0) * (x1 - x0) < 0.6 * camera.width * camera.height


def test_no_window_for_a_target_behind_the_camera_or_outside_the_image():
    _, camera, pose, world = next(_frames("telephoto"))
    body = world.model.body.vertices
    ahead = camera.world_from_camera[:3, 2]
    behind = pose.copy()
    behind[:3] = camera.center_world - 5 * ahead                   # 5 m behind the lens
    assert target_window(camera, behind, body, 48) is None
    aside = pose.copy()
    aside[:3] = camera.center_world + 20 * ahead + 40 * camera.world_from_camera[:3, 0]   # far out to the right
    assert target_window(camera, aside, body, 48) is None
    assert grown((10, 12, 700, 710), 0, 640, 480) is None          # a box past the image's edge
    assert grown((10, 12, 20, 24), 0, 640, 480)[1] - 0 >= MIN_WINDOW_PX


@pytest.mark.parametrize("name", ["telephoto", "paper"])
def test_around_the_true_pose_the_front_end_finds_the_marks_of_the_whole_image(name):
    frames = list(_frames(name))
    world = frames[0][3]
    extract = feature_extractor("contrast", world.model, world.bounds())
    for image, camera, pose, _ in frames:
        found, _ = extract(image, camera, pose)
        assert _same(found, _whole_image(image, camera, world))


def test_a_window_without_the_target_gives_way_to_the_whole_image():
    frames = list(_frames("paper"))
    world = frames[0][3]
    extract = feature_extractor("contrast", world.model, world.bounds())
    for image, camera, pose, _ in frames:
        off = pose.copy()
        off[1] += 3.0   # 3 m away on the ground (~250 px at the paper's scale): a window of ground, no robot
        y0, y1, x0, x1 = target_window(camera, off, world.model.body.vertices, 48)
        marks = _whole_image(image, camera, world)
        assert not np.any(np.all((marks >= (x0, y0)) & (marks < (x1, y1)), axis=1))
        found, _ = extract(image, camera, off)
        assert len(found) >= 8 and _same(found, marks)


@pytest.mark.parametrize("name", ["telephoto", "paper"])
def test_without_a_pose_the_body_found_at_half_resolution_holds_every_mark(name):
    for image, camera, pose, world in _frames(name):
        model, area = world.model, world.bounds()
        box = locate_body(image, model.body_colour)
        assert box is not None
        prior = mark_prior(camera, model.mark_radius, model.size, area.lo[:3], area.hi[:3])
        y0, y1, x0, x1 = grown(box, crop_margin(prior), camera.width, camera.height)
        marks = _whole_image(image, camera, world)
        assert len(marks) and np.all((marks >= (x0, y0)) & (marks < (x1, y1)))   # every coordinate of every mark
        # and the front-end without a pose finds them there
        found, _ = feature_extractor("contrast", model, area)(image, camera)
        assert _same(found, marks)


def test_without_the_target_no_paint_is_found_at_half_resolution():
    for image, _, _, world in _frames("absent"):
        assert locate_body(image, world.model.body_colour) is None


@pytest.mark.parametrize("world_name", ["exp2", "exp2-paper-scale"])
def test_hue_bands_near_the_true_pose_find_every_true_mark_of_the_whole_image_and_fewer_false(world_name):
    """The hue-band front-end on drawn frames looks near the pose first, too: every mark it finds on the whole image
    that is a true mark (within 1.5 px of the truth) it finds in the window, at the same place; of the rest (the
    distractors the renderer scatters over the image) fewer; and a pose 3 m off gives the whole image's points."""
    from scenarios.render import render_frame
    from scenarios.world import load_scenario

    world = load_scenario(world_name)
    extract = feature_extractor("marks", world.model, world.bounds())
    false_whole = false_window = 0
    for k in range(0, 12, 3):
        frame = render_frame(world, k, "H1")
        pose = world.target_pose(k)
        whole, whole_labels = extract(frame.image, frame.camera)
        near, near_labels = extract(frame.image, frame.camera, pose)
        true_whole = np.linalg.norm(whole[:, None] - frame.truth.mark_uv[None], axis=2).min(axis=1) < 1.5
        true_near = np.linalg.norm(near[:, None] - frame.truth.mark_uv[None], axis=2).min(axis=1) < 1.5
        assert true_whole.sum() >= 8
        # the same place: a centroid taken in the window's coordinates differs in the last bits
        kept = {(tuple(np.round(p, 6)), int(c)) for p, c in zip(near[true_near], near_labels[true_near])}
        assert kept == {(tuple(np.round(p, 6)), int(c)) for p, c in zip(whole[true_whole], whole_labels[true_whole])}
        false_whole, false_window = false_whole + int((~true_whole).sum()), false_window + int((~true_near).sum())
        off = pose.copy()
        off[1] += 3.0   # a window of ground, no robot: the whole image
        assert np.array_equal(extract(frame.image, frame.camera, off)[0], whole)
    assert false_window < false_whole
