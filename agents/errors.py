"""Exceptions of the fleet plumbing; the CLI turns every :class:`evopose_errors.EvoPoseError` (these too) into
``error: ...`` and exit 2."""

from __future__ import annotations

from evopose_errors import EvoPoseError


class FleetError(EvoPoseError):
    """Root of the errors a fleet command reports to its user as one line."""


class BusConfigError(FleetError):
    """A bad Zenoh mode, endpoint or configuration file, or a session that cannot be opened."""


class TeamNotMetError(FleetError):
    """The team-mates a vehicle was told to wait for (``--wait-for``) never appeared."""

    def __init__(self, message: str, missing: list[str] | None = None) -> None:
        super().__init__(message)
        self.missing = list(missing or [])
