"""What the camera front-end costs a vehicle per frame, this tree against another, side by side in one run.

Each tree runs in a fresh interpreter set up as its agent is (``--trees``: this checkout and e.g. ``/work/main``):
its own ``agents.vehicle.threads`` (BLAS, and where the tree does it OpenCV, one thread) and
``agents.vehicle.memory`` (malloc's mmap threshold pinned, a warm-up frame, the free memory returned, then where the
tree has them the frame loop's settings), and plays every camera of each dataset as a vehicle of a pair does: frames 0
and 1 without a pose to look near (the pair's first good pose is frame 1's on these datasets: BENCHMARKS.md, "20-frame
sequences at 10 fps"), then, where the tree's front-end takes one (``near``), around the previous frame's true pose,
the stand-in for the last good one (0.1-0.7 cm off it there). Per frame: wall time, CPU time of the process (user and
system) and page faults. Reports, per dataset and tree, the medians over rounds of the frames' medians and the
largest frame. One process at a time: two agents on the machine's two cores share it, and a pair's frames take longer
(the fleet benchmark, ``bench_photoreal_fleet``, measures those).

    python -m benchmarks.bench_frame_cost --trees . /work/main --rounds 3
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

from scenarios.dataset import DatasetError, open_dataset

from .report import provenance
from .trees import label, run_in_tree

ROOT = Path(__file__).resolve().parents[1]
DATASETS = ("datasets/photoreal-long/photoreal-telephoto-g2-low", "datasets/photoreal-long/photoreal-paper-g2-low")

#: Run inside each tree: per dataset, one row per frame played ``[frame, wall s, user s, system s, page faults]``.
TIMER = r"""
import inspect, json, resource, sys, time
from pathlib import Path
import cv2
from agents.vehicle import memory
from agents.vehicle.threads import limit_blas_threads
from scenarios.dataset import open_dataset
from vision.extract import feature_extractor

limit_blas_threads()
memory.pin_mmap_threshold()
datasets = [open_dataset(Path(p)) for p in sys.argv[1:]]
image = lambda ds, cam, k: cv2.imread(str(ds.image_path(cam, k)), cv2.IMREAD_COLOR)
for ds in datasets:   # the warm-up, as CameraVehicle.warm_up: one frame through a front-end of its own
    world = ds.world()
    feature_extractor("contrast", world.model, world.bounds())(image(ds, ds.cameras[0], 0), ds.camera(ds.cameras[0], 0))
memory.release_free_memory()
if hasattr(memory, "reuse_frame_memory"):
    memory.reuse_frame_memory()

def rss():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS:"))

out = {"file": sys.modules["vision.extract"].__file__, "rss_warm": rss()}
for ds in datasets:
    world = ds.world()
    rows = []
    for cam in ds.cameras:
        extract = feature_extractor("contrast", world.model, world.bounds())
        takes_near = "near" in inspect.signature(extract).parameters
        for k in range(ds.frames):
            picture, camera = image(ds, cam, k), ds.camera(cam, k)
            near = ds.truth(k - 1).target_pose if takes_near and k >= 2 else None
            r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
            extract(picture, camera) if near is None else extract(picture, camera, near)
            t1, r1 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
            rows.append([k, t1 - t0, r1.ru_utime - r0.ru_utime, r1.ru_stime - r0.ru_stime, r1.ru_minflt - r0.ru_minflt])
    out[ds.root.name] = rows
out["rss_end"] = rss()
print(json.dumps(out))
"""


def time_tree(tree: Path, datasets: list[Path]) -> dict:
    """Per dataset, the rows of :data:`TIMER` with ``tree``'s code (a fresh interpreter, cwd ``tree``); and the
    resident memory (bytes) after the warm-up and after every dataset's frames (``rss_warm``, ``rss_end``)."""
    return run_in_tree(tree, TIMER, list(map(str, datasets)))


