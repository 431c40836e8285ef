"""Two checkouts side by side: a timing script run in a fresh interpreter with one tree's code, and a tree's name
(the benchmarks that compare codes in one run: bench_frontend_speed, bench_frame_cost)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


def run_in_tree(tree: Path, script: str, args: list[str], env: dict[str, str] | None = None) -> dict:
    """The JSON object the ``script`` (Python source) prints last, run with ``args`` in a fresh interpreter whose
    cwd and only import path is ``tree`` (plus ``env``). The script reports the file it imported the front-end from
    as ``"file"`` (popped): from another tree, or a failed run, ends the benchmark with one line saying so."""
    out = subprocess.run([sys.executable, "-c", script, *args], cwd=tree, capture_output=True, text=True,
                         timeout=900, env={"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin", **(env or {})})
    if out.returncode:
        raise SystemExit(f"{tree}: {out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode}")
    found = json.loads(out.stdout.strip().splitlines()[-1])
    if not Path(found.pop("file")).resolve().is_relative_to(tree):
        raise SystemExit(f"{tree}: the front-end was imported from another tree")
    return found


def label(tree: Path) -> str:
    """A tree by its commit (short hash; "+ changes" when tracked files differ from it), or its folder's name."""
    out = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    changed = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
                             capture_output=True, text=True).stdout.strip()
    return (out.stdout.strip() + (" + changes" if changed else "")) or tree.name


__all__ = ["label", "run_in_tree"]
