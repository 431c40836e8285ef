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
from protocol.errors import ProtocolError
from protocol.keys import ALIVE, ROOT, parse_alive_key

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


def present_elsewhere(session: zenoh.Session, fleet: str, vehicles: list[str],
                      timeout_s: float = QUERY_TIMEOUT_S) -> dict[str, list[str]]:
    """The other fleets in which each of ``vehicles`` is present now (a liveliness query over every fleet)."""
    found: dict[str, set[str]] = {}
    for reply in session.liveliness().get(f"{ROOT}/*/{ALIVE}/*", timeout=timeout_s):
        if reply.ok is None:
            continue
        try:
            other, vehicle = parse_alive_key(str(reply.ok.key_expr))
        except ProtocolError:
            continue
        if vehicle in vehicles and other != fleet:
            found.setdefault(vehicle, set()).add(other)
    return {vehicle: sorted(fleets) for vehicle, fleets in found.items()}


def connected(session: zenoh.Session) -> bool:
    """Whether the session has a router or a peer now."""
    return bool(list(session.info.routers_zid()) or list(session.info.peers_zid()))


def why_absent(session: zenoh.Session, fleet: str, missing: list[str], connect: tuple[str, ...]) -> str | None:
    """The cause, in one sentence saying what to do, of team-mates ``missing`` that never appeared in ``fleet``, when
    one can be seen: a session that reached no one (nothing answered at ``connect``), or the team-mates present
    under another fleet name. None when neither explains it."""
    if not connected(session):
        where = ", ".join(connect) if connect else "no --connect endpoint"
        return (f"could not reach the fleet: nothing answered at {where} (--connect); start the fleet's router "
                f"there (evopose router --listen {connect[0] if connect else 'tcp/127.0.0.1:7447'}) or the "
                "team-mate that listens, or fix --connect")
    elsewhere = present_elsewhere(session, fleet, missing)
    if elsewhere:
        fleets = sorted({f for found in elsewhere.values() for f in found})
        names = ", ".join(f"{v} in {', '.join(repr(f) for f in found)}" for v, found in sorted(elsewhere.items()))
        return (f"no team-mate {', '.join(missing)} in fleet {fleet!r}, but {names}: wrong --fleet? use "
                f"--fleet {fleets[0]}")
    return None


__all__ = ["DuplicateVehicleError", "connected", "ensure_name_free", "present_elsewhere", "vehicle_present",
           "why_absent"]
