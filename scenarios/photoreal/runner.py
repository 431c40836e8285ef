"""Running a Blender job: the interpreter that has ``bpy``, the job file, one progress report per image.

``bpy`` 4.5 (Blender 4.5 LTS from PyPI) needs numpy < 2 and the project pins numpy 2, so Blender runs in its own
interpreter: ``EVOPOSE_BPY_PYTHON`` if set, else ``<repo>/.venv-photoreal/bin/python`` (``make photoreal``).
"""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

from ..errors import WorldError
from .blender_job import PROGRESS

#: The repository (``scenarios/photoreal/runner.py`` -> three levels up).
REPO = Path(__file__).resolve().parents[2]
JOB_SCRIPT = Path(__file__).resolve().parent / "blender_job.py"
ENV_PYTHON = "EVOPOSE_BPY_PYTHON"
#: Lines of Blender's error output quoted when a job fails.
TAIL_LINES = 3


class PhotorealUnavailable(WorldError):
    """Blender's interpreter (``bpy``) is not installed or does not run."""


class RenderFailed(WorldError):
    """Blender stopped with an error while rendering a job."""


def bpy_python() -> Path:
    """The interpreter with ``bpy``: ``$EVOPOSE_BPY_PYTHON``, else ``.venv-photoreal/bin/python`` of the repository.

    Raises
    ------
    PhotorealUnavailable
        Neither exists (one line telling how to install it).
    """
    given = os.environ.get(ENV_PYTHON)
    if given:
        path = Path(given)
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise PhotorealUnavailable(f"{ENV_PYTHON}={given}: no such executable (a Python with bpy 4.5; "
                                       "`make photoreal` makes .venv-photoreal)")
        return path
    path = REPO / ".venv-photoreal" / "bin" / "python"
    if not path.is_file():
        raise PhotorealUnavailable(f"the photoreal renderer needs Blender's bpy in its own interpreter: run `make "
                                   f"photoreal` (creates {path.parent.parent}), or set {ENV_PYTHON}")
    return path


def blender_version(python: Path | None = None) -> str:
    """``bpy.app.version_string`` of the interpreter (e.g. ``4.5.15 LTS``)."""
    python = python or bpy_python()
    try:
        out = subprocess.run([str(python), "-c", "import bpy; print(bpy.app.version_string)"], capture_output=True,
                             text=True, timeout=300, check=False)
    except OSError as err:
        raise PhotorealUnavailable(f"{python}: cannot run: {err.strerror or err}") from None
    lines = [line for line in out.stdout.splitlines() if line.strip()]
    if out.returncode != 0 or not lines:
        tail = " | ".join(out.stderr.strip().splitlines()[-TAIL_LINES:]) or f"exit code {out.returncode}"
        raise PhotorealUnavailable(f"{python}: cannot import bpy: {tail} (run `make photoreal`)")
    return lines[-1].strip()


def progress_lines(stream) -> Iterator[dict]:
    """The job's progress reports among Blender's other output lines."""
    for line in stream:
        if line.startswith(PROGRESS + " "):
            yield json.loads(line[len(PROGRESS) + 1:])


def run_job(job: dict, job_path: Path, on_image: Callable[[dict], None], *, python: Path | None = None) -> None:
    """Write ``job`` to ``job_path`` and render it with Blender; ``on_image(report)`` after each image
    (``frame``, ``camera``, ``path``, ``seconds``, ``skipped``). Blender's own output goes to ``blender.log``
    beside the job.

    Raises
    ------
    RenderFailed
        Blender exited with an error (its last lines quoted).
    """
    python = python or bpy_python()
    job_path = Path(job_path)
    job_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = job_path.with_name(job_path.name + ".tmp")
    tmp.write_text(json.dumps(job), encoding="utf-8")
    os.replace(tmp, job_path)
    log_path = job_path.with_name("blender.log")
    with open(log_path, "w", encoding="utf-8") as log:
        proc = subprocess.Popen([str(python), str(JOB_SCRIPT), str(job_path)], stdout=subprocess.PIPE, stderr=log,
                                text=True, bufsize=1)
        try:
            for report in progress_lines(proc.stdout):
                on_image(report)
        except BaseException:
            proc.kill()
            proc.wait()
            raise
        finally:
            proc.stdout.close()
        code = proc.wait()
    if code != 0:
        lines = [line.strip() for line in log_path.read_text(encoding="utf-8", errors="replace").splitlines()
                 if line.strip()]
        tail = " | ".join(lines[-TAIL_LINES:]) or f"exit code {code}"
        raise RenderFailed(f"Blender failed on {job_path}: {tail} (log: {log_path})")
