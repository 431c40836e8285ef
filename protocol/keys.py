"""Every Zenoh key expression of the fleet, in one place (docs/design.md §4).

Data keys are ``evopose/<fleet>/<vehicle>/<topic>``; presence is the liveliness token
``evopose/<fleet>/@alive/<vehicle>``. Fleet and vehicle names are one key chunk each:
1 to 64 characters from ``A-Z a-z 0-9 _ - .``, not starting with ``.`` or ``-``, so they can
never contain the key-expression specials ``/ * $ # ? @``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum

from .errors import InvalidName

#: First chunk of every key of the protocol.
ROOT = "evopose"
#: Chunk that holds the liveliness tokens; verbatim (``@``) so that ``*`` and ``**`` never match it.
ALIVE = "@alive"
#: Longest fleet or vehicle name, in characters.
MAX_NAME_LENGTH = 64

_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}")


class Topic(StrEnum):
    """What a vehicle publishes, the last chunk of a data key."""

    IMAGE = "image"        #: ImageFrame, raw or JPEG/PNG-compressed
    FEATURES = "features"  #: FeatureSet, image points as packed float32
    HINT = "hint"          #: 24-byte pose hint, six little-endian float32
    ATTITUDE = "attitude"  #: Attitude from the vehicle's IMU
    POSE = "pose"          #: PoseEstimate of the target
    STATS = "stats"        #: Stats, the agent's own sent/received counts


def check_name(name: str, what: str = "name") -> str:
    """Return ``name`` if it is a valid fleet or vehicle name, else raise :class:`InvalidName`."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise InvalidName(f"{what} {name!r} must be 1-{MAX_NAME_LENGTH} characters from A-Z a-z 0-9 _ - . "
                          f"(not starting with - or .): no / * $ # ? @ or spaces")
    return name


def check_topic(topic: str) -> Topic:
    """Return ``topic`` as a :class:`Topic`, else raise :class:`InvalidName`."""
    try:
        return Topic(topic)
    except ValueError:
        raise InvalidName(f"unknown topic {topic!r}; topics are {', '.join(t.value for t in Topic)}") from None


@dataclass(frozen=True)
class TopicKey:
    """A parsed data key ``evopose/<fleet>/<vehicle>/<topic>``."""

    fleet: str
    vehicle: str
    topic: Topic

    def __str__(self) -> str:
        return topic_key(self.fleet, self.vehicle, self.topic)


def topic_key(fleet: str, vehicle: str, topic: str) -> str:
    """The key on which ``vehicle`` of ``fleet`` publishes ``topic``."""
    return f"{ROOT}/{check_name(fleet, 'fleet')}/{check_name(vehicle, 'vehicle')}/{check_topic(topic).value}"


def alive_key(fleet: str, vehicle: str) -> str:
    """The liveliness token key that ``vehicle`` declares while it runs."""
    return f"{ROOT}/{check_name(fleet, 'fleet')}/{ALIVE}/{check_name(vehicle, 'vehicle')}"


def fleet_selector(fleet: str | None = None) -> str:
    """Selector of every data key of ``fleet`` (of every fleet when ``None``)."""
    return f"{ROOT}/{'*' if fleet is None else check_name(fleet, 'fleet')}/*/*"


def topic_selector(fleet: str, topic: str) -> str:
    """Selector of ``topic`` from every vehicle of ``fleet``."""
    return f"{ROOT}/{check_name(fleet, 'fleet')}/*/{check_topic(topic).value}"


def alive_selector(fleet: str) -> str:
    """Selector of the liveliness tokens of every vehicle of ``fleet``."""
    return f"{ROOT}/{check_name(fleet, 'fleet')}/{ALIVE}/*"


def parse_key(key: str) -> TopicKey:
    """Split a data key into fleet, vehicle and topic; raise :class:`InvalidName` if it is not one."""
    chunks = str(key).split("/")
    if len(chunks) != 4 or chunks[0] != ROOT:
        raise InvalidName(f"key {key!r} is not of the form {ROOT}/<fleet>/<vehicle>/<topic>")
    return TopicKey(check_name(chunks[1], "fleet"), check_name(chunks[2], "vehicle"), check_topic(chunks[3]))


def parse_alive_key(key: str) -> tuple[str, str]:
    """``(fleet, vehicle)`` of a liveliness token key; raise :class:`InvalidName` if it is not one."""
    chunks = str(key).split("/")
    if len(chunks) != 4 or chunks[0] != ROOT or chunks[2] != ALIVE:
        raise InvalidName(f"key {key!r} is not of the form {ROOT}/<fleet>/{ALIVE}/<vehicle>")
    return check_name(chunks[1], "fleet"), check_name(chunks[3], "vehicle")
