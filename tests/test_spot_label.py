"""vision.spot_label's lit-paint and dark-paint rules on spots measured on the second robot's telephoto images
(linear BGR after the camera's look is undone; the diagnosis of BENCHMARKS.md, "the lit-paint share" and "a dark
paint's fit"): a red mark dimmer than its yellow ring is lit paint, a black mark under a cast is black, and a spot far
darker than its ring's light is still no bright paint."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from vision.blobs import MAX_LABEL_MISFIT_WEIGHED
from vision.body_paint import srgb_to_linear
from vision.spot_label import label_colours

ROOT = Path(__file__).resolve().parents[1]


def _husky():
    model = yaml.safe_load((ROOT / "scenarios" / "models" / "husky.yaml").read_text())
    names = list(model["colours"])
    palette = srgb_to_linear(np.array([model["colours"][n] for n in names], np.float32) / 255.0).astype(float)
    body = srgb_to_linear(np.array([20, 195, 240], np.float32) / 255.0).astype(float)
    return names, palette, body


def _label(spot, ring, min_brightness, ring_light):
    names, palette, body = _husky()
    label, misfit, _ = label_colours(np.array([spot]), np.array([ring]), palette, min_brightness, bleached=True,
                                     ring_light=np.array([ring_light]), body_linear=body)
    return names[label[0]], float(misfit[0])


def test_a_red_mark_dimmer_than_its_yellow_ring_in_a_dark_look_is_lit_red_paint():
    # corner look 0 on telephoto g1-low: the red mark keeps 0.35-0.44 of its ring's light (4:2:0 chroma blended toward
    # the yellow); at a lit share of 0.45 it was "unlit" and fitted nothing (black at misfit 8960)
    name, misfit = _label([0.0041, 0.0033, 0.0169], [0.013, 0.0268, 0.0437], 0.0376, 0.05)
    assert name == "red" and misfit < MAX_LABEL_MISFIT_WEIGHED


def test_a_spot_far_darker_than_its_rings_light_is_no_lit_paint():
    # the same spot at half its light (0.2 of its ring's): a shadow or a hole on that face, not red paint
    name, misfit = _label([0.0041 / 2, 0.0033 / 2, 0.0169 / 2], [0.013, 0.0268, 0.0437], 0.0376, 0.05)
    assert name != "red" or misfit > MAX_LABEL_MISFIT_WEIGHED


def test_a_black_mark_under_a_blue_cast_fits_black_within_the_bar():
    # corner look 2 on telephoto g1-low: a black mark a little blue (its residual 0.004 over a black's own light of
    # ~0.01: misfit 0.60 without the ring-light floor, over the bar)
    name, misfit = _label([0.0081, 0.0026, 0.0025], [0.063, 0.1683, 0.2403], 0.0122, 0.285)
    assert name == "black" and misfit < MAX_LABEL_MISFIT_WEIGHED
