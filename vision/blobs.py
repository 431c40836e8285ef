"""Marks found by their contrast, not by preset hues: the front-end for images the project did not draw.

A camera's picture of a 5 cm paint mark 30 m away is 2-4 px of a colour mixed with its surroundings, its chroma
halved again by the encoder's 4:2:0 subsampling, its brightness set by the sun, the exposure and the white
balance. A hue threshold sees the saturated red body and misses a pale sunlit yellow. What survives is
*contrast*: a mark is a small spot that differs from the ring around it, in luminance or chroma, at the
scale a mark has at the target's distance. So (docs/design.md, "The feature front-end"):

1. **Scale space** (:mod:`vision.scale_space`): the image in an opponent space (CIE L*a*b*: lightness and two
   chroma axes), blurred at scales sigma_i = r / sqrt(2) for the mark radii r the geometry allows
   (:class:`MarkPrior`); a difference of Gaussians per channel is the scale-normalised Laplacian, whose
   magnitude over the three channels peaks at a disc's centre and scale; built on the image halved where the
   target is large (:data:`vision.scale_space.HALVE_FROM_EXTENT_PX`), everything after it at full resolution.
2. **Candidates** (:func:`detect_contrast_marks`): local maxima in position and scale (in position only for marks
   under :data:`SMALL_SPOT_PX`, 3-5 px apart, where a neighbour's response outgrows a weak mark's) above a threshold of
   ``k_sigma`` times the image's own robust spread of the response (the ground's texture and the sensor's
   noise set it, so no exposure or gain is assumed), whose Hessian is not an edge's (a ridge along the body's
   outline, a wheel, a shadow's border) and whose scale fits a mark, not the body.
3. **Position** from the response's sub-pixel peak (a quadratic through the 3 x 3 neighbourhood), where the
   luminance carries the full resolution.
4. **Label** (:func:`vision.spot_label.label_colours`): which of the model's colours, seen under an unknown
   brightness ``s``, lies on the line from the background through the observed spot (a blend
   ``p = a c + (1 - a) b``), in linear light; where marks are 3 px and more, a bright spot may also be its colour
   bleached toward white (a tone curve's highlights); a confidence from the margin to the second colour. A spot
   that fits no paint colour (a body corner, a shadow) is dropped; where marks are 3 px and more, so is a spot lighter
   than its ring labelled a paint far darker than the body's (a wheel's glint as the second robot's black), and the
   converse (:func:`vision.spot_label.contrary_lightness`). Spots under :data:`SMALL_SPOT_PX` on a body
   take their label from :mod:`vision.spot_colour` instead, which models the encoder's 4:2:0 chroma, and drop a
   spot whose colour explains too little of it (the body's own shading).
5. **Context**: the marks lie on the target's body. Given the body's paint colour (the model's), a candidate
   must lie on or inside a patch of that paint seen under any light (:mod:`vision.body_paint`: the dichromatic
   reflection model, paint plus the light's own colour, and glossy faces touching it); clutter in the marks' own
   hues lies on the ground and is dropped, and so is a spot on the body's outline, which paint does not ring
   (:data:`MIN_PAINT_AROUND`). Where marks are 3 px and more that ring is looked for 1-3 px out (past a lens's
   blend), *one* paint must surround the spot (:data:`MIN_SURROUND`) and the marks share a scale
   (:func:`vision.mark_selection.one_scale`); or, opted in, a fitted context model weighs those
   (:mod:`vision.mark_context`). The scale space is built only around the body (2.8-3.4x faster on 640 x 480), its
   threshold from the ground beside it. The marks of one target lie within its extent: the densest cluster is kept.

Images are OpenCV BGR ``uint8`` (H, W, 3); points ``(u, v)`` pixels with pixel centres at integers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import partial

import cv2
import numpy as np

from .body_paint import (LINEAR_OF_BYTE, body_paint, body_region, body_silhouette, clipped_channels, paint_around,
                         pixel_box, srgb_to_linear)
from .camera_look import Look, estimate_look, hued_like_body, to_reference_look
from .features import MarkDetections, to_bgr
from .mark_prior import MarkPrior, mark_prior
from .mark_context import context_features, resolve_scorers
from .mark_scorer import MarkScorer, candidate_features
from .order_stats import median
from .mark_selection import (densest_cluster, merge_oblique_marks, one_mark_between, one_per_disc, one_scale,
                             same_spots, surrounded)
from .spot_colour import label_small_spots, labels_of, ring_colours, spot_colours, spot_misfits
from .spot_position import SMALL_SPOT_PX, blob_centroids, coverage_centroids, round_peaks
from .spot_label import label_colours
from .scale_space import (STEPS_PER_OCTAVE, contrast_responses, crop_margin, magnitude, scale_space_image,
                          scales)

#: A candidate's response must exceed this many robust spreads (1.4826 MAD) of its level's response.
K_SIGMA = 6.0
#: Largest ratio of the Hessian's eigenvalues (a disc seen at 70 deg from its normal is 3:1; an edge is >> 10). At 40
#: a pale mark on a face seen at a grazing angle, a 4:1 ellipse, was no candidate (the Pioneer's telephoto frames
#: through the reference look: three of its 15 missed marks, where 100 was chosen; that look is therefore not held out
#: for it). Judged on what it never saw, 100 against 40: the second robot's telephoto worlds recall +0.5..+2.0 points
#: in every named look and +0.0..+2.7 through 8 random looks, the random robots +0.4..+1.7 in 7 of 8 named looks and
#: +0.2..+1.0 in every random one, precision -0.9..+1.1; the paper's scale unchanged (BENCHMARKS.md, "the edge ratio").
MAX_EDGE_RATIO = 100.0
#: Largest misfit of a label: distance of the fitted paint colour from the line through background and spot,
#: as a fraction of the colour's brightness. Where marks are 3 px and more, a spot brighter than its ring may also be
#: its paint bleached toward white (:func:`vision.spot_label.bleached_misfit`): a film-like tone curve pulls bright
#: marks' channels together (highlights lose chroma) past what the look's estimate undoes. Through 16 random looks
#: (`bench_photoreal_looks --random-looks 16 --frames 2` on the telephoto training worlds t1 and t2, never the
#: benchmark's; the alternatives set by hand), with
#: RING_GAPS_PX: recall / precision 0.962 / 0.973 without it, 0.978 / 0.971 with it (the worst look 0.875 -> 0.924);
#: a looser bar instead (0.45 for every spot) gave 0.976 / 0.965 and took the second robot's low-sun precision from
#: 0.78 to 0.57 (its telephoto g1-low benchmark world; the bleached model leaves it as it was).
MAX_LABEL_MISFIT = 0.35
#: Least brightness (channel sum, linear) of a fitted mark colour, relative to the image's median brightness (a
#: mark in the shade of its own body, lit by the sky alone, keeps ~0.25 of a sunlit ground's). Where marks are 3 px
#: and more, a mark lit like the paint around it (:data:`vision.spot_label.LIT_SHARE` of its ring's light, the ring
#: itself past this bar) is lit paint however dark beside the scene: a saturated red on a face in its body's shade
#: under a low sun reflects one channel of a dim light (the second robot's red marks at telephoto: misfit 1.1-1.7 as
#: "no lit paint" without it; with it its recall 0.826 -> 0.860 in the reference look, the Pioneer's frames
#: unchanged: ``bench_photoreal_looks --front-ends contrast --frames 3`` on the telephoto worlds).
MIN_RELATIVE_BRIGHTNESS = 0.2
#: The body's paint is closed over gaps up to this share of the target's extent too (at the paper's scale marks
#: 3-5 px apart break a face's paint into pieces).
BODY_GAP = 0.12
#: Least share of the ring 1-2 px outside a spot that is the body's paint, glossy faces included
#: (:func:`vision.body_paint.paint_around`): a mark on a face is ringed by paint, about half of it on the face's
#: outline; a spot on the body's outline, or on the ground beside it, is not. Cycles sweeps: precision 0.456 -> 0.486 at
#: the paper's scale (recall 0.697 -> 0.695; without the glossy faces 0.517 but 0.685, and low-sun top faces lost),
#: 0.484 -> 0.547 at telephoto (recall 0.972 -> 0.966); 0.3 took telephoto recall to 0.956. Through six random looks
#: (scenarios.looks.random_look, seeds 1000-1005, telephoto g1-low and g3-overcast; a one-off analysis): 0.2 recall
#: 0.744 / precision 0.820, 0.3 0.703 / 0.824, 0.45 0.631 / 0.847 (under odd looks the paint mask frays; the Husky's
#: outline spots want 0.45). Dropped at telephoto once the surround rule existed (MIN_SURROUND), recall rose 0.7-1.6
#: points on the Pioneer's reference and random looks, but the Husky's precision fell 5-16 points in 7 of 8 looks:
#: kept.
MIN_PAINT_AROUND = 0.2
#: Where marks are 3 px and more, a spot's centre lies inside the body's silhouette (the closed, filled paint), by more
#: than this share of its radius: a mark lies on a face; a speck on the ground beside the outline does not. Through six
#: random looks (telephoto g1-low, g3-overcast; the one-off analysis of MIN_PAINT_AROUND): no rule 0.744 / 0.820 (recall
#: / precision), inside 0.733 / 0.835, half a radius in 0.716 / 0.833 (an odd look frays the paint mask at the
#: silhouette); the committed Husky telephoto frames 0.16 -> 0.22 precision, the Pioneer's unchanged
#: (tests/test_blobs.py measures both).
INSIDE_SHARE = 0.0
#: Where marks are 3 px and more, least share of the directions around a spot in which its surroundings are their usual
#: colour (:func:`vision.mark_selection.surrounded`): a mark is ringed by one paint; a contrast peak where the body
#: meets its plate, a tyre or a shadow is not. Chosen on the Pioneer's telephoto worlds through the reference look alone
#: (recall 0.966 -> 0.966, precision 0.857 -> 0.938; 0.6 lost recall, 0.961), then judged on what it never saw: the
#: Husky's telephoto worlds (reference look 0.838 / 0.183 -> 0.819 / 0.573, recall / precision; AgX 0.821 / 0.163 ->
#: 0.811 / 0.618) and the Pioneer's in AgX, Filmic, flat-cool, hable-faded (precision 0.91 -> 0.95, 0.86 -> 0.94, 0.61
#: -> 0.80, 0.89 -> 0.96, recall within 0.004). At the paper's scale a 2-4 px mark's ring reaches the next mark and the
#: face's outline (recall 0.813 -> 0.458 at 0.5): not used there.
MIN_SURROUND = 0.5
#: Where marks are 3 px and more, the ring of MIN_PAINT_AROUND is looked for this many pixels out (the best of them
#: counts): a lens's blur rings a mark with its blend with the paint first (a cyan mark on red paint blends to grey,
#: which is no paint), then with the paint. Through 16 random looks (lens blur 0-1.5 px; the telephoto training
#: worlds t1, t2: `bench_photoreal_looks --random-looks 16 --frames 2` with the constants set by hand; never the
#: benchmark's worlds) recall / precision 0.943 / 0.972 at 1 px alone, 0.962 / 0.973 at 1, 2 and 3 px (the worst
#: look 0.769 -> 0.875). The surround rule's ring (MIN_SURROUND) stays at 2 px: looked for further out too, it let
#: through peaks where the second robot's body meets its black plate (its committed telephoto frames, precision 0.90
#: -> 0.82; the same veto that kept MIN_PAINT_AROUND), so that robot is not held out from this choice.
RING_GAPS_PX = (1.0, 2.0, 3.0)
#: Least pixels beside the body for the response's spread to be taken there (else over the whole crop), and at most
#: about this many of them sampled for it (a robust statistic).
MIN_BACKGROUND_PX, MAX_SPREAD_SAMPLES = 200, 20000
#: With the body context, where the prior's largest mark radius is under :data:`SMALL_SPOT_PX`, a spot may misfit
#: its label this much: the encoder's 4:2:0 chroma (2 x 2 px blocks) leaves such a mark's colour far off its
#: paint's line, and the body, not the label, rejects the clutter.
MAX_LABEL_MISFIT_ON_BODY = 1.0
#: Where marks are 3 px and more and a context model weighs the spots (:mod:`vision.mark_context`, whose measures
#: include the misfit), a spot may misfit its label this much before the model sees it. Chosen on the Pioneer's
#: telephoto training worlds t1 and t2 (2 frames) through the named looks: through ``flat-cool`` (colours 0.45
#: saturated, white balance 30 % off, JPEG 50) 7 of its 19 missed marks misfit 0.35-0.5, recall / precision 0.928 /
#: 0.948 -> 0.955 / 0.939 at 0.5 (the same at 0.7 and 1.0); AgX and ``vivid-warm`` unchanged. Judged on worlds and
#: robots it was not chosen on (BENCHMARKS.md, "a label's misfit weighed by the context model"): recall up in every
#: look of the second robot and the random robots, precision down by up to 3.4 points.
MAX_LABEL_MISFIT_WEIGHED = 0.5
#: With a :class:`vision.mark_scorer.MarkScorer` (spots under :data:`SMALL_SPOT_PX` on a body) the candidates'
#: bars: response, paint around, share explained by the colour (instead of K_SIGMA, MIN_PAINT_AROUND and
#: vision.spot_colour.MIN_EXPLAINED); the scorer then decides. Cycles paper-scale sweep: recall of the candidates
#: 0.857 (0.808 with the bars), 2629 candidates against 1479 detections.
CANDIDATE_K_SIGMA, CANDIDATE_PAINT_AROUND, CANDIDATE_EXPLAINED = 4.0, 0.05, 0.05
CHANNEL_PEAKS = True
#: Where marks are 3 px and more, pixels hued like the body (:func:`vision.camera_look.hued_like_body`) join the
#: glossy faces' hysteresis (:func:`vision.body_paint.body_paint`): through a film curve's shoulder, a low saturation
#: and over-exposure a sunlit top face keeps the paint's hue but too little of its light for the paint's model, and
#: its marks lay outside the body's region. Chosen on the telephoto training worlds t1, t2 through 16 random and 16
#: corner looks (:func:`scenarios.looks.corner_look`). Judged with the rules beside it (BENCHMARKS.md, "a face
#: bleached toward grey"): the Pioneer's nine telephoto benchmark worlds through the named looks, recall +0.0..+4.1
#: points, precision -1.1..+0.1; the second robot's low-sun worlds pay precision (up to -2.2 points in a look). At the
#: paper's scale, on one benchmark world, it moved a mark or a false point either way per look: not used there.
HUED_PAINT = True
#: Where marks are 3 px and more, a spot's ring counts as lit paint (the light on it sets the bar of
#: :data:`vision.spot_label.LIT_SHARE`) when at least this share of it is the body's paint, however dark beside the
#: scene: a tone curve that darkens shadows (a gamma, AgX Punchy) takes a face in the body's shade under the scene's
#: brightness bar, and its marks were "no lit paint". Set by hand (half the ring); on the telephoto training worlds t1,
#: t2 through 16 random and 16 corner looks: recall +0.4..+1.5 points in 14 looks, precision -0.6..+0.1; judged on the
#: Pioneer's telephoto benchmark worlds (AgX Punchy 0.966 -> 0.992) and the second robot's (its low-sun g2-low world
#: through AgX Punchy: precision 0.896 -> 0.857; BENCHMARKS.md, "a face bleached toward grey").
PAINT_RING_LIT = 0.5


#: sRGB decoding (vision.body_paint), by the names this module's callers use
_srgb_to_linear, _LINEAR_OF_BYTE = srgb_to_linear, LINEAR_OF_BYTE


@dataclass(frozen=True)
class ContrastMarks(MarkDetections):
    """:class:`MarkDetections` with what the contrast front-end knows more: ``label_confidence`` (K,) in [0, 1],
    ``radius`` (K,) pixels (from the scale), ``contrast`` (K,) the response over its threshold."""

    label_confidence: np.ndarray = None  # type: ignore[assignment]
    radius: np.ndarray = None  # type: ignore[assignment]
    contrast: np.ndarray = None  # type: ignore[assignment]
    #: (K, F) the scorer's features (vision.mark_scorer.candidate_features; where marks are 3 px and more
    #: vision.mark_context.context_features), or None: no scorer ran
    features: np.ndarray | None = None


def detect_contrast_marks(image_bgr: np.ndarray, palette: Mapping[str, tuple[int, int, int]],
                          prior: MarkPrior = MarkPrior(), *, body: tuple[int, int, int] | None = None,
                          k_sigma: float = K_SIGMA, max_edge_ratio: float = MAX_EDGE_RATIO,
                          max_misfit: float | None = None, max_marks: int = 256,
                          scorer: MarkScorer | str | None = "shipped",
                          look: Look | str | None = "auto") -> ContrastMarks:
    """The model's marks in a camera image (uint8 (H, W, 3) BGR) by their contrast (see the module's docstring).

    ``palette``: the model's mark colours, name -> BGR (sRGB, 0-255); ``prior``: the marks' radius range and the
    target's extent in pixels; ``body``: the body's paint (BGR), the context the marks must lie on (None: no
    body context). ``max_misfit``: default :data:`MAX_LABEL_MISFIT`, with a body :data:`MAX_LABEL_MISFIT_ON_BODY`
    when every mark is under :data:`SMALL_SPOT_PX`. Returns the marks sorted by label then row.

    ``scorer``: which spots on a body are marks. ``"shipped"`` (the default): under :data:`SMALL_SPOT_PX` the
    shipped small-spot scorer (:mod:`vision.mark_scorer`, palette-relative: any palette), its candidates taken with
    the lenient :data:`CANDIDATE_K_SIGMA` bars (``k_sigma`` is not used); where marks are 3 px and more the shipped
    context model (:mod:`vision.mark_context`) instead of the hand-set context bars (paint ring, surround, common
    scale). A :class:`MarkScorer` of either kind (a file of ``evopose train-scorer``) replaces the shipped one of
    its kind. ``"bars"`` or None: the hand-set bars at every scale. ``"all"``: every candidate, with its features
    (to fit a scorer; where marks are 3 px and more every spot before the context bars, with its context features).

    ``look``: what the camera's look did to the colours (:mod:`vision.camera_look`), undone before anything is
    compared with the paint colours: ``"auto"`` estimated from this image and the body's paint, a :class:`Look`
    (e.g. a track's), or None (the image is taken as the reference look shows it).

    With a body the scale space is built only around it: the box of :func:`body_region` grown by three of the
    largest blur sigmas, at least :data:`vision.scale_space.MIN_MARGIN_PX` (no paint in the image: no marks)."""
    bgr = raw = to_bgr(image_bgr)
    names = tuple(palette)
    if not names:
        raise ValueError("the palette names no colour")
    if isinstance(look, str) and look != "auto":
        raise ValueError(f"look must be a Look, 'auto' or None, got {look!r}")
    if look == "auto":
        look = estimate_look(bgr, body, prior.extent_px)
    # a channel the camera clipped is a lower bound of the light (vision.body_paint: a face lit past the exposure
    # keeps its paint), read as the camera gave it, before the look is undone
    clipped = clipped_channels(bgr) if body is not None else None
    if isinstance(look, Look):
        bgr = to_reference_look(bgr, look)
    scorer, context = resolve_scorers(scorer, names)
    settings = dict(k_sigma=k_sigma, max_edge_ratio=max_edge_ratio, max_misfit=max_misfit, max_marks=max_marks,
                    scorer=scorer, context=context)
    lin = _LINEAR_OF_BYTE[bgr]
    if body is None:
        return _detect(bgr, lin, names, palette, prior, None, **settings)
    body_linear = _srgb_to_linear(np.array(body, np.float32) / 255.0)
    gap = 0.0 if prior.extent_px is None else BODY_GAP * prior.extent_px
    # the region grows into the glossy faces (hysteresis: a low sun's gloss on a red top face) at every scale; at
    # the paper's scale the sure paint alone lost the marks on such faces (recall 0.772 -> 0.808, precision 0.606
    # -> 0.569: benchmarks/bench_photoreal_features.py on datasets/photoreal/photoreal-paper-g*, either region),
    # and the spots the gloss adds are the body's shading that MIN_EXPLAINED drops
    # where marks are 3 px and more, a face a look bleached toward grey is paint by its hue (HUED_PAINT)
    hued = (partial(hued_like_body, raw, look if isinstance(look, Look) else Look(), body, extent_px=prior.extent_px)
            if HUED_PAINT and prior.radius_px[1] >= SMALL_SPOT_PX else None)
    sure, paint = body_paint(lin, body_linear, clipped, hued)   # a channel the camera clipped: a lower bound
    silhouette = body_silhouette(paint, prior.radius_px[1], gap)
    region = body_region(silhouette, prior.radius_px[1])
    box = pixel_box(region)
    if box is None:
        return _detect(bgr[:0, :0], lin[:0, :0], names, palette, prior, region[:0, :0], **settings)
    margin = crop_margin(prior)
    # the crop starts on even coordinates: the encoder's 2 x 2 chroma blocks stay aligned (vision.spot_colour)
    y0, y1 = max(box[0] - margin, 0) // 2 * 2, min(box[1] + margin + 1, bgr.shape[0])
    x0, x1 = max(box[2] - margin, 0) // 2 * 2, min(box[3] + margin + 1, bgr.shape[1])
    # the crop of the linear image in one block: the spots' windows gather from it by flat index (vision.spot_position)
    found = _detect(bgr[y0:y1, x0:x1], np.ascontiguousarray(lin[y0:y1, x0:x1]), names, palette, prior,
                    region[y0:y1, x0:x1], **settings, body=body, paint=paint[y0:y1, x0:x1], sure=sure[y0:y1, x0:x1],
                    silhouette=silhouette[y0:y1, x0:x1])
    return replace(found, points=found.points + (x0, y0))


def _detect(bgr: np.ndarray, lin: np.ndarray, names: tuple[str, ...], palette: Mapping[str, tuple[int, int, int]],
            prior: MarkPrior, region: np.ndarray | None, *, k_sigma: float, max_edge_ratio: float,
            max_misfit: float | None, max_marks: int, scorer: MarkScorer | str | None,
            context: MarkScorer | str | None = None,
            body: tuple[int, int, int] | None = None, paint: np.ndarray | None = None,
            sure: np.ndarray | None = None, silhouette: np.ndarray | None = None) -> ContrastMarks:
    """:func:`detect_contrast_marks` in ``bgr`` (H, W, 3) uint8 (``lin`` the same in linear light, float32), the
    marks kept on ``region`` (H, W) bool when given (the body's paint ``body``, BGR, whose pixels are ``paint``
    (H, W) bool, ``sure`` the sure ones, ``silhouette`` its closed and filled paint, :func:`body_silhouette`)."""
    h, w = bgr.shape[:2]
    if h < 5 or w < 5:
        empty = np.zeros(0)
        return ContrastMarks(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int), names, np.zeros(0, bool), empty,
                             empty, empty)
    scoring = scorer is not None and body is not None and prior.radius_px[1] < SMALL_SPOT_PX
    if scoring:
        k_sigma = CANDIDATE_K_SIGMA
    img = bgr.astype(np.float32) / 255.0
    lab = cv2.cvtColor(img, cv2.COLOR_BGR2Lab)
    full_prior = prior   # the scale space may be built on the image halved (vision.scale_space)
    space, prior, region = scale_space_image(lab, prior, region)
    halve = space is not lab
    sigmas = scales(prior)
    level_radius = np.sqrt(sigmas[:-1] * sigmas[1:]) * np.sqrt(2)
    step = 2 ** (1 / STEPS_PER_OCTAVE)
    fits = (level_radius >= prior.radius_px[0] / step) & (level_radius <= prior.radius_px[1] * step)
    # only the levels up to the last whose scale fits a mark are built: a level that fits none is never a peak's,
    # nor its neighbour's (its dilation counts as zero), so the coarsest blurs, the costliest, are left out
    used = int(np.flatnonzero(fits)[-1]) + 1 if fits.any() else 1
    sigmas, level_radius, fits = sigmas[:used + 1], level_radius[:used], fits[:used]
    dog = contrast_responses(space, sigmas)
    mag = magnitude(dog)                                                 # (S - 1, H, W)
    # threshold per level: robust spread of the response over the image (texture and noise); around a body, over
    # what lies beside it (the ground's texture, as over a whole image, not the marks and edges of the body)
    beside = None if region is None else ~cv2.dilate(region.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    if beside is not None and np.count_nonzero(beside) >= MIN_BACKGROUND_PX:
        at = np.flatnonzero(beside)
        sample = mag.reshape(len(mag), -1)[:, at[::max(1, len(at) // MAX_SPREAD_SAMPLES)]]
    else:
        sample = mag[:, ::3, ::3].reshape(len(mag), -1)
    med = median(sample, axis=1)
    spread = 1.4826 * median(np.abs(sample - med[:, None]), axis=1)
    thresh = med + k_sigma * np.maximum(spread, 1e-3)
    # local maxima in position and scale among the levels whose scale fits a mark (a disc of radius r peaks at
    # sigma = r / sqrt(2); a dog level's scale lies between its two blurs): at the largest fitting level a peak may
    # still be growing, as neighbours (marks 3-5 px apart, the body) keep the response rising past a small mark's
    # own scale. Under SMALL_SPOT_PX maxima in position only: marks 3-5 px apart, each 2-4 px, make one another's
    # response at the next scale up stronger than a weak mark's own, which then peaks at no scale (the strongest of
    # a spot's peaks at several scales is kept, :func:`_same_spot`). Cycles paper-scale sweep: of 317 visible marks
    # missed, 123 had no maximum; recall 0.680 -> 0.789, precision 0.595 -> 0.514 (before MIN_EXPLAINED 0.2). At
    # telephoto scale it only added false spots (recall 0.966 -> 0.913, precision 0.547 -> 0.312)
    kernel = np.ones((3, 3), np.uint8)
    dil = np.stack([cv2.dilate(m, kernel) if ok else np.zeros_like(m) for m, ok in zip(mag, fits)])
    peak = (mag >= dil) & (mag > thresh[:, None, None]) & fits[:, None, None]
    if prior.radius_px[1] >= SMALL_SPOT_PX:   # a fitting level's neighbours in scale (past the ends: zero, which
        peak[:-1] &= mag[:-1] >= dil[1:]      # the response never falls below; at the ends of the fitting range
        peak[1:] &= mag[1:] >= dil[:-1]       # it may still grow)
    elif scoring and CHANNEL_PEAKS:
        for c in range(3):
            for sign in (1.0, -1.0):
                ch = (sign * dog[..., c]).astype(np.float32)
                chd = np.stack([cv2.dilate(m, kernel) for m in ch])
                peak |= (ch >= chd) & (ch > 0) & (mag > thresh[:, None, None]) & fits[:, None, None]
    peak[:, :2, :] = peak[:, -2:, :] = peak[:, :, :2] = peak[:, :, -2:] = False
    lvl, ys, xs = np.unravel_index(np.flatnonzero(peak), peak.shape)   # (np.nonzero of a 3-D mask: 15x the time)
    radius = level_radius[lvl]
    if len(lvl) > 4 * max_marks:   # strongest first
        top = np.argsort(-mag[lvl, ys, xs])[:4 * max_marks]
        lvl, ys, xs, radius = lvl[top], ys[top], xs[top], radius[top]
    if region is not None:  # context: on or beside the body's paint, and (a mark on a face) ringed by it
        on = region[ys, xs]
        lvl, ys, xs, radius = lvl[on], ys[on], xs[on], radius[on]
    ok, pts = round_peaks(dog, lvl, ys, xs, max_edge_ratio)
    lvl, ys, xs, radius, pts = lvl[ok], ys[ok], xs[ok], radius[ok], pts[ok]
    in_space = (lvl, ys, xs)   # the peaks in the scale space; from here on full resolution
    prior = full_prior
    if halve:
        pts, radius = 2 * pts + 0.5, 2 * radius
        ys, xs = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1), np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
    # colours: the spot (finest blur at the centre) and its ring (median around, outside the mark), linear light
    spot = spot_colours(lin, xs, ys, radius)
    ring = ring_colours(lin, np.stack([xs, ys], axis=1).astype(float), radius)
    pal = _srgb_to_linear(np.array([palette[n] for n in names], np.float32) / 255.0)
    scene = float(median(lin[::4, ::4].sum(axis=2).reshape(-1)))
    # the light on each ring's paint, where the ring is lit itself (a dark spot in a dark ring stays no paint)
    body_lin = None if body is None else _LINEAR_OF_BYTE[np.asarray(body, np.uint8)].astype(float)
    # (or the ring is the body's paint: a face in the body's shade, however dark a look's tone curve makes it)
    lit_ring = None if body_lin is None or prior.radius_px[1] < SMALL_SPOT_PX else \
        ring.sum(axis=1) >= MIN_RELATIVE_BRIGHTNESS * scene
    if lit_ring is not None and paint is not None and not lit_ring.all():
        dim = np.flatnonzero(~lit_ring)   # only the rings under the bar need their paint counted
        lit_ring[dim] = paint_around(paint, np.stack([xs[dim], ys[dim]], axis=1).astype(float), radius[dim],
                                     RING_GAPS_PX[0]) >= PAINT_RING_LIT
    ring_light = (None if lit_ring is None
                  else np.where(lit_ring, ring.astype(float) @ body_lin / float(body_lin @ body_lin), np.inf))
    labels, misfit, conf = label_colours(spot.astype(float), ring.astype(float), pal.astype(float),
                                         MIN_RELATIVE_BRIGHTNESS * scene,
                                         bleached=prior.radius_px[1] >= SMALL_SPOT_PX, ring_light=ring_light,
                                         body_linear=body_lin if prior.radius_px[1] >= SMALL_SPOT_PX else None)
    if max_misfit is None:
        weighed = isinstance(context, MarkScorer) and region is not None and prior.radius_px[1] >= SMALL_SPOT_PX
        max_misfit = MAX_LABEL_MISFIT_ON_BODY if region is not None and prior.radius_px[1] < SMALL_SPOT_PX \
            else MAX_LABEL_MISFIT_WEIGHED if weighed else MAX_LABEL_MISFIT
    good = misfit <= max_misfit
    in_space = tuple(a[good] for a in in_space)
    lvl, ys, xs, radius, pts, labels, conf, misfit = lvl[good], ys[good], xs[good], radius[good], pts[good], \
        labels[good], conf[good], misfit[good]
    contrast = mag[in_space] / thresh[lvl]
    spot, ring = spot[good], ring[good]
    pts, long_axis = coverage_centroids(lin, pts, radius, spot, ring), np.zeros((len(pts), 2))
    if prior.radius_px[1] >= SMALL_SPOT_PX and len(pts):   # an oblique mark: its whole blob's centre and length
        pts, long_axis = blob_centroids(lin, pts, spot, ring, max(prior.radius_px[1], float(radius.max())))
    # one detection per place: a stronger peak within its radius (another scale of one spot) wins; an oblique mark's
    # two ends (at 3 px and more) are one detection at their middle (vision.mark_selection.merge_oblique_marks)
    order = np.argsort(-contrast)
    same = same_spots(pts, radius)
    ends = (one_mark_between(lin, pts, radius, labels, spot, ring) & ~same
            if prior.radius_px[1] >= SMALL_SPOT_PX else np.zeros(same.shape, bool))
    same |= ends
    taken, one_mark = [], {}   # the peaks kept; an oblique mark's other peaks under its first taken (int -> [int])
    for i in order.tolist():
        if not same[i, taken].any():
            taken.append(i)
        elif ends[i, taken].any():
            one_mark.setdefault(taken[int(np.flatnonzero(ends[i, taken])[0])], []).append(i)
        if len(taken) >= max_marks:
            break
    merge_oblique_marks(lin, pts, radius, spot, ring, one_mark)
    sel = np.array(sorted(taken), int)
    large = prior.radius_px[1] >= SMALL_SPOT_PX
    depth = (cv2.distanceTransform(silhouette.astype(np.uint8), cv2.DIST_L2, 3)   # into the body's silhouette
             if silhouette is not None and len(sel) and large else None)
    if depth is not None:   # a mark's centre is on the body
        cu, cv = np.rint(pts[sel]).astype(int).T
        ok = (cu >= 0) & (cv >= 0) & (cu < depth.shape[1]) & (cv < depth.shape[0])
        sel = sel[ok][depth[cv[ok], cu[ok]] > INSIDE_SHARE * radius[sel[ok]]]
    features = None   # where marks are 3 px and more a context model weighs the spots' context (vision.mark_context)
    if context is not None and paint is not None and depth is not None:   # (depth: at 3 px and more, with a body)
        features = context_features(lab, paint, depth, pts[sel], radius[sel], contrast[sel], misfit[sel],
                                    conf[sel], RING_GAPS_PX, prior.extent_px or float(max(h, w)), long_axis[sel])
        keep = context.marks(features) if isinstance(context, MarkScorer) else slice(None)   # "all": every spot
        sel, features = sel[keep], features[keep]
    else:
        if paint is not None and len(sel):  # a mark on a face is ringed by the body's paint
            share = paint_around(paint, pts[sel], radius[sel], RING_GAPS_PX if large else RING_GAPS_PX[:1],
                                 long_axis[sel])
            sel = sel[share >= (CANDIDATE_PAINT_AROUND if scoring else MIN_PAINT_AROUND)]
        if large and len(sel):   # a mark is ringed by one paint it stands out from (along an oblique one's blob)
            sel = sel[surrounded(lab, pts[sel], radius[sel], long_axis=long_axis[sel]) >= MIN_SURROUND]
    pts, labels, conf, radius, contrast = pts[sel], labels[sel], conf[sel], radius[sel], contrast[sel]
    if large and features is None and len(pts) > 2:   # marks of one target share a scale
        keep = one_scale(radius, contrast)
        pts, labels, conf, radius, contrast = pts[keep], labels[keep], conf[keep], radius[keep], contrast[keep]
    if prior.extent_px is not None and len(pts) > 1 and not (large and context == "all"):
        keep = densest_cluster(pts, contrast, 0.75 * prior.extent_px)
        pts, labels, conf, radius, contrast = pts[keep], labels[keep], conf[keep], radius[keep], contrast[keep]
        features = None if features is None else features[keep]
    if body is not None and prior.radius_px[1] < SMALL_SPOT_PX and len(pts):
        # 2-4 px spots: the label through the encoder's 4:2:0 chroma (vision.spot_colour); the crop is even-aligned
        palette_bgr = np.array([palette[n] for n in names], np.uint8)
        if not scoring:
            labels, conf = label_small_spots(bgr, pts, radius, palette_bgr, body)
        else:
            misfit, explained = spot_misfits(bgr, pts, radius, palette_bgr, body)
            labels, conf = labels_of(misfit, explained, CANDIDATE_EXPLAINED)
        kept = labels >= 0
        pts, labels, conf, radius, contrast = pts[kept], labels[kept], conf[kept], radius[kept], contrast[kept]
        if scoring:  # the scorer decides which candidates are marks (vision.mark_scorer)
            features = candidate_features(bgr, lab, pts, radius, contrast, labels, conf, misfit[kept],
                                          explained[kept], paint, sure, prior.extent_px or float(max(h, w)),
                                          palette_bgr, body)
            if isinstance(scorer, MarkScorer):
                probability = scorer.probability(features)
                kept = one_per_disc(pts, probability, prior.radius_px[1])
                kept = kept[probability[kept] >= scorer.threshold]
                pts, labels, conf, radius, contrast, features = (pts[kept], labels[kept], conf[kept], radius[kept],
                                                                 contrast[kept], features[kept])
    order = np.lexsort((pts[:, 0], pts[:, 1], labels)) if len(pts) else np.zeros(0, int)
    areas = np.round(np.pi * radius ** 2).astype(int)
    return ContrastMarks(pts[order].reshape(-1, 2), labels[order].astype(int), areas[order], names,
                         np.zeros(len(order), bool), conf[order], radius[order], contrast[order],
                         None if features is None else features[order])


__all__ = ["ContrastMarks", "MarkPrior", "contrast_responses", "crop_margin", "detect_contrast_marks", "mark_prior",
           "one_per_disc", "one_scale", "scales"]
