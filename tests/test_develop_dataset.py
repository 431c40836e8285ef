"""`evopose develop SRC --look NAME --out DIR` (agents/tools/develop_dataset.py): a dataset developed again through
another look from its raw EXRs, and `evopose render ... --look NAME`. The source is a small OpenCV-engine dataset
given raw EXRs here (the OpenCV engine keeps none; an uncompressed half-float EXR is written by `write_exr`)."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from agents.cli.main import main
from agents.tools.develop_dataset import develop_dataset
from agents.tools.render_dataset import render_dataset
from scenarios.photoreal.develop import develop_exr
from scenarios.camera_model import CameraModelSpec, linear_from_srgb
from scenarios.dataset import open_dataset
from scenarios.errors import WorldError
from scenarios.photoreal.exr import read_exr
from scenarios.world import load_scenario


def write_exr(path: Path, bgr: np.ndarray) -> None:
    """A scanline OpenEXR file, half-float B, G, R channels, no compression (the subset read_exr reads)."""
    h, w = bgr.shape[:2]

    def attr(name: str, kind: str, value: bytes) -> bytes:
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value

    chlist = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", 1, 0, 1, 1) for c in "BGR") + b"\0"
    box = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = (struct.pack("<ii", 20000630, 2) + attr("channels", "chlist", chlist)
              + attr("compression", "compression", b"\0") + attr("dataWindow", "box2i", box)
              + attr("displayWindow", "box2i", box) + attr("lineOrder", "lineOrder", b"\0")
              + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attr("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1.0)) + b"\0")
    half = bgr.astype("<f2")
    rows = [struct.pack("<ii", y, 6 * w) + b"".join(half[y, :, c].tobytes() for c in range(3)) for y in range(h)]
    start = len(header) + 8 * h
    offsets, at = [], start
    for row in rows:
        offsets.append(at)
        at += len(row)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(header + struct.pack(f"<{h}Q", *offsets) + b"".join(rows))


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """exp2-paper-scale, 2 frames of H2 (OpenCV engine), with a raw EXR per image (its linear light)."""
    src = tmp_path_factory.mktemp("src") / "paper"
    render_dataset("exp2-paper-scale", src, engine="opencv", frames=2, cameras=["H2"])
    for k in range(2):
        image = cv2.imread(str(src / "H2" / f"{k:06d}.jpg"))
        write_exr(src / "H2" / "raw" / f"{k:06d}.exr", linear_from_srgb(image) * 2.0)
    return src


def test_the_test_exr_writer_round_trips(tmp_path):
    bgr = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32) * 4
    write_exr(tmp_path / "x.exr", bgr)
    np.testing.assert_array_equal(read_exr(tmp_path / "x.exr"), bgr.astype(np.float16).astype(np.float32))


def test_develop_writes_the_same_dataset_through_another_look(source, tmp_path):
    out = tmp_path / "agx"
    summary = develop_dataset(source, out, "agx")
    assert summary["images_developed"] == 2 and summary["look"] == "agx" and summary["cameras"] == ["H2"]
    for name in ("model.yaml", "truth.jsonl", "H2/camera_info.yaml", "H2/poses.jsonl"):
        assert (out / name).read_bytes() == (source / name).read_bytes(), name
    assert not (out / "H2" / "raw").exists()
    manifest = yaml.safe_load((out / "manifest.yaml").read_text())
    old = yaml.safe_load((source / "manifest.yaml").read_text())
    assert manifest["look"] == "agx" and manifest["developed_from"] == str(source.resolve())
    assert manifest["camera_model"]["tone"] == "blender-agx"
    assert {k: v for k, v in manifest.items() if k not in ("look", "developed_from", "camera_model")} == \
        {k: v for k, v in old.items() if k != "camera_model"}
    assert "look" not in old and "saturation" not in old["camera_model"]
    world = yaml.safe_load((out / "world.yaml").read_text())
    assert world["render"]["camera_model"]["tone"] == "blender-agx"
    ds = open_dataset(out)
    assert ds.frames == 2 and ds.world().render.camera_model.tone == "blender-agx"
    # each image is the EXR through the look, with the original frame's seed
    scenario = load_scenario(source / "world.yaml")
    for k in range(2):
        data, suffix = develop_exr(scenario, source / "H2" / "raw" / f"{k:06d}.exr", k, "H2",
                                   CameraModelSpec(tone="blender-agx"))
        assert suffix == ".jpg" and (out / "H2" / f"{k:06d}.jpg").read_bytes() == data
    # and the home look gives other bytes from the same light
    home = develop_dataset(source, tmp_path / "home", "camera")
    assert home["look"] == "camera"
    assert (tmp_path / "home" / "H2" / "000000.jpg").read_bytes() != (out / "H2" / "000000.jpg").read_bytes()


def test_develop_takes_a_mapping_and_a_lossless_look(source, tmp_path):
    out = tmp_path / "custom"
    develop_dataset(source, out, {"saturation": 0.5, "jpeg_quality": None})
    manifest = yaml.safe_load((out / "manifest.yaml").read_text())
    assert manifest["look"] == "custom" and manifest["camera_model"]["saturation"] == 0.5
    assert (out / "H2" / "000001.png").is_file() and open_dataset(out).frames == 2
    with pytest.raises(WorldError, match="saturation"):
        develop_dataset(source, tmp_path / "bad", {"saturation": 9})
    assert not (tmp_path / "bad").exists() and not list(tmp_path.glob(".bad.developing-*"))


def _cli(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _usage_error(capsys, expected: str, *args) -> None:
    code, _, err = _cli(capsys, *args)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], (code, err)


def test_cli_develops_and_replaces_only_with_force(source, tmp_path, capsys):
    out = tmp_path / "warm"
    code, stdout, _ = _cli(capsys, "develop", source, "--look", "vivid-warm", "--out", out, "--json")
    assert code == 0 and '"look": "vivid-warm"' in stdout
    _usage_error(capsys, "holds a dataset already (--force replaces it)",
                 "develop", source, "--look", "flat-cool", "--out", out)
    code, _, _ = _cli(capsys, "develop", source, "--look", "flat-cool", "--out", out, "--force")
    assert code == 0 and yaml.safe_load((out / "manifest.yaml").read_text())["look"] == "flat-cool"


def test_cli_develop_errors_are_one_line(source, tmp_path, capsys):
    _usage_error(capsys, "unknown look 'sepia'", "develop", source, "--look", "sepia", "--out", tmp_path / "a")
    no_raw = tmp_path / "no-raw"
    shutil.copytree(source, no_raw)
    shutil.rmtree(no_raw / "H2" / "raw")
    _usage_error(capsys, "2 of 2 raw EXRs missing (first H2/raw/000000.exr)",
                 "develop", no_raw, "--look", "agx", "--out", tmp_path / "b")
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    _usage_error(capsys, "holds no dataset", "develop", source, "--look", "agx", "--out", other, "--force")
    assert (other / "notes.txt").read_text() == "mine"
    _usage_error(capsys, "outside the source dataset", "develop", source, "--look", "agx", "--out", source / "x")
    _usage_error(capsys, "not a dataset directory", "develop", tmp_path / "nothing", "--look", "agx",
                 "--out", tmp_path / "c")
    _usage_error(capsys, "--look", "render", "exp2", "--out", tmp_path / "f.png", "--look", "agx")
    _usage_error(capsys, "unknown look 'sepia'", "render", "exp2", "--engine", "opencv", "--out", tmp_path / "d",
                 "--look", "sepia")


def test_render_with_a_look_records_it(tmp_path, capsys):
    out = tmp_path / "cool"
    code, _, _ = _cli(capsys, "render", "exp2-paper-scale", "--engine", "opencv", "--frames", "1", "--cameras", "H2",
                      "--out", out, "--look", "flat-cool")
    assert code == 0
    manifest = yaml.safe_load((out / "manifest.yaml").read_text())
    assert manifest["look"] == "flat-cool" and manifest["camera_model"]["saturation"] == 0.45
    assert open_dataset(out).world().render.camera_model.saturation == 0.45
    # resumed with the same look: nothing to do; without it: another dataset
    code, _, _ = _cli(capsys, "render", "exp2-paper-scale", "--engine", "opencv", "--frames", "1", "--cameras", "H2",
                      "--out", out, "--look", "flat-cool")
    assert code == 0
    _usage_error(capsys, "manifest.yaml: camera_model: the dataset has", "render", "exp2-paper-scale", "--engine",
                 "opencv", "--frames", "1",
                 "--cameras", "H2", "--out", out)


def test_the_scorer_s_training_also_sees_each_frame_through_random_looks(source):
    # evopose train-scorer --looks N: each frame with a raw EXR is developed again through N random camera looks
    # (scenarios.looks.random_look), its candidates added to the reference look's; seeded, so the same twice
    from vision.train_scorer import candidates

    plain, is_mark, groups, names, _ = candidates([source])
    seen, seen_marks, seen_groups, seen_names, _ = candidates([source], looks=2, seed=3)
    again = candidates([source], looks=2, seed=3)[0]
    other = candidates([source], looks=2, seed=4)[0]
    assert names == seen_names and len(plain) > 0 and is_mark.any()
    assert len(seen) > len(plain) and seen_marks.sum() > is_mark.sum() and set(seen_groups) == set(groups)
    np.testing.assert_array_equal(seen, again)
    assert other.shape != seen.shape or not np.array_equal(other, seen)


def test_the_scorer_s_training_sees_corner_looks_after_the_random_ones(source, monkeypatch):
    # evopose train-scorer --corner-looks N: each frame is also developed through N looks at the edges of the random
    # ranges (scenarios.looks.corner_look), drawn after the frame's random looks from the same seed
    import vision.train_scorer as ts

    drawn, apply_look = [], ts.apply_look
    monkeypatch.setattr(ts, "apply_look", lambda base, look: drawn.append(look) or apply_look(base, look))
    seen, seen_marks, _, _, _ = ts.candidates([source], looks=1, seed=3, corner_looks=2)
    assert len(drawn) == 2 * 3   # two frames, each through one random look and two corner looks
    corners = drawn[1:3] + drawn[4:6]
    assert all(c["saturation"] in (0.4, 0.45, 1.5) and abs(c["exposure_bias_ev"]) == 1.5
               and c["jpeg_quality"] in (50, 55) for c in corners)
    drawn.clear()
    fewer = ts.candidates([source], looks=1, seed=3)[0]
    assert len(drawn) == 2 and len(seen) > len(fewer) and seen_marks.any()
