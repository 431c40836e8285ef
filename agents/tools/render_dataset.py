"""``evopose render WORLD --out DIR``: a world rendered into a dataset directory (docs/datasets.md).

Two engines write the same layout through :class:`scenarios.dataset.DatasetWriter`:

- ``cycles``: the scene description (:mod:`scenarios.photoreal.scene`) goes to Blender's interpreter as a JSON
  job; each image comes back as linear radiance (``<camera>/raw/NNNNNN.exr``) and is developed here by the
  camera model (lens distortion, then :func:`scenarios.camera_model.capture`) into the camera's JPEG.
- ``opencv``: :func:`scenarios.render.render_frame`; with the world's camera model it has applied it already,
  without one its 8-bit sRGB image is made linear and goes through the default camera model.

Resuming: a directory with a manifest is continued when its manifest and world are the ones this call would
write (otherwise one line; ``force`` starts it anew); an image already there is not rendered again (an EXR there
is developed without rendering). Truth per frame: the target pose and per camera the marks it shows
(:mod:`scenarios.photoreal.truth` for Cycles: the renderer's rules with occluders and clutter as obstacles).
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from scenarios.camera_model import CameraModelSpec, encode, spec_record
from scenarios.dataset import IMAGE_SUFFIXES, DatasetError, DatasetWriter
from scenarios.errors import WorldError
from scenarios.looks import look_spec
from scenarios.photoreal.develop import (camera_model_of, camera_rng, develop_exr, develop_radiance,
                                         radiance_of_srgb)
from scenarios.photoreal.scene import ENGINE_DEFAULTS, describe_frame, describe_scene
from scenarios.photoreal.truth import absent_target, view_truth
from scenarios.render import render_frame
from scenarios.world import Scenario, load_scenario

ENGINES = ("cycles", "opencv")
#: Hidden work folder of a Cycles dataset (the job, the ground texture, Blender's log).
WORK = ".blender"
MAX_SAMPLES = 4096


class RenderDatasetError(WorldError):
    """A bad argument of a dataset render (engine, frames, samples, cameras, an existing directory)."""


def engine_settings(engine: str, samples: int, blender: str | None = None) -> dict:
    """What the manifest records of the engine (a resumed render must use the same)."""
    if engine == "opencv":
        return {"name": "opencv"}
    settings = {k: v for k, v in ENGINE_DEFAULTS.items() if k != "samples"}
    return {"name": "cycles", "samples": int(samples), "blender": blender, **settings}


def _check_arguments(engine: str, frames: int | None, samples: int, cameras: Sequence[str] | None) -> None:
    if engine not in ENGINES:
        raise RenderDatasetError(f"--engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if frames is not None and not 1 <= frames <= 999_999:
        raise RenderDatasetError(f"--frames: expected 1..999999, got {frames}")
    if not 1 <= samples <= MAX_SAMPLES:
        raise RenderDatasetError(f"--samples: expected 1..{MAX_SAMPLES}, got {samples}")
    if cameras is not None and (not cameras or any(not c for c in cameras)):
        raise RenderDatasetError("--cameras: expected comma-separated vehicle names, e.g. H1,H2")


def existing_image(root: Path, camera: str, k: int) -> Path | None:
    for suffix in IMAGE_SUFFIXES:
        path = root / camera / f"{k:06d}{suffix}"
        if path.is_file():
            return path
    return None


def write_bytes(path: Path, data: bytes) -> Path:
    tmp = path.with_name(f".tmp-{path.name}")
    tmp.write_bytes(data)
    os.replace(tmp, path)
    return path


def open_writer(world: str | Path, out_dir: Path, *, engine: dict, frames: int | None, cameras, target: bool,
                camera_model: dict, force: bool, look: str | None = None) -> DatasetWriter:
    """The dataset's writer: a new directory, or an existing dataset resumed (``force``: removed first)."""
    manifest = out_dir / "manifest.yaml"
    if force and manifest.is_file():
        shutil.rmtree(out_dir)
    try:
        return DatasetWriter(out_dir, world, engine=engine, frames=frames, cameras=cameras, camera_model=camera_model,
                             target_visible=target, resume=manifest.is_file(), look=look,
                             world_camera_model=None if look is None else camera_model)
    except DatasetError as err:
        if manifest.is_file():
            raise DatasetError(f"{err}; --force renders it anew") from None
        raise


class _Committer:
    """Appends frames to the writer in order once every camera's image of the frame exists."""

    def __init__(self, writer: DatasetWriter, truth: Callable[[int, str], object]) -> None:
        self.writer, self.truth = writer, truth

    def flush(self) -> None:
        w = self.writer
        while not w.done and all(existing_image(w.root, c, w.next_frame) for c in w.cameras):
            k = w.next_frame
            views = {c: self.truth(k, c) for c in w.cameras}
            for c in w.cameras:
                w.append_pose(c, k, w.scenario.vehicle(c).world_from_camera(w.scenario.time(k)))
            first = views[w.cameras[0]]
            w.append_truth(k, first.target_pose, views, time=first.time)


def _opencv_image(scenario: Scenario, render_world: Scenario, k: int, camera: str) -> tuple[bytes, str]:
    rendered = render_frame(render_world, k, camera)
    spec = scenario.render.camera_model
    if spec is not None:  # render_frame has applied the world's camera model: its decoded stream, as streamed
        return encode(rendered.image, spec.jpeg_quality, spec.chroma)
    veh = scenario.vehicle(camera)
    captured = develop_radiance(radiance_of_srgb(rendered.image), rendered.camera, CameraModelSpec(),
                                camera_rng(scenario, veh.index, k))
    return captured.encoded, captured.suffix


