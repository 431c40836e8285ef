"""``evopose train-scorer``: fit the contrast front-end's mark scorer (:mod:`vision.mark_scorer`) on datasets, or
with ``scale="telephoto"`` its context model for marks of 3 px and more (:mod:`vision.mark_context`).

Every camera image of every dataset (docs/datasets.md) goes through the contrast front-end with ``scorer="all"``:
the lenient candidates and their features. A candidate within ``match_px`` of a mark's projected centre (seen or
hidden: the dataset's truth, one to one, nearest first) is a mark. The scorer fitted on them is written as JSON;
the front-end takes it with ``detect_contrast_marks(..., scorer=vision.mark_scorer.load(path))``.

Its threshold keeps as many marks as the hand-set bars do on the same frames (``scorer=None``), judged with each
geometry held out: the scorer is as sensitive as the bars and drops more of the rest. Fewer marks cost the search
more than false points do (on the nine 20-frame Cycles sequences, a scorer at the break-even of kept marks and
precision, recall 0.76 against the bars' 0.81, left the fleet good on 272 of 360 frames against 308).
Only cameras whose marks are under ``SMALL_SPOT_PX`` (the paper's scale) have candidates to score; with
``scale="telephoto"`` only the others, each spot before the hand-set context bars with its context features, matched
within 3 px (the feature benchmark's radius there); the shipped one's threshold keeps 98 % of the marks (``keep``,
the issue's recall bar), each geometry held out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np

from vision import mark_scorer
from vision.mark_context import CONTEXT_FEATURES
from vision.blobs import SMALL_SPOT_PX, detect_contrast_marks, mark_prior
from vision.features import match_to_truth
from scenarios.dataset import open_dataset
from scenarios.looks import apply_look, corner_look, random_look
from scenarios.photoreal.develop import camera_model_of, develop_exr
from scenarios.errors import WorldError

#: A candidate this close to a mark's projection (px) is that mark (the feature benchmark's radius at this scale).
MATCH_PX = 1.5
#: ... per scale: the paper's (marks under SMALL_SPOT_PX) and telephoto (the others).
SCALE_MATCH_PX = {"paper": MATCH_PX, "telephoto": 3.0}


def candidates(directories: Sequence[Path], match_px: float = MATCH_PX,
               progress: Callable[[str], None] | None = None, looks: int = 0, seed: int = 0, scale: str = "paper",
               corner_looks: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...], float]:
    """The features (K, F) of every small-spot candidate in the datasets, whether each is a mark (K,) bool, its
    group (K,): the datasets whose cameras start at the same places (:func:`_place`) are one group, and the feature
    names (:func:`vision.mark_scorer.feature_names`), and the share of the candidates' marks the hand-set bars find.

    ``looks``: each frame of a Cycles dataset that kept its radiance (``raw/*.exr``) is also developed through this
    many random camera looks (:func:`scenarios.looks.random_look`, seeded by ``seed``), the front-end estimating
    each one's look as it does on a camera's images: a scorer that has seen many looks, judged on named ones;
    ``corner_looks``: and through this many looks at the edges of those ranges (:func:`scenarios.looks.corner_look`,
    drawn from the same seed after each frame's random ones), where a camera's settings add up.
    ``scale``: ``"paper"`` (marks under SMALL_SPOT_PX, :mod:`vision.mark_scorer`'s features) or ``"telephoto"``
    (the others, :data:`vision.mark_context.CONTEXT_FEATURES`)."""
    if scale not in SCALE_MATCH_PX:
        raise ValueError(f"scale must be one of {', '.join(SCALE_MATCH_PX)}, got {scale!r}")
    rng = np.random.default_rng(seed)
    rows, marks, groups, names, places = [], [], [], None, {}
    by_bars = 0
    for directory in directories:
        dataset = open_dataset(Path(directory))
        group = places.setdefault(_place(dataset), len(places))
        world = dataset.world()
        area = world.bounds()
        colours = tuple(world.model.palette)
        here = mark_scorer.feature_names(colours) if scale == "paper" else CONTEXT_FEATURES
        if names is not None and here != names:
            raise WorldError(f"{directory}: its model's colours {colours} differ from the first dataset's")
        names = here
        for cam in dataset.cameras:
            for k in range(dataset.frames):
                image = cv2.imread(str(dataset.image_path(cam, k)), cv2.IMREAD_COLOR)
                if image is None:
                    raise WorldError(f"{dataset.image_path(cam, k)}: not an image OpenCV can read")
                prior = mark_prior(dataset.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                                   area.hi[:3])
                if (prior.radius_px[1] >= SMALL_SPOT_PX) != (scale == "telephoto"):
                    continue
                uv = np.array([m.uv for m in dataset.truth(k).cameras[cam].marks], float).reshape(-1, 2)
                exr = Path(directory) / cam / "raw" / f"{k:06d}.exr"
                images = [image]
                drawn = [random_look(rng) for _ in range(looks)] + [corner_look(rng) for _ in range(corner_looks)]
                for look in drawn if exr.is_file() else []:
                    spec = apply_look(camera_model_of(world), look)
                    encoded, _ = develop_exr(world, exr, k, cam, spec)
                    images.append(cv2.imdecode(np.frombuffer(encoded, np.uint8), cv2.IMREAD_COLOR))
                for seen in images:
                    found = detect_contrast_marks(seen, world.model.palette, prior, body=world.model.body_colour,
                                                  scorer="all")
                    if found.features is None or not len(found):
                        continue
                    is_mark = np.zeros(len(found), bool)
                    pairs, _ = match_to_truth(found.points, uv, match_px)
                    is_mark[[i for i, _ in pairs]] = True
                    bars = detect_contrast_marks(seen, world.model.palette, prior, body=world.model.body_colour,
                                                 scorer=None)
                    by_bars += len(match_to_truth(bars.points, uv, match_px)[0])
                    rows.append(found.features)
                    marks.append(is_mark)
                    groups.append(np.full(len(is_mark), group))
        if progress is not None:
            progress(f"{directory}: {sum(len(m) for m in marks)} candidates so far")
    if names is None or not rows:
        raise WorldError(f"no {'small-spot' if scale == 'paper' else 'telephoto'} candidates in the datasets (the "
                         f"scorer is for marks {'under' if scale == 'paper' else 'of'} {SMALL_SPOT_PX} px"
                         f"{'' if scale == 'paper' else ' and more'}: --scale {scale})")
    is_mark = np.concatenate(marks)
    return np.concatenate(rows), is_mark, np.concatenate(groups), names, min(by_bars / max(is_mark.sum(), 1), 1.0)


def _place(dataset) -> tuple:
    """Where the dataset's cameras are at its first frame, to a metre: one geometry under several lights is one
    group (its frames are alike, so a model held out from one dataset is not held out from its geometry)."""
    return tuple((name, *np.round(dataset.camera(name, 0).world_from_camera[:3, 3]).astype(int).tolist())
                 for name in dataset.cameras)


def train(directories: Sequence[Path], out: Path, *, l2: float = 30.0, match_px: float | None = None,
          progress: Callable[[str], None] | None = None, looks: int = 0, seed: int = 0, scale: str = "paper",
          keep: float | None = None, corner_looks: int = 0) -> dict:
    """Fit a scorer on ``directories`` and write it to ``out``; a summary (candidates, marks, threshold, and the
    fitting data's recall and precision of marks among the candidates it keeps). The threshold keeps the share of
    marks the bars find (:func:`vision.mark_scorer.fit` with ``keep``), each geometry (:func:`_place`) scored by
    a model fitted on the others; ``keep``, a share of the marks to keep instead (the shipped context model: 0.98,
    the issue's recall bar). ``match_px`` None: the scale's (:data:`SCALE_MATCH_PX`)."""
    match_px = SCALE_MATCH_PX.get(scale, MATCH_PX) if match_px is None else match_px
    features, is_mark, groups, names, by_bars = candidates(directories, match_px, progress, looks, seed, scale,
                                                           corner_looks)
    fitted_on = "evopose train-scorer " + " ".join(Path(d).name for d in directories) + (
        f" --looks {looks}" if looks else "") + (f" --corner-looks {corner_looks}" if corner_looks else "") + (
        f" --seed {seed}" if looks or corner_looks else "") + (" --scale telephoto" if scale == "telephoto" else "") + (
        f" --keep {keep:g}" if keep is not None else "")
    scorer = mark_scorer.fit(features, is_mark, names, l2=l2, groups=groups, keep=by_bars if keep is None else keep,
                             fitted_on=fitted_on)
    out.parent.mkdir(parents=True, exist_ok=True)
    scorer.save(out)
    kept = scorer.marks(features)
    return {"out": str(out), "candidates": int(len(is_mark)), "marks": int(is_mark.sum()),
            "threshold": scorer.threshold, "kept": int(kept.sum()), "bars_keep": by_bars,
            "marks_kept": float(np.sum(kept & is_mark) / max(is_mark.sum(), 1)),
            "precision": float(np.sum(kept & is_mark) / max(kept.sum(), 1))}


__all__ = ["MATCH_PX", "SCALE_MATCH_PX", "candidates", "train"]
