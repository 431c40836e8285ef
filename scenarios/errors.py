"""The world's exceptions: one root, precise subclasses, one-line messages (the CLI prints them as ``error: ...``)."""

from __future__ import annotations

from evopose_errors import EvoPoseError


class WorldError(EvoPoseError, ValueError):
    """Root of every input problem in the simulated world: a bad file, a frame out of range, an unreadable image."""


class ModelFileError(WorldError):
    """A target-model file that cannot be used; the message names the file and the field."""


class ScenarioError(WorldError):
    """A scenario file that cannot be used; the message names the file and the field."""


class FrameError(WorldError):
    """A frame index or vehicle name that the scenario does not have."""


class ImageError(WorldError):
    """An image file that cannot be read or decoded."""
