"""The report's figures: the error series against the world's truth (by hand), and each figure drawn from run
records shaped like `evopose scenario run`'s."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from agents.experiments import figures
from agents.runs import PoseRow
from scenarios.world import load_scenario

WORLD = "exp2-paper-scale-driving"


def published(frames: range, offset=(0.0, 0.0, 0.0), yaw_offset: float = 0.0, good: bool = True) -> list[list]:
    scenario = load_scenario(WORLD)
    rows = []
    for n in frames:
        truth = scenario.target_pose(n % scenario.frames).copy()
        truth[:3] += offset
        truth[5] += yaw_offset
        rows.append(PoseRow(n, tuple(truth), good).to_json())
    return rows


def test_error_series_is_the_distance_to_the_truth_at_each_frame():
    frames = range(37, 57)  # the fleet clock's frames past the world's last: its frame n mod frames
    exact = figures.error_series({"poses": published(frames)}, WORLD)
    assert list(exact[0]) == list(range(20)) and np.allclose(exact[1], 0) and np.allclose(exact[2], 0)
    off = figures.error_series({"poses": published(frames, (0.3, -0.4, 0.0), 2 * np.pi - np.radians(1.5),
                                                   good=False)}, WORLD)
    assert np.allclose(off[1], 0.5) and np.allclose(off[2], 1.5) and not off[3].any()
    assert all(len(a) == 0 for a in figures.error_series({"poses": []}, WORLD))


def test_every_figure_is_drawn_from_its_run_records(tmp_path):
    """Each figure is an image of the records it was given: other records (errors 0.5 m instead of 1-2 cm, other
    byte rates, another fitness history) draw another image."""
    def record(scenario: str, world: str, run: int, error_m: float) -> dict:
        agents = {v: {"poses": published(range(100, 130), (error_m * (run + 1), 0, 0))} for v in ("H1", "H2")}
        return {"scenario": scenario, "world": world, "variant": "H1+H2", "run": run, "agents": agents}

    def rows(scale: float) -> list[dict]:
        return [{"scenario": s, "vehicle": "H1", "world": WORLD, "history": [3.0 * scale, 2.0, 1.0],
                 "traffic": {t: {"bytes_per_s": b * scale}}}
                for s, t, b in (("exp2-raw", "image", 9.2e6), ("exp2a-features", "features", 4000.0),
                                ("exp2b-hints", "hint", 4800.0))]

    def draw(error_m: float, scale: float, folder) -> list:
        folder.mkdir()
        records = [record(s, WORLD, r, error_m) for s in ("exp2-solo", "exp2a-features", "exp2b-hints") for r in (0, 1)]
        paths = [figures.error_over_time(records, folder / "error.png", WORLD),
                 figures.tracks_from_above(records, folder / "tracks.png", WORLD),
                 figures.bandwidth(rows(scale), folder / "bandwidth.png", [WORLD]),
                 figures.figure_6({"H1 + H2": rows(scale)[1]}, folder / "fig6.png", WORLD)]
        return [cv2.imread(str(path)) for path in paths]

    first, other = draw(0.01, 1.0, tmp_path / "a"), draw(0.5, 3.0, tmp_path / "b")
    for name, a, b in zip(("error", "tracks", "bandwidth", "fig6"), first, other):
        assert a is not None and a.shape[0] > 300 and a.std() > 10, name
        assert a.shape != b.shape or np.abs(a.astype(int) - b).sum() > 0, f"{name} does not depend on its records"


@pytest.mark.parametrize("missing", ["exp2a-features", "exp2b-hints"])
def test_a_mode_that_did_not_run_is_left_out(tmp_path, monkeypatch, missing):
    """The figures name only the modes that ran: one panel from above, one line per helicopter's error plot."""
    from matplotlib.figure import Figure

    drawn: list[Figure] = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda fig, *args, **kwargs: (drawn.append(fig), save(fig, *args, **kwargs)))
    ran = "exp2b-hints" if missing == "exp2a-features" else "exp2a-features"
    records = [{"scenario": ran, "world": WORLD, "variant": "v", "run": 0, "agents": {"H1": {"poses": published(
        range(5))}}}]
    assert cv2.imread(str(figures.tracks_from_above(records, tmp_path / "t.png", WORLD))) is not None
    assert [ax.get_title() for ax in drawn[-1].axes] == [f"{figures.SHARE_LABELS[ran]}, {WORLD}"]
    assert cv2.imread(str(figures.error_over_time(records, tmp_path / "e.png", WORLD))) is not None
    legend = drawn[-1].axes[0].get_legend()
    assert [text.get_text() for text in legend.get_texts()] == [figures.SHARE_LABELS[ran]]
    assert figures.SHARE_LABELS[missing] not in {line.get_label() for ax in drawn[-1].axes for line in ax.lines}
