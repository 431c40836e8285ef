"""Where the contrast front-end loses the marks it misses, per camera look and scale: a census (issue 32).

Run from the repository root on Cycles datasets that kept their radiance (``raw/*.exr``; docs/datasets.md)::

    .venv/bin/python -m benchmarks.bench_mark_misses datasets/photoreal-paper/photoreal-paper-g*

Each frame is developed through each look as in ``benchmarks/bench_photoreal_looks.py`` and the front-end runs as the
agents run it (:func:`vision.blobs.detect_contrast_marks`, the look estimated and undone). Each fully visible mark it
misses (matched within 1.5 px at the paper's scale, 3 px at telephoto) is then looked for again with the front-end's
bars loosened one after the other, each loosening kept for the next, and counted under the first that finds it:

* *scorer / context*: every candidate before the decision that keeps marks (under 3 px the shipped scorer,
  :mod:`vision.mark_scorer`; from 3 px the context model, :mod:`vision.mark_context`);
* *label*: any label misfit, no least brightness, no least share explained (:mod:`vision.spot_label`,
  :mod:`vision.spot_colour`): the spot's colour fits no paint as the look was undone;
* *edge*: any Hessian ratio (:data:`vision.blobs.MAX_EDGE_RATIO`): the response is a ridge, not a spot;
* *weak peak*: a local maximum of the response above the ground's median but under the candidates' bar (in the
  ground's robust spreads: :data:`vision.blobs.CANDIDATE_K_SIGMA` under 3 px, else :data:`vision.blobs.K_SIGMA`): the
  mark stands out from the ground's texture less than the bar asks;
* *off the body*: found only without the body's context, at the candidates' own bar (the body's paint was not
  found around it, :mod:`vision.body_paint`);
* *no peak*: none of these finds it: no local maximum of the scale space's response within the match radius (a mark
  merged with a neighbour, blurred or darkened under the ground's texture; or a long ellipse, a disc seen at a grazing
  angle, whose response peaks near its ends), or its peak lost to a stronger one within its radius (every run keeps one
  detection per place, :func:`vision.mark_selection.same_spots`).

A *weak peak* carries too little contrast for this front-end's detector, and so may a *no peak* mark; the others were
seen and rejected by a later decision. A diagnostic: the bars are loosened by setting the front-end's
module constants for one call each (restored after), so it runs in its own worker processes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from unittest import mock

import cv2
import numpy as np

from .bench_mark_visibility import mark_contrast, outlines_in
from .bench_photoreal_looks import _scale_of, add_dataset_arguments, chosen_looks, look_of
from .report import provenance

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "mark_misses.md"
#: The causes, in the order the bars are loosened (the module's docstring), then the remainder.
CAUSES = ("scorer / context", "label", "edge", "weak peak", "off the body", "no peak")


@contextmanager
def _loosened(**constants: float):
    """The front-end's module constants of :mod:`vision.blobs` set for the block (``NAME=value``), restored after."""
    import vision.blobs as blobs

    with mock.patch.multiple(blobs, **constants):
        yield


def _detections(image: np.ndarray, world, prior, look) -> list:
    """The front-end's detections of one image, as shipped and with each loosening of :data:`CAUSES` in turn."""
    from vision.blobs import detect_contrast_marks

    model = world.model

    def run(**kw):
        body = kw.pop("body", model.body_colour)
        return detect_contrast_marks(image, model.palette, prior, body=body, look=look, **kw).points

    anything = dict(max_misfit=1e9)   # (an infinite bar: no label, no Hessian test passes)
    out = [run(), run(scorer="all")]
    with _loosened(CANDIDATE_EXPLAINED=0.0, MIN_RELATIVE_BRIGHTNESS=0.0):
        out.append(run(scorer="all", **anything))
        out.append(run(scorer="all", max_edge_ratio=1e9, **anything))
        with _loosened(CANDIDATE_K_SIGMA=0.0):
            out.append(run(scorer="all", max_edge_ratio=1e9, k_sigma=0.0, max_marks=1024, **anything))
        out.append(run(body=None, scorer="all", max_edge_ratio=1e9, **anything))
    return out


