"""BENCHMARKS.md as benchmarks/report.py assembles it: one title per section, a contents list that links each one,
the newest figure first; and the file in the repository is what the assembler makes of benchmarks/results/."""

from __future__ import annotations

import re

import pytest

from benchmarks.report import anchor, assemble, sections
from tests.fleet_procs import ROOT


def headings(text: str) -> list[str]:
    return [line[3:] for line in text.splitlines() if line.startswith("## ")]


def test_benchmarks_md_is_assembled_with_unique_titles_contents_and_newest_first(tmp_path):
    out = assemble(out=tmp_path / "BENCHMARKS.md")
    text = out.read_text()
    assert text == (ROOT / "BENCHMARKS.md").read_text(), "BENCHMARKS.md is stale: run python -m benchmarks.report"
    assert not [line for line in text.splitlines() if re.match(r"# ", line)][1:], "one top-level title only"
    titles = headings(text)
    assert titles[0] == "Contents" and len(set(titles)) == len(titles), titles
    links = re.findall(r"^- \[(.*)\]\(#(.*)\) \((\d{4}-\d\d-\d\d)\)$", text, re.M)
    assert [title for title, _, _ in links] == titles[1:]
    assert all(target == anchor(title) for title, target, _ in links)
    dates = [date for _, _, date in links]
    assert dates == sorted(dates, reverse=True), dates


def test_a_title_shared_by_two_sections_is_refused(tmp_path):
    for name in ("a", "b"):
        (tmp_path / f"{name}.md").write_text("## Same title\n\nProduced by `x`; 2026-01-01.\n")
    with pytest.raises(ValueError, match="share a title"):
        sections(tmp_path)


def test_anchor_is_githubs():
    assert anchor("Eq. (4) view weights: equal, step") == "eq-4-view-weights-equal-step"
    assert anchor("A frame's path through the code") == "a-frames-path-through-the-code"
