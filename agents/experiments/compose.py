"""``evopose scenario compose``: a fleet scenario as a docker-compose file (a Zenoh router + one service per agent).

The router service runs ``evopose router`` and publishes port 7447 on the host's loopback, so that
``evopose meter --connect tcp/127.0.0.1:7447`` watches the fleet from outside. Each agent of the chosen
variant is a service named after its vehicle (lower-cased), joining the router by its service name as a
Zenoh client. Agents run until stopped (no ``--frames``): ``docker compose stop`` sends SIGTERM, which
``evopose agent`` handles by finishing the frame and printing its summary.

The document is a pure function of the scenario: no timestamps and no absolute paths, so the committed
files can be compared with what the generator produces (``make compose`` rewrites them).
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from scenarios.errors import ScenarioError
from scenarios.fleet import FleetScenario
from scenarios.world import SCENARIOS_DIR

from agents.experiments import DEFAULT_IMAGE

#: The directory holding the ``scenarios`` package: the repository root in a checkout (the build context).
REPO_ROOT = SCENARIOS_DIR.parent
#: The router's port, inside the compose network and on the host's loopback.
ROUTER_PORT = 7447
ROUTER_SERVICE = "router"

_SERVICE_NAME = re.compile(r"^[a-z0-9][a-z0-9_.-]*$")
#: Is the router's port open yet? Zenoh clients fail at once when it is not, so the agents wait for this.
_ROUTER_HEALTHCHECK = f'import socket; socket.create_connection(("127.0.0.1", {ROUTER_PORT}), timeout=1).close()'


def world_path_in_repo(scenario: FleetScenario) -> str:
    """The scenario's world file relative to the repository root, e.g. ``scenarios/exp2.yaml``."""
    world = Path(scenario.world_path).resolve()
    try:
        return world.relative_to(REPO_ROOT.resolve()).as_posix()
    except ValueError:
        raise ScenarioError(f"{scenario.path}: world {str(world)!r} is outside {str(REPO_ROOT)!r}; a container "
                            f"image holds only the repository's files") from None


def _service_name(vehicle: str) -> str:
    name = vehicle.lower()
    if not _SERVICE_NAME.match(name):
        raise ScenarioError(f"vehicle {vehicle!r}: {name!r} is not a valid compose service name")
    return name


def _image(image: str, context: str) -> dict:
    return {"build": context, "image": image}


def compose_document(scenario: FleetScenario, variant: str | None = None, *, image: str = DEFAULT_IMAGE,
                     context: str = ".") -> dict:
    """The docker-compose document of one variant of ``scenario`` (default: its first).

    Parameters
    ----------
    scenario : FleetScenario
        A loaded fleet scenario.
    variant : str or None
        The variant's name; ``None`` takes the first.
    image : str
        Name of the image every service runs (built from the repository's Dockerfile).
    context : str
        The build context relative to the compose file: ``.`` for a file at the repository root, ``..``
        for one in ``compose/``.

    Raises
    ------
    ScenarioError
        Unknown variant, a vehicle whose name is no compose service name or clashes with another one.
    """
    chosen = scenario.variant(variant) if variant is not None else scenario.spec.variants[0]
    world = world_path_in_repo(scenario)
    services: dict[str, dict] = {
        ROUTER_SERVICE: {
            **_image(image, context),
            "command": ["evopose", "router", "--listen", f"tcp/0.0.0.0:{ROUTER_PORT}", "--no-multicast"],
            "ports": [f"127.0.0.1:{ROUTER_PORT}:{ROUTER_PORT}"],
            "healthcheck": {"test": ["CMD", "python", "-c", _ROUTER_HEALTHCHECK],
                            "interval": "1s", "timeout": "2s", "retries": 60},
            "stop_signal": "SIGTERM",
            "stop_grace_period": "10s",
            "init": True,
        },
    }
    vehicles = [a.vehicle for a in chosen.agents]
    for agent in chosen.agents:
        name = _service_name(agent.vehicle)
        if name in services:
            raise ScenarioError(f"scenario {scenario.name!r}, variant {chosen.name!r}: vehicle {agent.vehicle!r} "
                                f"gives service name {name!r}, which is taken")
        command = ["evopose", "agent", "--scenario", world, "--fleet", scenario.name, *agent.cli_args()]
        if scenario.spec.fps is not None:
            command += ["--fps", f"{scenario.spec.fps:g}"]
        command += ["--mode", "client", "--connect", f"tcp/{ROUTER_SERVICE}:{ROUTER_PORT}", "--no-multicast"]
        others = [v for v in vehicles if v != agent.vehicle]
        if others:
            command += ["--wait-for", ",".join(others)]
        command.append("--json")
        services[name] = {
            **_image(image, context),
            "command": command,
            "depends_on": {ROUTER_SERVICE: {"condition": "service_healthy"}},
            "stop_signal": "SIGTERM",
            "stop_grace_period": "10s",
            "init": True,
        }
    return {"services": services}


def compose_header(scenario: FleetScenario, variant: str | None = None, *, image: str = DEFAULT_IMAGE,
                   context: str = ".") -> str:
    """The comment at the top of the file: how it was generated, and that it must not be edited."""
    chosen = scenario.variant(variant) if variant is not None else scenario.spec.variants[0]
    args = [scenario.name]
    if variant is not None:
        args += ["--variant", variant]
    if image != DEFAULT_IMAGE:
        args += ["--image", image]
    if context != ".":
        args += ["--context", context]
    lines = [f"# Generated by `evopose scenario compose {' '.join(args)}`: do not edit by hand;",
             "# run `make compose` to regenerate.",
             f"# Fleet scenario {scenario.name}, variant {chosen.name}"
             + (f": {scenario.spec.description}" if scenario.spec.description else "")]
    others = [v.name for v in scenario.spec.variants if v.name != chosen.name]
    if others:
        lines.append(f"# Other variants (--variant): {', '.join(others)}")
    return "\n".join(lines) + "\n"


class _Flow(list):
    """A list written on one line (``command: [evopose, agent, ...]``), as compose files usually do."""


class _Dumper(yaml.SafeDumper):
    pass


_Dumper.add_representer(_Flow, lambda dumper, data: dumper.represent_sequence("tag:yaml.org,2002:seq", data,
                                                                              flow_style=True))


def _flow_string_lists(node: object) -> object:
    if isinstance(node, dict):
        return {k: _flow_string_lists(v) for k, v in node.items()}
    if isinstance(node, list):
        return _Flow(node) if all(isinstance(v, str) for v in node) else [_flow_string_lists(v) for v in node]
    return node


def compose_yaml(scenario: FleetScenario, variant: str | None = None, *, image: str = DEFAULT_IMAGE,
                 context: str = ".") -> str:
    """:func:`compose_document` as YAML text, after the generated-file header."""
    document = compose_document(scenario, variant, image=image, context=context)
    body = yaml.dump(_flow_string_lists(document), Dumper=_Dumper, sort_keys=False, default_flow_style=False,
                     width=1000, allow_unicode=True)
    return compose_header(scenario, variant, image=image, context=context) + body


__all__ = ["compose_document", "compose_header", "compose_yaml", "world_path_in_repo"]
