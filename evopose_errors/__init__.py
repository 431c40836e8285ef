"""The project's one root exception, which every package's errors derive from (docs/design.md §2, "Errors").

A package of its own, standard library only: every room may import it (docs/architecture.md), and the CLI's error
edge imports it without loading numpy (``evopose --help`` stays light). An :class:`EvoPoseError` is a bad input or
setting that the user can fix, and its message is one line: the CLI prints it as ``error: ...`` and exits 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class EvoPoseError(Exception):
    """Root of every error the project reports to its user as one line (a bad file, argument, message or setup)."""


__all__ = ["EvoPoseError"]
