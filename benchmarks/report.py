"""Benchmark results as markdown: each benchmark writes one section file, this assembles BENCHMARKS.md.

    python -m benchmarks.report            # benchmarks/results/*.md -> BENCHMARKS.md

Sections keep the command that produced them, so a reader can re-run any one of them.
"""

from __future__ import annotations

import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parents[1]
#: Order of the sections in BENCHMARKS.md (others follow alphabetically).
ORDER = ("solvers", "solver_regression", "softposit", "solver_phases", "confidence", "weights", "kernels", "features", "fleet", "fleet_side_by_side", "frame_path", "latency", "capacity",
         "footprint", "agent_memory", "photoreal_features", "photoreal_features_sweep", "photoreal_features_telephoto_sweep",
         "photoreal_features_opencv_camera", "photoreal_features_train",
         "photoreal_fleet", "photoreal_fleet_long", "photoreal_fleet_paper_long", "photoreal_tracking",
         "photoreal_encoding", "photoreal_looks", "photoreal_looks_husky", "photoreal_looks_bodies_telephoto", "photoreal_looks_context",
         "photoreal_looks_halved", "photoreal_looks_dark_paint", "photoreal_looks_lit_share", "photoreal_looks_lightness", "photoreal_looks_clipped", "photoreal_looks_random_side", "photoreal_looks_edge", "photoreal_looks_stride",
         "photoreal_looks_weighed_misfit", "photoreal_looks_separated_blob",
         "photoreal_looks_train_telephoto",
         "photoreal_fleet_looks",
         "photoreal_fleet_looks_paper", "wrong_frames", "mark_misses", "mark_visibility", "mark_visibility_bodies", "photoreal_fleet_husky", "photoreal_fleet_husky_looks", "photoreal_fleet_husky_long", "photoreal_fleet_pace", "photoreal_fleet_context", "photoreal_fleet_realtime", "photoreal_fleet_looks_long", "photoreal_fleet_clock",
         "frontend_speed", "frame_cost")

#: Titles that several section files share, told apart by what each measures (by file stem).
TITLES = {
    "mark_visibility_bodies": "How much of each mark a look leaves: twelve random robots at telephoto (held out)",
    "solver_regression": "Solver regression check: a fixed problem set against the committed figures",
    "softposit": "SoftPOSIT beside EvoPose and the oracle: telephoto boxes and the paper's scale",
    "solver_phases": "Where a solve's time goes: per phase, before and after",
    "photoreal_features": "Feature front-ends on rendered datasets: the first paper-scale and telephoto datasets",
    "photoreal_features_sweep": "Feature front-ends on rendered datasets: nine paper-scale worlds "
                                "(three geometries, three skies)",
    "photoreal_features_telephoto_sweep": "Feature front-ends on rendered datasets: nine telephoto worlds "
                                          "(three geometries, three skies)",
    "photoreal_features_opencv_camera": "Feature front-ends on rendered datasets: the OpenCV renderer through the "
                                        "camera model",
    "photoreal_fleet": "The fleet on rendered datasets: paper-scale and telephoto worlds, with and without the robot",
    "photoreal_fleet_looks": "The fleet on rendered datasets: nine telephoto worlds through three camera looks",
    "photoreal_fleet_looks_paper": "The fleet on rendered datasets: nine paper-scale worlds through three camera looks",
    "photoreal_fleet_realtime": "The fleet on rendered datasets: 20-frame sequences at 10 fps, the clock's ticks kept",
    "photoreal_fleet_looks_long": "The fleet on rendered datasets: 20-frame sequences at 10 fps through camera looks",
    "photoreal_fleet_clock": "The pair at 10 fps on camera looks: the front-end's time, side by side",
    "photoreal_fleet_husky_looks": "The fleet on rendered datasets: the second robot at telephoto through three looks, "
                                   "side by side",
    "photoreal_fleet_husky": "The fleet on rendered datasets: the second robot (Husky-like UGV) at telephoto",
    "photoreal_fleet_rover": "The fleet on rendered datasets: a robot no rule was chosen on (the orange rover)",
    "photoreal_looks_rover": "Mark front-ends through camera looks: a robot no rule was chosen on (the orange rover)",
    "photoreal_fleet_context": "The fleet on rendered datasets: the telephoto context model as the default, side by "
                               "side",
    "frontend_speed": "Contrast front-end: time per camera image",
    "label_chroma_heldout": "The label gate: 2-4 px marks' chroma against their labels (the benchmark's worlds, random "
                            "looks no bar was chosen on)",
    "frame_cost": "What the camera front-end costs a vehicle per frame",
    "photoreal_looks": "Mark front-ends through camera looks: the Pioneer",
    "photoreal_looks_husky": "Mark front-ends through camera looks: the second robot (Husky-like UGV)",
    "photoreal_looks_bodies_telephoto": "Mark front-ends through camera looks: random robots at telephoto (no rule "
                                        "chosen on them)",
    "photoreal_looks_context": "Mark front-ends through camera looks: the telephoto context model beside the hand-set "
                               "bars",
    "photoreal_looks_halved": "Mark front-ends through camera looks: the scale space halved for large targets, side "
                              "by side",
    "photoreal_looks_clipped": "Mark front-ends through camera looks: a clipped channel as a bound, side by side",
    "photoreal_looks_random_side": "Mark front-ends through camera looks: eight random looks, side by side with "
                                   "5b0a10d",
    "photoreal_looks_edge": "Mark front-ends through camera looks: the edge ratio 100 against 40, side by side",
    "photoreal_looks_stride": "Mark front-ends through camera looks: a large body's look patch on a quarter of the pixels, side by side",
    "photoreal_fleet_husky_long": "The fleet on rendered datasets: the second robot's 20-frame telephoto sequence "
                                  "through camera looks",
    "photoreal_looks_weighed_misfit": "Mark front-ends through camera looks: a label's misfit weighed by the context "
                                      "model, side by side",
    "photoreal_looks_dark_paint": "Mark front-ends through camera looks: a dark paint's fit against its ring's light, "
                                  "side by side",
    "photoreal_looks_lit_share": "Mark front-ends through camera looks: the lit-paint share 0.45 against 0.35, side "
                                 "by side",
    "photoreal_looks_lightness": "Mark front-ends through camera looks: a spot's lightness against its ring, side by "
                                 "side",
    "photoreal_looks_train_telephoto": "Mark front-ends through camera looks: the telephoto training worlds, random "
                                       "looks (where the telephoto rules are chosen)",
}