def render_dataset(world: str | Path, out_dir: str | Path, *, engine: str = "cycles", frames: int | None = None,
                   samples: int = 24, cameras: Sequence[str] | None = None, target: bool = True,
                   force: bool = False, keep_raw: bool = True, threads: int | None = None,
                   progress: Callable[[dict], None] | None = None, look: str | None = None) -> dict:
    """Render ``world`` into the dataset directory ``out_dir`` (created, or resumed).

    ``look`` names a look (:data:`scenarios.looks.LOOKS`) put over the world's camera model: the dataset's
    world.yaml carries the resulting camera model (``render.camera_model``) and its manifest the look's name.

    ``progress(event)`` after each image: ``camera``, ``frame``, ``frames`` (per camera), ``done`` and ``total``
    (images of the dataset), ``rendered`` (False: it was there already), ``seconds`` (the engine's time for it).
    Returns a summary: the directory, frames, cameras, images rendered, engine seconds per rendered image, wall time.

    Raises
    ------
    WorldError
        A bad argument or world, an existing directory of another dataset (without ``force``), Blender missing
        (:class:`scenarios.photoreal.runner.PhotorealUnavailable`) or failing.
    """
    start = time.perf_counter()
    _check_arguments(engine, frames, samples, cameras)
    out_dir = Path(out_dir)
    blender = None
    if engine == "cycles":
        from scenarios.photoreal.runner import blender_version

        blender = blender_version()
    spec = camera_model_of(load_scenario(world))
    if look is not None:
        spec = look_spec(spec, look)
    writer = open_writer(world, out_dir, engine=engine_settings(engine, samples, blender), frames=frames,
                         cameras=list(cameras) if cameras else None, target=target,
                         camera_model=spec_record(spec), force=force, look=look)
    scenario = writer.scenario
    render_world = scenario if target else absent_target(scenario)
    total = writer.frames * len(writer.cameras)
    state = {"done": writer.next_frame * len(writer.cameras), "rendered": 0, "seconds": 0.0}
    committer = _Committer(writer, lambda k, c: view_truth(scenario, k, c, target=target) if engine == "cycles"
                           else render_frame(render_world, k, c).truth)

    def report(camera: str, k: int, rendered: bool, seconds: float) -> None:
        state["done"] += 1
        state["rendered"] += int(rendered)
        state["seconds"] += seconds if rendered else 0.0
        if progress is not None:
            progress({"camera": camera, "frame": k, "frames": writer.frames, "done": state["done"], "total": total,
                      "rendered": rendered, "seconds": seconds})

    pending = [(k, c) for k in range(writer.next_frame, writer.frames) for c in writer.cameras]
    if engine == "opencv":
        for k, c in pending:
            if existing_image(out_dir, c, k) is None:
                t0 = time.perf_counter()
                data, suffix = _opencv_image(scenario, render_world, k, c)
                write_bytes(writer.image_path(c, k, suffix), data)
                report(c, k, True, time.perf_counter() - t0)
            else:
                report(c, k, False, 0.0)
            committer.flush()
    else:
        _render_cycles(writer, scenario, pending, samples=samples, target=target, keep_raw=keep_raw,
                       threads=threads, report=report, committer=committer)
    committer.flush()
    return {"dataset": str(out_dir), "world": scenario.name, "engine": engine, "frames": writer.frames,
            "cameras": writer.cameras, "complete_frames": writer.next_frame, "images_rendered": state["rendered"],
            "seconds_per_image": state["seconds"] / state["rendered"] if state["rendered"] else None,
            "wall_seconds": time.perf_counter() - start}


def _render_cycles(writer: DatasetWriter, scenario: Scenario, pending: list[tuple[int, str]], *, samples: int,
                   target: bool, keep_raw: bool, threads: int | None, report, committer: _Committer) -> None:
    from scenarios.photoreal.runner import run_job

    root = writer.root
    todo: dict[int, dict[str, Path]] = {}
    for k, c in pending:
        if existing_image(root, c, k) is None:
            todo.setdefault(k, {})[c] = root / c / "raw" / f"{k:06d}.exr"
        else:
            report(c, k, False, 0.0)
    committer.flush()
    if not todo:
        return
    engine = {"samples": samples, **({"threads": threads} if threads else {})}
    job = describe_scene(scenario, root / WORK, target=target, engine=engine, cameras=writer.cameras)
    job["frames"] = [describe_frame(scenario, k, renders, target=target) for k, renders in sorted(todo.items())]

    def on_image(event: dict) -> None:
        k, c = int(event["frame"]), event["camera"]
        exr = Path(event["path"])
        data, suffix = develop_exr(scenario, exr, k, c)
        write_bytes(writer.image_path(c, k, suffix), data)
        if not keep_raw:
            exr.unlink(missing_ok=True)
        report(c, k, not event["skipped"], float(event["seconds"]))
        committer.flush()

    run_job(job, root / WORK / "job.json", on_image)
    if not keep_raw:  # nothing but the images and the truth (a dataset to commit or ship)
        shutil.rmtree(root / WORK, ignore_errors=True)
        for c in writer.cameras:
            raw = root / c / "raw"
            if raw.is_dir() and not any(raw.iterdir()):
                raw.rmdir()
