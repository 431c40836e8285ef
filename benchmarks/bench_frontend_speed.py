"""How long the contrast front-end takes per camera image, this tree against another, side by side in one run.

Each round times every image of the committed Cycles fixtures (``tests/data/photoreal/*``: both scales, looks, the
second robot) through :func:`vision.blobs.detect_contrast_marks` with the look estimated, once per tree, the trees
taking turns in fresh interpreters (``--trees``: this checkout and e.g. a ``git worktree`` of an older commit; a
tree from before the ``vision/`` room imports ``evopose.blobs``). One OpenCV thread. Each image is timed
``--repeats`` times in a round and its least time kept (what the code costs, not what else the machine did). Reports
the median over rounds of each tree's mean milliseconds per image, per fixture, and the ratio to the first tree. A
camera at 10 fps has 100 ms per frame for the front-end and the search together.

    python -m benchmarks.bench_frontend_speed --trees . /tmp/base --rounds 5 --repeats 3
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

from .report import provenance
from .trees import label, run_in_tree

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ("paper", "paper-agx", "paper-flat-cool", "telephoto", "telephoto-agx", "telephoto-flat-cool",
            "husky-paper", "husky-telephoto")

#: Run inside each tree: mean seconds per image of each fixture, as JSON on stdout.
TIMER = r"""
import json, os, sys, time
from pathlib import Path
import cv2, numpy as np
if Path("vision/blobs.py").exists():   # the tree's own room (an editable install maps names to another tree)
    from vision.blobs import detect_contrast_marks, mark_prior
else:
    from evopose.blobs import detect_contrast_marks, mark_prior
from scenarios.dataset import open_dataset
cv2.setNumThreads(1)
out = {"module": detect_contrast_marks.__module__, "file": sys.modules[detect_contrast_marks.__module__].__file__}
for path in sys.argv[1:]:
    ds = open_dataset(Path(path)); world = ds.world(); area = world.bounds()
    body = world.model.body_colour   # once per robot, as an agent reads it (an older tree computes it per access)
    jobs = []
    for cam in ds.cameras:
        for k in range(ds.frames):
            image = cv2.imread(str(ds.image_path(cam, k)), cv2.IMREAD_COLOR)
            prior = mark_prior(ds.camera(cam, k), world.model.mark_radius, world.model.size, area.lo[:3], area.hi[:3])
            jobs.append((image, prior))
    detect_contrast_marks(jobs[0][0], world.model.palette, jobs[0][1], body=body)   # warm-up
    least = []   # each image's least time over the repeats: what the code costs, not what the machine did meanwhile
    for image, prior in jobs:
        times = []
        for _ in range(int(os.environ.get("BENCH_REPEATS", "1"))):
            start = time.perf_counter()
            detect_contrast_marks(image, world.model.palette, prior, body=body, look="auto")
            times.append(time.perf_counter() - start)
        least.append(min(times))
    out[Path(path).name] = sum(least) / len(jobs)
print(json.dumps(out))
"""


def time_tree(tree: Path, fixtures: list[Path], repeats: int = 1) -> dict[str, float]:
    """Mean seconds per image of each fixture (each image's least over ``repeats``), with ``tree``'s code (a fresh
    interpreter, cwd ``tree``)."""
    times = run_in_tree(tree, TIMER, list(map(str, fixtures)), {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                                                                 "BENCH_REPEATS": str(repeats)})
    times.pop("module")
    return times


def markdown(trees: list[Path], medians: dict[str, list[float]], rounds: int, repeats: int, command: str) -> str:
    names = [label(t) for t in trees]
    lines = ["## Contrast front-end time per image, side by side", "",
             f"Produced by `{command}`; {provenance()}. {rounds} rounds, the trees taking turns in fresh "
             "interpreters, one OpenCV "
             "thread; the median over rounds of each tree's mean milliseconds per image of each committed fixture "
             f"(both cameras, 2 frames each, the look estimated; each image's least time over {repeats} repeats "
             "within a round). The ratio is the first tree's time over each other's.", "",
             "| fixture | " + " | ".join(f"{n} ms" for n in names) + " | " +
             " | ".join(f"{names[0]} / {n}" for n in names[1:]) + " |",
             "|---|" + "---|" * (2 * len(names) - 1)]
    for fixture, per_tree in medians.items():
        ms = [1000 * t for t in per_tree]
        lines.append(f"| {fixture} | " + " | ".join(f"{m:.0f}" for m in ms) + " | " +
                     " | ".join(f"{ms[0] / m:.2f}" for m in ms[1:]) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs="+", type=Path, default=[ROOT],
                        help="checkouts to compare (the first is the reference of the ratios)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3, help="each image this many times a round, its least kept")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "frontend_speed.md")
    args = parser.parse_args(argv)
    trees = [t.resolve() for t in args.trees]
    fixtures = [ROOT / "tests" / "data" / "photoreal" / f for f in FIXTURES]
    runs: list[list[dict[str, float]]] = [[] for _ in trees]
    for _ in range(args.rounds):
        for i, tree in enumerate(trees):
            runs[i].append(time_tree(tree, fixtures, args.repeats))
    medians = {f.name: [statistics.median(r[f.name] for r in runs[i]) for i in range(len(trees))] for f in fixtures}
    command = "python -m benchmarks.bench_frontend_speed " + " ".join(argv if argv is not None else sys.argv[1:])
    text = markdown(trees, medians, args.rounds, args.repeats, command)
    args.out.write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