INTRO = """# Benchmarks

Measured on this project's 2-core development machine, which is shared and noisy: compare solvers
by the ratios measured side by side in one run, not by absolute times across sections.
`make bench` re-runs every section but the agent footprint (`make bench-footprint`, 30 min) and re-assembles
this file (`python -m benchmarks.report`). Every section names the command, the commit and the date that
produced it. Newest first: sections are in the order of the date they were measured, the latest at the top.
`make bench-solver` (about a minute) re-runs the solver on a fixed problem set and fails when its success, accuracy,
evaluations or time got worse than the committed figures ("Solver regression check" below): run it on every change
to the search.
"""

DATE = re.compile(r"\b(20\d\d-\d\d-\d\d)\b")


def code_version() -> str:
    """The commit the benchmark runs, and whether the code has uncommitted changes."""
    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""
    commit = git("rev-parse", "--short", "HEAD") or "unknown commit"
    # the code, not the results a benchmark run is writing
    dirty = git("status", "--porcelain", "--", "agents", "evopose", "scenarios", "protocol", "benchmarks",
                ":(exclude)benchmarks/results")
    return f"{commit} + uncommitted changes" if dirty else commit


def provenance() -> str:
    """Where a section's numbers come from: commit, date, machine, Python, cores."""
    return (f"code at {code_version()}, {time.strftime('%Y-%m-%d', time.gmtime())}, {platform.machine()}, "
            f"Python {platform.python_version()}, {os.cpu_count()} cores")


def md_table(header: list[str], rows: list[list]) -> list[str]:
    """A GitHub markdown table as lines."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return out


def documented_table(command: str, doc: str | None, paragraph: str, header: list[str], rows: list[list]) -> str:
    """A section's body: "Produced by `.venv/bin/COMMAND`" with its :func:`provenance`, the paragraph of the
    benchmark's docstring ``doc`` that starts with ``paragraph`` (what the columns mean), and the table."""
    said = next(part for part in (doc or "").split("\n\n") if part.startswith(paragraph)).replace("\n", " ")
    return "\n".join([f"Produced by `.venv/bin/{command}`; {provenance()}.", "", said, "", *md_table(header, rows)])


def write_section(path: Path, title: str, body: str) -> None:
    """Write one section file (``## title`` + body)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"## {title}\n\n{body.rstrip()}\n")


def anchor(title: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")


def sections(results: Path = RESULTS) -> list[tuple[str, str, str, str]]:
    """``(stem, title, date, body)`` of every section file, newest date first (then :data:`ORDER`). The title is
    the file's ``#``/``##`` heading unless :data:`TITLES` names it; the date is the first ``YYYY-MM-DD`` of the
    body (its provenance). Raises ValueError when two sections share a title or one has no date."""
    found = []
    for path in results.glob("*.md"):
        heading, _, body = path.read_text().partition("\n")
        title = TITLES.get(path.stem, heading.lstrip("#").strip())
        date = DATE.search(body)
        if date is None:
            raise ValueError(f"{path}: no YYYY-MM-DD date in the section (its provenance)")
        found.append((path.stem, title, date.group(1), body.strip("\n")))
    titles = [title for _, title, _, _ in found]
    if len(set(titles)) != len(titles):
        twice = sorted({t for t in titles if titles.count(t) > 1})
        raise ValueError(f"sections share a title: {twice}; name them in benchmarks.report.TITLES")
    position = {stem: i for i, stem in enumerate(ORDER)}
    found.sort(key=lambda s: (s[2], -position.get(s[0], len(ORDER)), s[0]), reverse=True)
    return found


def assemble(results: Path = RESULTS, out: Path = ROOT / "BENCHMARKS.md") -> Path:
    """The section files in ``out``: the intro, a contents list, then each section (``##`` + its one title), newest
    first (:func:`sections`)."""
    found = sections(results)
    contents = ["## Contents", ""] + [f"- [{title}](#{anchor(title)}) ({date})" for _, title, date, _ in found]
    parts = [INTRO, "\n".join(contents)] + [f"## {title}\n\n{body.strip()}" for _, title, _, body in found]
    out.write_text("\n\n".join(p.rstrip() for p in parts) + "\n")
    return out


if __name__ == "__main__":
    print(assemble())
    sys.exit(0)
