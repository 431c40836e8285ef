"""The photoreal world sets (benchmarks/photoreal_worlds.py): the committed files are what the generator writes, the
recoloured training robots are the Pioneer with other paints, and the random training robots
(benchmarks/random_bodies.py) are marked on their faces where no dark part covers them."""

from pathlib import Path

import numpy as np
import pytest

from benchmarks import photoreal_worlds as worlds
from benchmarks.random_bodies import random_body_model
from scenarios.target import ModelFileSpec, model_from_spec
from scenarios.world import load_scenario

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("world_set, count", [("palettes", 12), ("bodies", 24), ("bodies-dev", 24)])
def test_the_committed_training_robots_worlds_and_models_are_the_generators(tmp_path, monkeypatch, world_set, count):
    """Recoloured robots at the paper's scale; random robots at both scales (each world its own robot), the
    development set's other robots than the training set's."""
    committed_folder = worlds.SETS[world_set][0]
    folder = tmp_path / world_set
    monkeypatch.setitem(worlds.SETS, world_set, (folder, *worlds.SETS[world_set][1:]))
    written = worlds.write_worlds(world_set)
    assert len(written) == count
    for path in written:
        committed = committed_folder / path.relative_to(folder)
        assert committed.read_text(encoding="utf-8") == path.read_text(encoding="utf-8"), committed
        model = Path("models") / path.name
        assert (committed_folder / model).read_text(encoding="utf-8") == (folder / model).read_text(
            encoding="utf-8"), model
    if world_set == "bodies-dev":   # none of the training robots
        names = {(folder / "models" / p.name).read_text(encoding="utf-8").splitlines()[1] for p in written}
        trained = {p.read_text(encoding="utf-8").splitlines()[1]
                   for p in (worlds.BODY_WORLDS / "models").glob("*.yaml")}
        assert len(names) == count and not names & trained


def _on_box_face(point: np.ndarray, centre: np.ndarray, size: np.ndarray, normal: np.ndarray) -> bool:
    axis = int(np.argmax(np.abs(normal)))
    half = size / 2
    on_plane = np.isclose(point[axis], centre[axis] + np.sign(normal[axis]) * half[axis], atol=1e-3)
    inside = all(abs(point[k] - centre[k]) < half[k] for k in range(3) if k != axis)
    return bool(on_plane and inside)


@pytest.mark.parametrize("seed", range(40))
def test_a_random_robot_is_marked_on_its_painted_faces_clear_of_its_dark_parts(seed):
    doc = random_body_model(seed)
    model = model_from_spec(ModelFileSpec.model_validate(doc))
    body = doc["parts"][0]
    centre, size = np.array(body["box"]["centre"]), np.array(body["box"]["size"])
    assert model.body_colour == tuple(body["colour"])          # the paint a camera sees around the marks
    assert len(model.mark_points) >= 6 and set(m["colour"] for m in doc["marks"]) == set(doc["colours"])
    radius = doc["mark_radius"]
    for mark in doc["marks"]:
        p, n = np.array(mark["position"]), np.array(mark["normal"])
        assert _on_box_face(p, centre, size, n), mark
        for part in doc["parts"][1:]:   # no dark part covers a mark: its disc is clear of the part's box
            shape = part.get("box") or part["ellipsoid"]
            c = np.array(shape["centre"])
            half = np.array(shape["size"]) / 2 if "box" in part else np.array(shape["semi_axes"])
            near = np.all(np.abs(p - c) < half + radius, axis=0)
            assert not near, (mark, part)


def test_random_robots_differ_in_shape_and_parts():
    docs = [random_body_model(seed) for seed in range(12)]
    sizes = {tuple(d["parts"][0]["box"]["size"]) for d in docs}
    assert len(sizes) == 12
    # dark parts: a plate is one box, bumpers two, wheels four ellipsoids
    kinds = {(sum("box" in p for p in d["parts"][1:]), sum("ellipsoid" in p for p in d["parts"][1:])) for d in docs}
    assert len(kinds) >= 4, kinds


def test_a_recoloured_robot_is_the_pioneer_with_its_own_body_and_mark_paints():
    pioneer = load_scenario(ROOT / "scenarios" / "exp2-photoreal.yaml").model
    robots = [load_scenario(p).model for p in sorted(worlds.PALETTE_WORLDS.glob("*.yaml"))]
    assert len({r.body_colour for r in robots}) == 12 and pioneer.body_colour not in {r.body_colour for r in robots}
    for robot in robots:
        np.testing.assert_array_equal(robot.mark_points, pioneer.mark_points)
        assert len(set(robot.palette.values())) == 4 and set(robot.palette.values()).isdisjoint(pioneer.palette.values())
