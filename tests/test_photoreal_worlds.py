"""The photoreal world sets (benchmarks/photoreal_worlds.py): the committed files are what the generator writes, and
the recoloured training robots are the Pioneer with other paints."""

from pathlib import Path

import numpy as np

from benchmarks import photoreal_worlds as worlds
from scenarios.world import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def test_the_committed_palette_worlds_and_models_are_the_generators(tmp_path, monkeypatch):
    folder = tmp_path / "photoreal-palettes"
    monkeypatch.setitem(worlds.SETS, "palettes", (folder, *worlds.SETS["palettes"][1:]))
    written = worlds.write_worlds("palettes")
    assert len(written) == 12
    for path in written:
        committed = worlds.PALETTE_WORLDS / path.relative_to(folder)
        assert committed.read_text(encoding="utf-8") == path.read_text(encoding="utf-8"), committed
        model = Path("models") / path.name
        assert (worlds.PALETTE_WORLDS / model).read_text(encoding="utf-8") == (folder / model).read_text(
            encoding="utf-8"), model


def test_a_recoloured_robot_is_the_pioneer_with_its_own_body_and_mark_paints():
    pioneer = load_scenario(ROOT / "scenarios" / "exp2-photoreal.yaml").model
    robots = [load_scenario(p).model for p in sorted(worlds.PALETTE_WORLDS.glob("*.yaml"))]
    assert len({r.body_colour for r in robots}) == 12 and pioneer.body_colour not in {r.body_colour for r in robots}
    for robot in robots:
        np.testing.assert_array_equal(robot.mark_points, pioneer.mark_points)
        assert len(set(robot.palette.values())) == 4 and set(robot.palette.values()).isdisjoint(pioneer.palette.values())
