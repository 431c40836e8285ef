"""Fleet names as ROS 2 names, and the ROS topics and frames of a fleet (docs/ros2.md, "Names").

Fleet and vehicle names (``protocol.keys``) are 1-64 characters from ``A-Z a-z 0-9 _ - .``. A ROS 2 name token
may hold only ``A-Z a-z 0-9 _``, must not start with a digit and must not contain ``__``. The mapping:

1. every ``-`` and ``.`` becomes ``_``;
2. runs of ``_`` become one ``_``;
3. a name that starts with a digit gets a leading ``_``.

So ``exp2a-features`` -> ``exp2a_features``, ``uav.1`` -> ``uav_1``, ``2nd`` -> ``_2nd``. The mapping is not
one-to-one (``a-b`` and ``a_b`` both become ``a_b``): :class:`NameMap` reports such a collision once.

Topics (absolute): ``/<fleet>/<vehicle>/<leaf>``, and ``/tf`` for the fleet's transforms.
Frames (REP-105): ``map`` (ENU, z up: the scenarios' world), ``<vehicle>/base_link``, ``<vehicle>/camera_optical``,
``<vehicle>/target_estimate`` (a vehicle's estimate of the target), ``<target>/truth`` (the simulated truth).
"""

from __future__ import annotations

import re
import threading

#: The fixed world frame (ENU, z up).
MAP_FRAME = "map"
#: The one transform topic of the fleet (tf2's).
TF_TOPIC = "/tf"

_RUNS = re.compile(r"_+")


def ros_name(name: str) -> str:
    """``name`` (a fleet or vehicle name) as a valid ROS 2 name token; see the module docstring."""
    token = _RUNS.sub("_", name.replace("-", "_").replace(".", "_"))
    if not token:
        raise ValueError(f"cannot map {name!r} to a ROS name")
    return f"_{token}" if token[0].isdigit() else token


def topic_name(fleet: str, vehicle: str, leaf: str) -> str:
    """The absolute ROS topic ``/<fleet>/<vehicle>/<leaf>`` (``leaf`` is already a ROS name, may hold ``/``)."""
    return f"/{ros_name(fleet)}/{ros_name(vehicle)}/{leaf}"


def base_frame(vehicle: str) -> str:
    return f"{ros_name(vehicle)}/base_link"


def camera_frame(vehicle: str) -> str:
    return f"{ros_name(vehicle)}/camera_optical"


def estimate_frame(vehicle: str) -> str:
    return f"{ros_name(vehicle)}/target_estimate"


def truth_frame(target: str) -> str:
    return f"{ros_name(target)}/truth"


class NameMap:
    """Remembers which fleet name gave each ROS name, to report (once) two names that map to one."""

    def __init__(self) -> None:
        self._origin: dict[str, str] = {}
        self._reported: set[tuple[str, str]] = set()
        self._lock = threading.Lock()

    def collision(self, name: str) -> str | None:
        """The fleet name first mapped to ``name``'s ROS name if it is another one, once per pair; else None."""
        token = ros_name(name)
        with self._lock:
            first = self._origin.setdefault(token, name)
            if first == name or (first, name) in self._reported:
                return None
            self._reported.add((first, name))
            return first
