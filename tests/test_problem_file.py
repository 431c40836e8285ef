"""The pose-problem file (docs/design.md §3): loading, validation messages, round trip, output object."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from agents.problem.problem_file import ProblemFileError, load_problem, problem_to_dict, solution_to_dict
from benchmarks.problems import make_problem
from evopose import Camera, PoseProblem, SearchOptions, Solution, View
from examples.make_examples import EXAMPLES, EXAMPLES_DIR, render

DESIGN_KEYS = {"pose", "fitness", "generations", "evaluations", "seconds", "converged"}
POSE_KEYS = {"x", "y", "z", "roll", "pitch", "yaw", "quaternion"}


def minimal_document() -> dict:
    """A small valid problem: four model points seen by one camera."""
    return {
        "model": {"points": [[0, 0, 0], [0.2, 0, 0], [0, 0.2, 0], [0, 0, 0.2]]},
        "views": [{"camera": {"fx": 800, "fy": 800, "cx": 320, "cy": 240, "width": 640, "height": 480},
                   "points": [[320, 240], [352, 240], [320, 272], [330, 250]]}],
        "search": {"x": [-1, 1], "y": [-1, 1], "z": [2, 8]},
    }


def write_yaml(tmp_path: Path, document, name: str = "problem.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(document, sort_keys=False), encoding="utf-8")
    return path


def load_error(tmp_path: Path, document) -> str:
    with pytest.raises(ProblemFileError) as info:
        load_problem(write_yaml(tmp_path, document))
    message = str(info.value)
    assert "\n" not in message
    return message


# -- valid files ---------------------------------------------------------------------------------

def test_minimal_file_loads_with_defaults(tmp_path):
    problem, options, seed = load_problem(write_yaml(tmp_path, minimal_document()))
    assert problem.model.points.shape == (4, 3) and problem.model.normals is None
    assert len(problem.views) == 1 and problem.views[0].points.shape == (4, 2)
    assert problem.views[0].weight == 1.0
    np.testing.assert_array_equal(problem.views[0].camera.world_from_camera, np.eye(4))
    np.testing.assert_array_equal(problem.bounds.lo, [-1, -1, 2, -np.pi, -np.pi, -np.pi])
    np.testing.assert_array_equal(problem.bounds.hi, [1, 1, 8, np.pi, np.pi, np.pi])
    assert problem.bounds.periodic.tolist() == [False, False, False, True, True, True]
    assert problem.hints.shape == (0, 6)
    assert options == SearchOptions() and seed is None


def test_labels_type_the_points(tmp_path):
    """Colour classes of the model's marks and of a view's points (our extension of eq. 1) load and round-trip."""
    document = minimal_document()
    document["model"]["labels"] = [0, 1, 2, 3]
    document["views"][0]["labels"] = [0, 1, 2, 3]
    problem, _, _ = load_problem(write_yaml(tmp_path, document))
    assert problem.model.labels.tolist() == [0, 1, 2, 3] and problem.views[0].labels.tolist() == [0, 1, 2, 3]
    assert problem_to_dict(problem)["views"][0]["labels"] == [0, 1, 2, 3]
    assert problem_to_dict(problem)["model"]["labels"] == [0, 1, 2, 3]


def test_json_file_loads_like_yaml(tmp_path):
    document = minimal_document() | {"seed": 7}
    path = tmp_path / "problem.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    problem, _, seed = load_problem(path)
    from_yaml, _, _ = load_problem(write_yaml(tmp_path, document))
    assert seed == 7
    np.testing.assert_array_equal(problem.views[0].points, from_yaml.views[0].points)


def test_every_optional_field(tmp_path):
    document = minimal_document() | {
        "constraints": {"roll": {"value": 0.1, "tolerance": 0.002}, "z": {"value": 5.0, "tolerance": 0.0}},
        "hints": [{"x": 0.1, "y": 0.2, "z": 5, "roll": 0.1, "pitch": 0, "yaw": 1}],
        "seed": 3,
        "options": {"fitness": "paper", "time_budget": 1.5, "max_generations": 20, "good_fitness": 0.5},
    }
    document["model"]["normals"] = [[0, 0, -2], [0, 0, -1], [0, 0, -1], [0, 0, -1]]
    camera = document["views"][0]["camera"]
    camera["distortion"] = [0.1, -0.01, 0.001, 0.0, 0.002]
    camera["world_from_camera"] = {"x": 1, "y": 0, "z": 0, "roll": 0, "pitch": 0, "yaw": 0.5}
    document["views"].append({"camera": {**camera}, "points": [[1, 2]], "weight": 0.0})
    problem, options, seed = load_problem(write_yaml(tmp_path, document))
    np.testing.assert_allclose(problem.bounds.lo[[2, 3]], [5.0, 0.098])
    np.testing.assert_allclose(problem.bounds.hi[[2, 3]], [5.0, 0.102])
    assert not problem.bounds.free[2]
    np.testing.assert_array_equal(problem.hints, [[0.1, 0.2, 5, 0.1, 0, 1]])
    np.testing.assert_allclose(problem.model.normals[0], [0, 0, -1])
    cam = problem.views[0].camera
    np.testing.assert_array_equal(cam.distortion, [0.1, -0.01, 0.001, 0.0, 0.002])
    np.testing.assert_allclose(cam.world_from_camera[:3, 3], [1, 0, 0])
    assert [v.weight for v in problem.views] == [1.0, 0.0]
    assert (options.fitness, options.time_budget, options.max_generations, options.good_fitness) == \
        ("paper", 1.5, 20, 0.5)
    assert seed == 3


def test_yaml_exponent_without_dot_is_a_number(tmp_path):
    text = yaml.safe_dump(minimal_document()) + "constraints: {roll: {value: 1e-1, tolerance: 2E-3}}\n"
    path = tmp_path / "problem.yaml"
    path.write_text(text, encoding="utf-8")
    problem, _, _ = load_problem(path)
    np.testing.assert_allclose([problem.bounds.lo[3], problem.bounds.hi[3]], [0.098, 0.102])


@pytest.mark.parametrize("kind", ["box", "ellipsoid", "random", "grid"])
def test_problem_to_dict_round_trip(tmp_path, kind):
    rng = np.random.default_rng(11)
    original = make_problem(kind, rng, n_views=2).problem
    cam = original.views[1].camera
    distorted = Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height,
                       np.array([0.05, -0.01, 0.001, 0.002, 0.0]), cam.world_from_camera)
    original = PoseProblem(original.model, (original.views[0], View(distorted, original.views[1].points, 0.5)),
                           original.bounds, hints=rng.uniform(-1, 1, (2, 6)))
    document = problem_to_dict(original, constraints={"pitch": (0.3, 0.01)}, seed=5)
    problem, _, seed = load_problem(write_yaml(tmp_path, document))
    assert seed == 5
    np.testing.assert_array_equal(problem.model.points, original.model.points)
    for got, want in zip(problem.views, original.views, strict=True):
        np.testing.assert_array_equal(got.points, want.points)
        np.testing.assert_array_equal(got.camera.distortion, want.camera.distortion)
        np.testing.assert_allclose(got.camera.world_from_camera, want.camera.world_from_camera, atol=1e-12)
        assert got.weight == want.weight
    np.testing.assert_allclose(problem.hints, original.hints)
    assert problem.bounds.lo[4] == pytest.approx(0.29) and problem.bounds.hi[4] == pytest.approx(0.31)
    np.testing.assert_array_equal(problem.bounds.lo[:3], original.bounds.lo[:3])


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_committed_examples_are_up_to_date(name):
    text, _ = render(name)
    committed = (EXAMPLES_DIR / f"{name}.yaml").read_text(encoding="utf-8")
    assert committed == text, f"examples/{name}.yaml is stale: run `python -m examples.make_examples`"


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_examples_contain_their_true_pose(name):
    _, synthetic = render(name)
    problem, _, seed = load_problem(EXAMPLES_DIR / f"{name}.yaml")
    assert seed == 0
    assert problem.bounds.contains(synthetic.true_pose)


# -- malformed files: one line naming the field ---------------------------------------------------

def _set(path: str, value):
    """A mutation of the minimal document: set the value at a dotted path (integers index lists)."""
    def mutate(document: dict) -> dict:
        *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
        node = document
        for part in parents:
            node = node[part]
        node[last] = value
        return document
    return mutate


def _drop(key: str):
    def mutate(document: dict) -> dict:
        del document[key]
        return document
    return mutate


MALFORMED = [
    ("missing model", _drop("model"), "model: required field missing"),
    ("missing search z", _set("search", {"x": [0, 1], "y": [0, 1]}), "search.z: required field missing"),
    ("view point with 3 numbers", _set("views.0.points.3", [1, 2, 3]),
     "views[0].points[3]: expected 2 numbers [u, v], got 3"),
    ("view point not a list", _set("views.0.points.1", 5), "views[0].points[1]: expected a list of 2 numbers"),
    ("model point with 2 numbers", _set("model.points.2", [1, 2]),
     "model.points[2]: expected 3 numbers [x, y, z], got 2"),
    ("NaN in view points", _set("views.0.points.0", [float("nan"), 1.0]),
     "views[0].points[0][0]: expected a finite number, got nan"),
    ("inf in model points", _set("model.points.1", [0, float("inf"), 0]), "model.points[1][1]: expected a finite"),
    ("string number", _set("views.0.camera.fx", "800"), "views[0].camera.fx: expected a number, got '800'"),
    ("boolean number", _set("views.0.points.0", [True, 1]), "views[0].points[0][0]: expected a number"),
    ("empty view points", _set("views.0.points", []), "views[0].points: must not be empty"),
    ("empty model points", _set("model.points", []), "model.points: must not be empty"),
    ("no views", _set("views", []), "views: must not be empty"),
    ("views not a list", _set("views", {"a": 1}), "views: expected a list, got a mapping"),
    ("model not a mapping", _set("model", [[0, 0, 0]]), "model: expected a mapping, got a list"),
    ("lo > hi", _set("search.y", [2, 1]), "search.y: lo 2.0 > hi 1.0"),
    ("range of 3 numbers", _set("search.x", [0, 1, 2]), "search.x: expected 2 numbers [lo, hi], got 3"),
    ("unknown search parameter", _set("search.rol", [0, 1]), "search.rol: unknown key"),
    ("unknown top-level key", _set("modle", {}), "modle: unknown key"),
    ("unknown camera key", _set("views.0.camera.k1", 0.1), "views[0].camera.k1: unknown key"),
    ("negative weight", _set("views.0.weight", -0.5), "views[0].weight: must be >= 0"),
    ("all weights zero", _set("views.0.weight", 0), "views: all view weights are 0"),
    ("zero focal length", _set("views.0.camera.fy", 0), "views[0].camera.fy: must be > 0"),
    ("float image width", _set("views.0.camera.width", 640.5), "views[0].camera.width: expected an integer"),
    ("distortion of 4", _set("views.0.camera.distortion", [0, 0, 0, 0]),
     "views[0].camera.distortion: expected 5 numbers [k1, k2, p1, p2, k3], got 4"),
    ("partial extrinsic", _set("views.0.camera.world_from_camera", {"x": 1}),
     "views[0].camera.world_from_camera.y: required field missing"),
    ("normals count", _set("model.normals", [[0, 0, 1]]), "model.normals: expected one normal per point (4), got 1"),
    ("labels count", _set("model.labels", [0, 1]), "model.labels: expected one label per point (4), got 2"),
    ("negative label", _set("views.0.labels", [0, -1, 0, 0]), "views[0].labels[1]: must be >= 0"),
    ("view labels count", _set("views.0.labels", [0]), "views[0]: labels: expected one per point (4), got 1"),
    ("zero normal", _set("model.normals", [[0, 0, 1], [0, 0, 0], [0, 0, 1], [0, 0, 1]]),
     "model.normals[1]: a normal must be a non-zero vector"),
    ("negative tolerance", _set("constraints", {"roll": {"value": 0.1, "tolerance": -0.01}}),
     "constraints.roll.tolerance: must be >= 0"),
    ("unknown constraint", _set("constraints", {"heading": {"value": 0.1, "tolerance": 0.01}}),
     "constraints.heading: unknown key"),
    ("constraint outside search range", _set("constraints", {"x": {"value": 3.0, "tolerance": 0.1}}),
     "constraints.x: constraint on x (3.0 +- 0.1) lies outside its search range"),
    ("hint missing yaw", _set("hints", [{"x": 0, "y": 0, "z": 5, "roll": 0, "pitch": 0}]),
     "hints[0].yaw: required field missing"),
    ("negative seed", _set("seed", -1), "seed: must be >= 0"),
    ("float seed", _set("seed", 1.5), "seed: expected an integer, got 1.5"),
    ("unknown fitness", _set("options", {"fitness": "fast"}), "options.fitness: expected 'mutual', 'robust' or 'paper'"),
    ("unknown option", _set("options", {"popsize": 10}), "options.popsize: unknown key"),
    ("option rejected by SearchOptions", _set("options", {"population": 1}), "options: population must be >= 2"),
]


@pytest.mark.parametrize("mutate, expected", [m[1:] for m in MALFORMED], ids=[m[0] for m in MALFORMED])
def test_malformed_field_is_named(tmp_path, mutate, expected):
    message = load_error(tmp_path, mutate(minimal_document()))
    assert message.startswith(expected), message


def test_missing_file(tmp_path):
    with pytest.raises(ProblemFileError, match=r"nope\.yaml: cannot read: No such file"):
        load_problem(tmp_path / "nope.yaml")


def test_directory_is_unreadable(tmp_path):
    with pytest.raises(ProblemFileError, match="cannot read"):
        load_problem(tmp_path)


def test_binary_file_is_unreadable(tmp_path):
    path = tmp_path / "problem.yaml"
    path.write_bytes(b"\xff\xfe\x00model")
    with pytest.raises(ProblemFileError, match="cannot read: not UTF-8 text"):
        load_problem(path)


@pytest.mark.parametrize("text, expected", [
    ("- 1\n- 2\n", "top level must be a mapping, got a list"),
    ("just a string\n", "top level must be a mapping, got 'just a string'"),
    ("", "top level must be a mapping, got an empty document"),
    ("model: [1, 2\n", "problem.yaml:2:1: invalid YAML"),
    ("model: {a: 1}\nmodel: {a: 2}\n", "problem.yaml:2:1: invalid YAML: duplicate key 'model'"),
    ("a: *nope\n", "invalid YAML"),
])
def test_bad_yaml_documents(tmp_path, text, expected):
    path = tmp_path / "problem.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ProblemFileError) as info:
        load_problem(path)
    assert expected in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("text, expected", [
    ('{"model": {"points": [[0, 0, 0]]}, ', "problem.json:1:"),
    ('{"seed": 1, "seed": 2}', "invalid JSON: duplicate key 'seed'"),
    ("[1, 2]", "top level must be a mapping, got a list"),
])
def test_bad_json_documents(tmp_path, text, expected):
    path = tmp_path / "problem.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ProblemFileError, match=expected):
        load_problem(path)


# -- output object --------------------------------------------------------------------------------

def test_solution_to_dict_has_design_keys_and_is_json():
    pose = np.array([0.1, -0.2, 5.0, 0.3, -0.4, 2.5])
    solution = Solution(pose=pose, fitness=1.25, view_terms=np.array([1.25]), view_weights=np.array([1.0]),
                        generations=7, evaluations=321, seconds=0.5, converged=True, stop_reason="consensus",
                        history=[2.0, 1.25])
    out = json.loads(json.dumps(solution_to_dict(solution)))
    assert DESIGN_KEYS <= set(out) and set(out["pose"]) == POSE_KEYS
    assert [out["pose"][k] for k in ("x", "y", "z", "roll", "pitch", "yaw")] == pose.tolist()
    q = Rotation.from_euler("xyz", pose[3:]).as_quat()  # scipy order (x, y, z, w)
    assert np.allclose(out["pose"]["quaternion"], q) or np.allclose(out["pose"]["quaternion"], -q)
    assert out["pose"]["quaternion"][3] >= 0
    assert (out["fitness"], out["generations"], out["evaluations"], out["seconds"], out["converged"]) == \
        (1.25, 7, 321, 0.5, True)
    assert out["stop_reason"] == "consensus" and out["view_weights"] == [1.0]


def test_solution_to_dict_carries_confidence_and_a_covariance_without_nan():
    """Issue 11: "confident" and a 6x6 "covariance" (ROS order, row by row); an unknown covariance is null,
    never NaN or Infinity, so the output stays strict JSON."""
    base = dict(pose=np.zeros(6), fitness=1.0, view_terms=np.array([1.0]), view_weights=np.array([1.0]),
                generations=1, evaluations=1, seconds=0.1, converged=False, stop_reason="stalled", history=[1.0])
    unknown = solution_to_dict(Solution(**base))  # the default: no covariance computed
    text = json.dumps(unknown, allow_nan=False)
    assert json.loads(text)["confident"] is False
    assert json.loads(text)["covariance"] == [[None] * 6] * 6
    cov = np.diag([1e-4, 2e-4, 3e-4, 1e-3, 2e-3, 3e-3])
    cov[0, 5] = cov[5, 0] = 5e-5
    known = json.loads(json.dumps(solution_to_dict(Solution(**base, covariance=cov, confident=True)),
                                  allow_nan=False))
    assert known["confident"] is True and np.array_equal(np.array(known["covariance"]), cov)
    partly = cov.copy()
    partly[2, 2] = np.nan
    out = json.loads(json.dumps(solution_to_dict(Solution(**base, covariance=partly)), allow_nan=False))
    assert out["covariance"][2][2] is None and out["covariance"][0][0] == 1e-4
