"""`evopose ARGS` through the CLI's ``main`` in the test's own process: what the console script runs, without the
~0.8 s of interpreter start and imports a subprocess costs each time. Tests of what only a process shows (a hang, a
signal, unbounded memory, the installed script) start one instead."""

from __future__ import annotations

import contextlib
import io
import subprocess
from pathlib import Path

from agents.cli.main import main


def run_cli(*args: str | Path | int | float) -> subprocess.CompletedProcess:
    """``evopose ARGS``: its exit code, standard output and standard error, as :func:`subprocess.run` gives them."""
    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return subprocess.CompletedProcess(["evopose", *argv], code, out.getvalue(), err.getvalue())
