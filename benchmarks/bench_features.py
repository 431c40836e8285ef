"""Feature-extraction benchmark on rendered frames: localisation error, recall, precision, speed.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_features [--frames 20] [--out benchmarks/results/features.md]

For every scenario camera (exp1 ground station, exp2 H1 and H2 with telephoto lenses, and exp2-paper-scale
H1 and H2 at the paper's image scale: the Pioneer ~25 px, its marks 2-4 px across and 3-5 px apart) it
renders seeded frames twice: clean (geometry only) and with the scenario's nuisances (noise, blur, lighting
changes, distractor blobs, occluders). Marks are searched with the target model's palette (what the agents
do) and, for the Pioneer worlds, also with the default search for any saturated hue. A detection within
the camera's match radius of a visible mark's projected centre is a true positive (one-to-one, nearest
first): 3 px, or 1.5 px at the paper's scale, where 3 px is most of the distance between two marks.
Recall counts the fully visible marks; precision counts every detection (a detection of a partly hidden
mark is correct). Extraction speed is CPU time on one core (``cv2.setNumThreads(1)``; ``time.process_time``,
so other processes on a shared machine do not count); rendering speed is wall time.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from vision.features import colour_ranges, detect_colour_marks, match_to_truth
from scenarios.render import render_frame
from scenarios.world import load_scenario

#: (scenario, camera, match radius in pixels, also search any hue)
CAMERAS = (("exp1-airship", "ground-station", 3.0, False), ("exp2", "H1", 3.0, True), ("exp2", "H2", 3.0, True),
           ("exp2-paper-scale", "H1", 1.5, True), ("exp2-paper-scale", "H2", 1.5, True))
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "features.md"


def run_case(scenario_name: str, vehicle: str, frames: list[int], clean: bool, repeats: int, match_px: float,
             any_hue: bool) -> list[dict]:
    """One row per search (palette, and any hue when asked) over the same rendered frames."""
    scenario = load_scenario(scenario_name)
    searches = {"palette": colour_ranges(scenario.model.palette)} | ({"any hue": None} if any_hue else {})
    acc = {name: {"errors": [], "whole": 0, "found": 0, "det": 0, "correct": 0, "extract_s": 0.0}
           for name in searches}
    render_s = 0.0
    for k in frames:
        t0 = time.perf_counter()
        frame = render_frame(scenario, k, vehicle, clean=clean)
        render_s += time.perf_counter() - t0
        truth = frame.truth
        whole = truth.mark_uv[truth.fully_visible]
        for name, ranges in searches.items():
            a = acc[name]
            t0 = time.process_time()   # CPU time of this (single-threaded) process: other load does not count
            for _ in range(repeats):
                det = detect_colour_marks(frame.image, ranges)
            a["extract_s"] += time.process_time() - t0
            pairs, dist = match_to_truth(det.points, whole, match_px)
            any_pairs, _ = match_to_truth(det.points, truth.mark_uv, match_px)
            a["errors"] += dist.tolist()
            a["whole"] += len(whole)
            a["found"] += len(pairs)
            a["det"] += len(det)
            a["correct"] += len(any_pairs)
    rows = []
    for name, a in acc.items():
        err = np.array(a["errors"]) if a["errors"] else np.array([np.nan])
        rows.append({"scenario": scenario_name, "vehicle": vehicle, "clean": clean, "search": name,
                     "frames": len(frames), "marks": a["whole"], "match_px": match_px,
                     "median_px": float(np.median(err)), "p90_px": float(np.percentile(err, 90)),
                     "p95_px": float(np.percentile(err, 95)), "max_px": float(err.max()),
                     "recall": a["found"] / max(a["whole"], 1), "precision": a["correct"] / max(a["det"], 1),
                     "extract_fps": len(frames) * repeats / a["extract_s"], "render_fps": len(frames) / render_s})
    return rows


def markdown(rows: list[dict], command: str, frames: int) -> str:
    lines = [
        "# Feature extraction on rendered frames",
        "",
        f"Produced by `{command}` on {platform.machine()} / Python {platform.python_version()} / "
        f"OpenCV {cv2.__version__}, {time.strftime('%Y-%m-%d')}, load average {os.getloadavg()[0]:.1f} "
        f"on {os.cpu_count()} CPUs (speeds are CPU time; a busy machine still slows them through shared caches).",
        "",
        f"{frames} seeded frames per camera (every few frames of the scenario), 640 x 480. *clean*: geometry only;",
        "*nuisances*: the scenario's sensor noise, blur, lighting changes, distractor blobs in the mark colours",
        "and occluders. *exp2-paper-scale*: exp2 through the lenses of the paper's images (H1 f = 1700 px, H2",
        "f = 1150 px): the Pioneer spans ~25 px, its marks 2-4 px across and 3-5 px apart. Search: *palette*, the",
        "model's mark colours (what the agents use); *any hue*, the default without colours. Localisation error:",
        "detected centroid vs. projected mark centre, over fully visible marks matched within the match radius.",
        "Recall over fully visible marks; precision over all detections (distractors and specks are false",
        "positives). Extraction: frames per CPU second on one core (`cv2.setNumThreads(1)`); render: wall time.",
        "",
        "| scenario | camera | search | frames | marks | match px | median px | p90 px | p95 px | max px | recall "
        "| precision | extract fps | render fps |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['scenario']} | {r['vehicle']} ({'clean' if r['clean'] else 'nuisances'}) | {r['search']} "
                     f"| {r['frames']} | {r['marks']} | {r['match_px']:g} | {r['median_px']:.3f} | {r['p90_px']:.3f} "
                     f"| {r['p95_px']:.3f} | {r['max_px']:.3f} | {r['recall']:.3f} | {r['precision']:.3f} "
                     f"| {r['extract_fps']:.0f} | {r['render_fps']:.0f} |")
    slowest = min(r["extract_fps"] for r in rows if r["search"] == "palette")
    paper = [r for r in rows if r["scenario"] == "exp2-paper-scale" and r["clean"] and r["search"] == "palette"]
    lines += ["", f"Slowest extraction with a palette: {slowest:.0f} frames/s (target: >= 200 frames/s at 640 x 480 "
              "on one core).",
              "Paper scale, clean, palette: recall " + ", ".join(f"{r['vehicle']} {r['recall']:.3f}" for r in paper)
              + "; median centre error " + ", ".join(f"{r['vehicle']} {r['median_px']:.3f} px" for r in paper)
              + " (target: recall >= 0.9, median <= 0.3 px).",
              "Precision below 1 with nuisances comes from the distractor blobs, drawn in the mark colours on",
              "purpose: the detector cannot tell them from marks; the pose search's robust fitness has to.",
              "Any hue: the Pioneer's saturated red body is a candidate too; it is dropped where it encloses marks",
              "(a painted surface), but at ~25 px it can break into pieces between the marks that are kept.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=20, help="frames per camera and condition")
    parser.add_argument("--repeats", type=int, default=20, help="extractions per frame for the speed")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    rows = []
    for scenario_name, vehicle, match_px, any_hue in CAMERAS:
        total = load_scenario(scenario_name).frames
        frames = sorted({int(round(x)) for x in np.linspace(0, total - 1, args.frames)})
        for clean in (True, False):
            rows += run_case(scenario_name, vehicle, frames, clean, args.repeats, match_px, any_hue)
            for r in rows[-(2 if any_hue else 1):]:
                print(f"{scenario_name:16s} {vehicle:15s} {'clean' if clean else 'noisy':6s} {r['search']:8s} "
                      f"median {r['median_px']:.3f} p90 {r['p90_px']:.3f} recall {r['recall']:.3f} "
                      f"precision {r['precision']:.3f} extract {r['extract_fps']:.0f} fps "
                      f"render {r['render_fps']:.0f} fps", flush=True)
    argv_text = " ".join(argv if argv is not None else sys.argv[1:])
    command = f".venv/bin/python -m benchmarks.bench_features {argv_text}".strip()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(rows, command, len(frames)), encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
