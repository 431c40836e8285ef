"""Benchmark results as markdown: each benchmark writes one section file, this assembles BENCHMARKS.md.

    python -m benchmarks.report            # benchmarks/results/*.md -> BENCHMARKS.md

Sections keep the command that produced them, so a reader can re-run any one of them.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parents[1]
#: Order of the sections in BENCHMARKS.md (others follow alphabetically).
ORDER = ("solvers", "confidence", "weights", "kernels", "features", "fleet", "frame_path", "latency", "capacity",
         "footprint", "photoreal_features", "photoreal_features_sweep", "photoreal_features_telephoto_sweep",
         "photoreal_features_opencv_camera", "photoreal_features_train",
         "photoreal_fleet", "photoreal_fleet_long", "photoreal_fleet_paper_long", "photoreal_tracking",
         "photoreal_encoding")

INTRO = """# Benchmarks

Measured on this project's 2-core development machine, which is shared and noisy: compare solvers
by the ratios measured side by side in one run, not by absolute times across sections.
`make bench` re-runs every section but the agent footprint (`make bench-footprint`, 30 min) and re-assembles
this file (`python -m benchmarks.report`). Every section names the command, the commit and the date that
produced it.
"""


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


def assemble(results: Path = RESULTS, out: Path = ROOT / "BENCHMARKS.md") -> Path:
    """Concatenate the section files in :data:`ORDER` into ``out``."""
    files = sorted(results.glob("*.md"), key=lambda p: (ORDER.index(p.stem) if p.stem in ORDER else len(ORDER),
                                                        p.stem))
    parts = [INTRO] + [f.read_text() for f in files]
    out.write_text("\n".join(p.rstrip() + "\n" for p in parts))
    return out


if __name__ == "__main__":
    print(assemble())
    sys.exit(0)
