"""The gate on a camera's 2-4 px mark labels (vision/label_chroma.py): labels go out only while its spots keep
their chroma."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.label_chroma import MIN_LABEL_CHROMA, LabelChromaGate, spot_chroma

DATA = Path(__file__).resolve().parent / "data" / "photoreal"


def _red_body_with_marks(colours: list[tuple[int, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """A red face (BGR) with one 3 px disc of each colour, 12 px apart; the discs' centres (K, 2)."""
    image = np.zeros((40, 20 + 12 * len(colours), 3), np.uint8)
    image[:] = (40, 40, 150)
    centres = np.array([[14.0 + 12 * i, 20.0] for i in range(len(colours))])
    for (u, v), colour in zip(centres, colours):
        cv2.circle(image, (int(u), int(v)), 2, colour, -1)
    return image, centres


def test_a_spot_keeps_its_chroma_and_one_whose_chroma_the_encoder_removed_does_not():
    cyan, green, magenta = (220, 210, 20), (40, 190, 40), (200, 40, 210)
    image, centres = _red_body_with_marks([cyan, green, magenta])
    radius = np.full(len(centres), 2.0)
    coloured = spot_chroma(image, centres, radius)
    # the encoder at low quality: the spots' luminance kept, their chroma replaced by the body's around them (paints
    # whose luminance with the body's chroma stays inside the sRGB gamut)
    ycc = cv2.cvtColor(image, cv2.COLOR_BGR2YCrCb)
    ycc[..., 1:] = cv2.cvtColor(np.full((1, 1, 3), (40, 40, 150), np.uint8), cv2.COLOR_BGR2YCrCb)[0, 0, 1:]
    faded = spot_chroma(cv2.cvtColor(ycc, cv2.COLOR_YCrCb2BGR), centres, radius)
    assert np.all(coloured > 4 * MIN_LABEL_CHROMA), coloured
    assert np.all(faded < 2.0), faded
    assert spot_chroma(image, np.zeros((0, 2)), np.zeros(0)).shape == (0,)


def test_the_gate_follows_the_cameras_recent_frames_and_ignores_frames_with_few_spots():
    gate = LabelChromaGate(window=3)
    assert gate.carried                                   # nothing measured: labels go out
    assert gate.update(np.array([20.0, 25.0, 30.0]))
    assert gate.update(np.array([1.0, 2.0]))              # two spots say nothing
    assert gate.update(np.array([1.0, 2.0, 3.0]))         # median of (25, 2): still over the bar
    assert not gate.update(np.array([1.0, 2.0, 3.0]))     # median of (25, 2, 2)
    assert not gate.update(np.array([30.0, 30.0, 30.0]))  # (2, 2, 30)
    assert gate.update(np.array([30.0, 30.0, 30.0]))      # (2, 30, 30)
    with pytest.raises(ValueError, match="window"):
        LabelChromaGate(window=0)


@pytest.mark.parametrize("name, sent", [("paper", True), ("paper-flat-cool", False)])
def test_on_committed_camera_frames_labels_go_out_where_they_are_mostly_right(name, sent):
    # the reference look labels 0.8 of its matched marks right, the cold, flat, JPEG-50 camera (scenarios/looks.py)
    # 0.4: its spots keep 2-4 units of chroma (cyan and green read yellow), so its points go out untyped
    from benchmarks.bench_photoreal_features import evaluate, pooled
    from scenarios.dataset import open_dataset
    from vision.extract import feature_extractor

    ds = open_dataset(DATA / name)
    world = ds.world()
    extract = feature_extractor("contrast", world.model, world.bounds())
    labelled = [extract(cv2.imread(str(ds.image_path(cam, k)), cv2.IMREAD_COLOR), ds.camera(cam, k))[1] is not None
                for k in range(ds.frames) for cam in ds.cameras]
    assert labelled == [sent] * len(labelled), labelled
    right = pooled(evaluate(DATA / name), "contrast")["labels"]
    assert (right >= 0.7) if sent else (right <= 0.5), right