def census(directory: Path, look: str, frames: int | None) -> dict:
    """Counts of one dataset developed through ``look``: fully visible marks, found, and missed per cause."""
    from scenarios.dataset import open_dataset
    from scenarios.photoreal.develop import camera_model_of, develop_exr
    from vision.blobs import SMALL_SPOT_PX, mark_prior
    from vision.camera_look import estimate_look
    from vision.features import match_to_truth

    cv2.setNumThreads(1)
    dataset = open_dataset(directory)
    world = dataset.world()
    area = world.bounds()
    spec = look_of(camera_model_of(world), look)
    counts: Counter = Counter()
    missed = []
    for cam in dataset.cameras:
        for k in range(dataset.frames if frames is None else min(frames, dataset.frames)):
            encoded, _ = develop_exr(world, Path(directory) / cam / "raw" / f"{k:06d}.exr", k, cam, spec)
            image = cv2.imdecode(np.frombuffer(encoded, np.uint8), cv2.IMREAD_COLOR)
            marks = dataset.truth(k).cameras[cam].marks
            fully = np.array([m.fully_visible for m in marks], bool)
            whole = np.array([m.uv for m in marks], float).reshape(-1, 2)[fully]
            contrast = None   # each fully visible mark's Delta E*ab, once a mark of the frame is missed
            prior = mark_prior(dataset.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3],
                               area.hi[:3])
            match_px = 1.5 if prior.radius_px[1] < SMALL_SPOT_PX else 3.0
            stages = _detections(image, world, prior, estimate_look(image, world.model.body_colour, prior.extent_px))
            for j in range(len(whole)):
                hit = [len(points) > 0 and len(match_to_truth(points, whole[j:j + 1], match_px)[0]) > 0
                       for points in stages]
                counts["visible"] += 1
                if hit[0]:
                    counts["found"] += 1
                else:
                    cause = next((c for c, h in zip(CAUSES, hit[1:]) if h), CAUSES[-1])
                    counts[cause] += 1
                    if contrast is None:
                        outlines = outlines_in(dataset, cam, k, np.array([m.index for m in marks]))
                        contrast = mark_contrast(image, outlines)[fully]
                    missed.append({"dataset": directory.name, "look": look, "camera": cam, "frame": k,
                                   "uv": whole[j].round(1).tolist(), "cause": cause,
                                   "delta_e": round(float(contrast[j]), 1)})
    return {"model": world.model.name, "scale": _scale_of(dataset.manifest.world), "look": look,
            "counts": dict(counts), "missed": missed}


def markdown(rows: list[dict], command: str, looks: list[str]) -> str:
    lines = ["## Where the front-end loses marks: a census per look", "",
             f"Produced by `{command}`; {provenance()}, OpenCV {cv2.__version__}.", "",
             " ".join(__doc__.split("\n\n")[3].split()), "",
             *("* " + " ".join(item.split()) for item in __doc__.split("\n\n")[4].split("* ")[1:]), "",
             " ".join(__doc__.split("\n\n")[5].split()), ""]
    for model, scale in sorted({(r["model"], r["scale"]) for r in rows}):
        lines += [f"### {model}, {scale} scale", "", "| look | fully visible | found | " + " | ".join(CAUSES) + " |",
                  "|---|---|---|" + "---|" * len(CAUSES)]
        for look in looks:
            total: Counter = Counter()
            for r in rows:
                if (r["model"], r["scale"], r["look"]) == (model, scale, look):
                    total.update(r["counts"])
            if total["visible"]:
                share = total["found"] / total["visible"]
                lines.append(f"| {look} | {total['visible']} | {total['found']} ({share:.3f}) | "
                             + " | ".join(str(total[c]) for c in CAUSES) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_dataset_arguments(parser, DEFAULT_OUT)
    parser.add_argument("--misses", type=Path, default=None,
                        help="also write every missed mark, with its Delta E*ab from its ring (JSON lines; "
                             "benchmarks/bench_mark_visibility.py)")
    args = parser.parse_args(argv)
    looks = chosen_looks(parser, args)
    jobs = [(d, lk, args.frames) for lk in looks for d in args.datasets]
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        rows = list(pool.map(census, *zip(*jobs)))
    command = ".venv/bin/python -m benchmarks.bench_mark_misses " + " ".join(sys.argv[1:] if argv is None else argv)
    args.out.write_text(markdown(rows, command, looks))
    if args.misses is not None:
        args.misses.write_text("".join(json.dumps(m) + "\n" for r in rows for m in r["missed"]))
    print(f"wrote {args.out} ({os.path.getsize(args.out)} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