def summary(rows: list[list[float]]) -> dict[str, float]:
    """Milliseconds (and page faults) per frame: frames 0-1 (no pose) and the later ones."""
    first = [r for r in rows if r[0] < 2]
    later = [r for r in rows if r[0] >= 2]
    return {"first_ms": 1000 * statistics.median(r[1] for r in first),
            "first_cpu_ms": 1000 * statistics.median(r[2] + r[3] for r in first),
            "later_ms": 1000 * statistics.median(r[1] for r in later),
            "later_cpu_ms": 1000 * statistics.median(r[2] + r[3] for r in later),
            "later_max_ms": 1000 * max(r[1] for r in later),
            "system_ms": 1000 * statistics.median(r[3] for r in rows),
            "faults": statistics.median(r[4] for r in rows)}


def markdown(trees: list[Path], medians: dict[str, list[dict[str, float]]], memory: list[tuple[float, float]],
             rounds: int, command: str) -> str:
    names = [label(t) for t in trees]
    lines = ["## What the camera front-end costs a vehicle per frame", "",
             f"Produced by `{command}`; {provenance()}. {rounds} rounds, the trees taking turns in fresh interpreters "
             "set up as each tree's agent is (threads, malloc), one process at a time; each camera of a dataset "
             "played as a vehicle of a pair plays it: frames 0-1 without a pose to look near, the later ones (where "
             "the tree's front-end takes one) near the previous frame's true pose, the stand-in for the last good "
             "one. Medians over rounds of: the frames' median wall and CPU ms (the process's, user and system), "
             "frames 0-1 and frames 2-19, and the largest later frame's wall ms; the median frame's system ms and "
             "page faults. A vehicle at 10 fps has 100 ms a frame for the front-end, the pairing and the search.", "",
             "| dataset | tree | frames 0-1 ms | CPU ms | frames 2-19 ms | CPU ms | largest, 2-19 ms "
             "| system ms | page faults |",
             "|---|---|---|---|---|---|---|---|---|"]
    for dataset, per_tree in medians.items():
        for name, s in zip(names, per_tree):
            lines.append(f"| {dataset} | {name} | {s['first_ms']:.0f} | {s['first_cpu_ms']:.0f} | {s['later_ms']:.0f} "
                         f"| {s['later_cpu_ms']:.0f} | {s['later_max_ms']:.0f} | {s['system_ms']:.0f} "
                         f"| {s['faults']:.0f} |")
    lines += ["", "Resident memory (MB) of each tree's process after its warm-up and after the datasets' frames, "
              "medians over rounds: " + "; ".join(f"{name} {warm / 1e6:.0f} -> {end / 1e6:.0f}"
                                                  for name, (warm, end) in zip(names, memory)) + "."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="*", type=Path, default=[ROOT / d for d in DATASETS])
    parser.add_argument("--trees", nargs="+", type=Path, default=[ROOT],
                        help="checkouts to compare, each with its own agents and vision code")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "frame_cost.md")
    args = parser.parse_args(argv)
    trees = [t.resolve() for t in args.trees]
    datasets = [d.resolve() for d in args.datasets]
    for d in datasets:   # frames 0-1 are timed apart (no pose to look near): a shorter dataset has no later frame
        try:
            frames = open_dataset(d).frames
        except DatasetError as err:
            parser.error(str(err))
        if frames < 3:
            parser.error(f"{d}: {frames} frames; the benchmark needs 3 or more (frames 0-1 without a pose, then later)")
    runs: list[list[dict]] = [[] for _ in trees]
    rss: list[list[tuple[float, float]]] = [[] for _ in trees]
    for _ in range(args.rounds):
        for i, tree in enumerate(trees):
            found = time_tree(tree, datasets)
            rss[i].append((found.pop("rss_warm"), found.pop("rss_end")))
            runs[i].append({name: summary(rows) for name, rows in found.items()})
    medians = {d.name: [{key: statistics.median(r[d.name][key] for r in runs[i]) for key in runs[i][0][d.name]}
                        for i in range(len(trees))] for d in datasets}
    memory = [(statistics.median(w for w, _ in r), statistics.median(e for _, e in r)) for r in rss]
    command = "python -m benchmarks.bench_frame_cost " + " ".join(argv if argv is not None else sys.argv[1:])
    text = markdown(trees, medians, memory, args.rounds, command)
    args.out.write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
