"""Is a vehicle's name already taken in its fleet? Asked once, before the vehicle declares its own presence.

A vehicle is present while its liveliness token ``evopose/<fleet>/@alive/<vehicle>`` exists (docs/design.md §4).
A second agent with the same name would mix its messages with the first one's under one key (receivers
would count them as lost or reordered, and take either pose as the vehicle's), so it must refuse to start:
:func:`ensure_name_free` raises :class:`DuplicateVehicleError` (one line, exit code 2 at the CLI).

The check is a liveliness query: it sees what the session's router or peers know when it is asked. Two
agents of the same name started at the same instant can both pass it (neither has declared its token yet).
"""

from __future__ import annotations

import zenoh

from protocol import alive_key

from agents.errors import FleetError

#: How long to wait for the answers to the liveliness query, s.
QUERY_TIMEOUT_S = 2.0


class DuplicateVehicleError(FleetError):
    """Another agent with this vehicle's name is already present in the fleet."""


def vehicle_present(session: zenoh.Session, fleet: str, vehicle: str, timeout_s: float = QUERY_TIMEOUT_S) -> bool:
    """True when some session of the fleet holds ``vehicle``'s liveliness token now."""
    replies = session.liveliness().get(alive_key(fleet, vehicle), timeout=timeout_s)
    found = False
    for reply in replies:  # iterate to the end: the query is finished when the channel closes
        if reply.ok is not None:
            found = True
    return found


def ensure_name_free(session: zenoh.Session, fleet: str, vehicle: str, timeout_s: float = QUERY_TIMEOUT_S) -> None:
    """Raise :class:`DuplicateVehicleError` when ``vehicle`` is already present in ``fleet``."""
    if vehicle_present(session, fleet, vehicle, timeout_s):
        raise DuplicateVehicleError(f"vehicle {vehicle!r} is already present in fleet {fleet!r} (its liveliness "
                                    f"token {alive_key(fleet, vehicle)} exists): another agent runs under this "
                                    "name; stop it or choose another --vehicle")


__all__ = ["DuplicateVehicleError", "ensure_name_free", "vehicle_present"]
