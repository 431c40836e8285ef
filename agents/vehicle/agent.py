"""One vehicle of the fleet as its own process: ``evopose agent`` opens the bus and runs the vehicle's role.

The roles are classes in :mod:`agents.vehicle.roles` (a camera vehicle's per-frame decision is the pure
:func:`agents.vehicle.step.step`). Every agent evaluates what it publishes or receives against the
scenario's ground truth and ends with a summary (JSON with ``--json``). Zenoh is used only through
:class:`agents.transport.bus.FleetBus`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from scenarios.world import Scenario, build_scenario, load_scenario

from agents.errors import FleetError, TeamNotMetError
from agents.transport.bus import FleetBus
from agents.transport.presence import ensure_name_free, why_absent
from agents.transport.session import SessionOptions, open_session
from agents.vehicle.config import CAMERA_ROLES, AgentConfig
from agents.vehicle.memory import pin_mmap_threshold
from agents.vehicle.threads import limit_blas_threads
from agents.vehicle.roles import CameraVehicle, GroundStation, Vehicle
from agents.vehicle.start_signal import read_epoch
from agents.vehicle.target_roles import Airship, Target

Emit = Callable[[dict], None]
#: The world of an agent given no ``--scenario`` (and no dataset with its own world).
DEFAULT_WORLD = "exp2"
#: The class of each role.
ROLE_CLASSES: dict[str, type[Vehicle]] = {"uav": CameraVehicle, "ground-station": GroundStation,
                                          "airship": Airship, "target": Target}


def load_world(config: AgentConfig) -> Scenario:
    """The scenario, with its seed replaced by ``world_seed`` when given (each run of a scenario differs).

    Without ``--scenario``: the world of the dataset ``--source`` is in (its world.yaml), else :data:`DEFAULT_WORLD`.
    """
    if config.scenario is not None:
        scenario = load_scenario(config.scenario)
    else:
        from agents.vehicle.dataset_source import dataset_world

        scenario = dataset_world(config.source) or load_scenario(DEFAULT_WORLD)
    if config.world_seed is not None:
        spec = scenario.spec.model_copy(update={"seed": int(config.world_seed)})
        scenario = build_scenario(spec, Path(scenario.path).parent if scenario.path else None, scenario.path)
    return scenario


def resolve_role(scenario: Scenario, vehicle: str, role: str | None) -> str:
    """The vehicle's role: the given one, else the scenario's; it must fit the vehicle (target or camera)."""
    target = scenario.spec.target
    if vehicle == target.name:
        found = role or target.role or "target"
        if found not in ("airship", "target"):
            raise FleetError(f"--vehicle {vehicle} is the scenario's target; its role is airship or target, "
                             f"not {found!r}")
        return found
    names = [v.name for v in scenario.vehicles]
    if vehicle not in names:
        raise FleetError(f"--vehicle {vehicle!r} is not in scenario {scenario.name!r} "
                         f"(vehicles: {', '.join(names)}; target: {target.name})")
    found = role or scenario.vehicle(vehicle).role or "uav"
    if found not in CAMERA_ROLES:
        raise FleetError(f"--vehicle {vehicle} carries a camera; its role is uav or ground-station, not {found!r}")
    return found


def run_agent(options: SessionOptions, config: AgentConfig, stop: threading.Event, emit: Emit) -> dict | None:
    """Open the bus and run the vehicle of its role until ``stop`` or ``config.frames``; returns the summary (None:
    stopped while waiting for its epoch, before frame 0)."""
    config.check()
    pin_mmap_threshold()
    limit_blas_threads()
    scenario = load_world(config)
    role = resolve_role(scenario, config.vehicle, config.role)
    if role in CAMERA_ROLES:
        scenario.bounds()  # a camera vehicle needs the operating area: fail before joining the fleet
    ROLE_CLASSES[role].warm_up(config, scenario)
    session = open_session(options)
    try:
        ensure_name_free(session, config.fleet, config.vehicle)  # a second agent of this name refuses to start
        bus = FleetBus(session, config.fleet, config.vehicle, max_age_s=config.max_age_s, stats_period_s=1.0,
                       announce=False, on_join=lambda v: emit({"event": "join", "vehicle": v}),
                       on_leave=lambda v: emit({"event": "leave", "vehicle": v}), owns_session=True)
    except BaseException:
        session.close()
        raise
    with bus:
        if config.epoch_from_stdin:  # frame 0 once every agent of the run is warm and connected: then the team
            emit({"event": "warm", "vehicle": config.vehicle})          # meets in milliseconds (start_signal)
            epoch_ns = read_epoch(stop)
            if epoch_ns is None:
                return None
            config = replace(config, epoch_ns=epoch_ns, epoch_from_stdin=False)
        vehicle = ROLE_CLASSES[role](config, bus, scenario, emit)
        vehicle.subscribe()
        bus.announce()  # present only once warm and listening: a team-mate may start on seeing it
        try:
            return vehicle.run(stop)
        except TeamNotMetError as err:  # say why, when it can be seen: no one reached, or another fleet name
            cause = why_absent(session, config.fleet, err.missing, options.connect)
            if cause is None:
                raise
            raise TeamNotMetError(f"{err.missing and ', '.join(err.missing)} of {config.vehicle} did not appear "
                                  f"within {config.wait_timeout_s:g} s: {cause}", err.missing) from None
