"""``evopose develop SRC --look NAME --out DIR``: a rendered dataset developed again through another look, from its
raw EXRs, without rendering (docs/datasets.md, docs/camera-model.md "Looks").

The new dataset has the source's layout and content (manifest, world.yaml, model.yaml, truth.jsonl, each camera's
camera_info.yaml and poses.jsonl, byte for byte except where the look changes them) and new images: each
``<camera>/raw/NNNNNN.exr`` developed by :func:`scenarios.photoreal.develop.develop_exr` with the source's camera
model under the look, seeded per world, camera and frame as the original images were (the same sensor noise draws).
Its manifest records the look's name and the source (``developed_from``); world.yaml carries the look's camera
model as ``render.camera_model``. The raw EXRs are not copied.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from scenarios.camera_model import CameraModelSpec, spec_record
from scenarios.dataset import open_dataset
from scenarios.dataset_files import (CAMERA_INFO, MANIFEST, MODEL, POSES, TRUTH, WORLD, DatasetError, ManifestSpec,
                                     dump_yaml, write_text)
from scenarios.dataset_writer import manifest_document
from scenarios.documents import read_mapping, validate
from scenarios.errors import WorldError
from scenarios.looks import apply_look, look_overrides
from scenarios.photoreal.develop import camera_model_of, develop_exr
from scenarios.world import load_scenario

from agents.tools.render_dataset import write_bytes

#: The look name a manifest records for a look given as a mapping of fields.
CUSTOM_LOOK = "custom"


class DevelopDatasetError(WorldError):
    """A bad argument of ``develop``: an unknown look, a source without raw EXRs, an output that holds something
    else."""


def raw_path(root: Path, camera: str, k: int) -> Path:
    return root / camera / "raw" / f"{k:06d}.exr"


def _inside(a: Path, b: Path) -> bool:
    return a == b or b in a.parents


def _check_out(src: Path, out: Path, force: bool) -> None:
    s, o = src.resolve(), out.resolve()
    if _inside(o, s) or _inside(s, o):
        raise DevelopDatasetError(f"--out {out}: must lie outside the source dataset {src} (and not contain it)")
    if out.exists() or out.is_symlink():
        if not out.is_dir() or out.is_symlink():
            raise DevelopDatasetError(f"--out {out}: exists and is not a directory")
        if any(out.iterdir()):
            if not (out / MANIFEST).is_file():
                raise DevelopDatasetError(f"--out {out}: exists, is not empty and holds no dataset (it is never "
                                          "replaced; name a new directory)")
            if not force:
                raise DevelopDatasetError(f"--out {out}: holds a dataset already (--force replaces it)")


def _source(src: Path):
    if not src.is_dir() or not (src / MANIFEST).is_file():
        raise DevelopDatasetError(f"{src}: not a dataset directory (no {MANIFEST}); give the dataset's root")
    dataset = open_dataset(src)
    missing = [raw_path(src, c, k) for c in dataset.cameras for k in range(dataset.frames)
               if not raw_path(src, c, k).is_file()]
    if missing:
        first = missing[0].relative_to(src)
        raise DevelopDatasetError(f"{src}: {len(missing)} of {dataset.frames * len(dataset.cameras)} raw EXRs missing "
                                  f"(first {first}): only a dataset rendered with Cycles that kept its raw/ can be "
                                  "developed again")
    return dataset


def resolve_look(look: str | Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """A look's name and fields: a name of :data:`scenarios.looks.LOOKS`, or a mapping of fields (``custom``)."""
    if isinstance(look, str):
        try:
            return look, look_overrides(look)
        except WorldError as err:
            raise DevelopDatasetError(f"--look: {err}") from None
    if isinstance(look, Mapping):
        return CUSTOM_LOOK, dict(look)
    raise DevelopDatasetError(f"--look: expected a look's name or a mapping of camera model fields, got {look!r}")


def develop_dataset(src_dir: str | Path, out_dir: str | Path, look: str | Mapping[str, Any], *, force: bool = False,
                    progress: Callable[[dict], None] | None = None) -> dict:
    """Develop the dataset ``src_dir`` (with its raw EXRs) again through ``look`` into the new dataset ``out_dir``.

    ``look``: a name of :data:`scenarios.looks.LOOKS`, or a mapping of camera model fields, put over the source's
    camera model (its manifest's). ``force`` replaces a dataset already at ``out_dir`` (anything else there is never
    deleted). The new dataset is built in a hidden sibling directory and moved into place when complete.
    ``progress(event)`` after each image: ``camera``, ``frame``, ``done``, ``total``.

    Returns a summary: the dataset, its source, the look, frames, cameras, images developed, wall time.

    Raises
    ------
    WorldError
        An unknown or invalid look, a source that is not a dataset or lacks raw EXRs, an output directory that holds
        something else (or a dataset, without ``force``).
    """
    start = time.perf_counter()
    src, out = Path(src_dir), Path(out_dir)
    name, overrides = resolve_look(look)
    dataset = _source(src)
    _check_out(src, out, force)
    manifest = validate(ManifestSpec, read_mapping(src / MANIFEST, DatasetError), src / MANIFEST, DatasetError)
    scenario = load_scenario(src / WORLD)
    base = (CameraModelSpec.model_validate(manifest.camera_model) if manifest.camera_model is not None
            else camera_model_of(scenario))
    spec = apply_look(base, overrides)
    record = spec_record(spec)
    world_doc = read_mapping(src / WORLD, DatasetError)
    world_doc["render"] = {**(world_doc.get("render") or {}), "camera_model": record}
    new_manifest = manifest.model_copy(update={"camera_model": record, "look": name,
                                               "developed_from": str(src.resolve())})

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.developing-", dir=out.parent))
    tmp.chmod(0o755)  # mkdtemp makes it private; a dataset directory is not
    try:
        write_text(tmp / WORLD, dump_yaml(world_doc))
        for name_ in (MODEL, TRUTH):
            if (src / name_).is_file():
                shutil.copyfile(src / name_, tmp / name_)
        total, done = dataset.frames * len(dataset.cameras), 0
        for camera in dataset.cameras:
            (tmp / camera).mkdir()
            for name_ in (CAMERA_INFO, POSES):
                shutil.copyfile(src / camera / name_, tmp / camera / name_)
        for k in range(dataset.frames):
            for camera in dataset.cameras:
                data, suffix = develop_exr(scenario, raw_path(src, camera, k), k, camera, spec)
                write_bytes(tmp / camera / f"{k:06d}{suffix}", data)
                done += 1
                if progress is not None:
                    progress({"camera": camera, "frame": k, "frames": dataset.frames, "done": done, "total": total})
        write_text(tmp / MANIFEST, dump_yaml(manifest_document(new_manifest)))
        open_dataset(tmp).world()  # reads back: a dataset and a world that load
        if out.exists():
            shutil.rmtree(out) if any(out.iterdir()) else out.rmdir()
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"dataset": str(out), "source": str(src), "look": name, "camera_model": record,
            "frames": dataset.frames, "cameras": list(dataset.cameras), "images_developed": total,
            "wall_seconds": time.perf_counter() - start}
