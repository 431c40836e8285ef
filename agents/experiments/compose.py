"""``evopose scenario compose``: a fleet scenario as a docker-compose file (a Zenoh router + one service per agent).

The router service runs ``evopose router`` and publishes port 7447 on the host's loopback, so that
``evopose meter --connect tcp/127.0.0.1:7447`` watches the fleet from outside. Each agent of the chosen
variant is a service named after its vehicle (lower-cased), joining the router by its service name as a
Zenoh client. Agents run until stopped (no ``--frames``): ``docker compose stop`` sends SIGTERM, which
``evopose agent`` handles by finishing the frame and printing its summary.

The document is a pure function of the scenario: no timestamps and no absolute paths, so the committed
files can be compared with what the generator produces (``make compose`` rewrites them).

``secure``: the router listens with TLS only (``tls/0.0.0.0:7447`` inside its container), requires a client
certificate and enforces the fleet's ACL; each agent is a TLS client with its own certificate. The files
come from a credentials directory made beforehand (``evopose fleet credentials DIR --fleet <scenario>
--vehicles ... --observers meter --router-host router``: the router's certificate must name the service
``router``), and each service gets only its own files (read-only): the CA certificate, its certificate,
key and Zenoh configuration, mounted under ``/credentials``. The CA's key is never mounted.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from scenarios.errors import ScenarioError
from scenarios.fleet import FleetScenario
from scenarios.world import SCENARIOS_DIR

from agents.experiments import DEFAULT_CREDENTIALS, DEFAULT_IMAGE

#: The directory holding the ``scenarios`` package: the repository root in a checkout (the build context).
REPO_ROOT = SCENARIOS_DIR.parent
#: The router's port, inside the compose network and on the host's loopback.
ROUTER_PORT = 7447
ROUTER_SERVICE = "router"
#: Where a secure service finds its credentials inside its container.
CREDENTIALS_MOUNT = "/credentials"
#: The observer a secure fleet's credentials name, for a meter on the host.
OBSERVER = "meter"

_SERVICE_NAME = re.compile(r"^[a-z0-9][a-z0-9_.-]*$")
#: How long an agent waits for its team-mates before it exits with an error, s.
WAIT_FOR_TEAM_S = 120
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


def _credential_files(member: str) -> list[str]:
    """What one member needs (the names ``evopose fleet credentials`` writes): the CA certificate, its own
    certificate, key and Zenoh configuration."""
    return ["ca.pem", f"{member}.pem", f"{member}.key", f"{member}.json5"]


def _volumes(credentials: str, member: str) -> list[str]:
    # compose reads a source without ./ ../ or / as a named volume, not a file
    source = credentials if credentials.startswith(("/", "./", "../")) else f"./{credentials}"
    return [f"{source.rstrip('/')}/{name}:{CREDENTIALS_MOUNT}/{name}:ro" for name in _credential_files(member)]


def credentials_command(scenario: FleetScenario, variant: str | None = None) -> str:
    """The command that makes the credentials a secure compose file of ``scenario`` expects."""
    chosen = scenario.variant(variant) if variant is not None else scenario.spec.variants[0]
    return (f"evopose fleet credentials {DEFAULT_CREDENTIALS} --fleet {scenario.name} --vehicles "
            f"{','.join(a.vehicle for a in chosen.agents)} --observers {OBSERVER} --router-host {ROUTER_SERVICE}")


def compose_document(scenario: FleetScenario, variant: str | None = None, *, image: str = DEFAULT_IMAGE,
                     context: str = ".", secure: bool = False, credentials: str = DEFAULT_CREDENTIALS) -> dict:
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
    secure : bool
        TLS, mutual TLS and the router's ACL, from the ``credentials`` directory (relative to the file).

    Raises
    ------
    ScenarioError
        Unknown variant, a vehicle whose name is no compose service name or clashes with another one.
    """
    chosen = scenario.variant(variant) if variant is not None else scenario.spec.variants[0]
    world = world_path_in_repo(scenario)
    protocol = "tls" if secure else "tcp"
    router_command = ["evopose", "router", "--listen", f"{protocol}/0.0.0.0:{ROUTER_PORT}"]
    if secure:
        router_command[2:2] = ["--config", f"{CREDENTIALS_MOUNT}/{ROUTER_SERVICE}.json5"]
    services: dict[str, dict] = {
        ROUTER_SERVICE: {
            **_image(image, context),
            "command": router_command,
            **({"volumes": _volumes(credentials, ROUTER_SERVICE)} if secure else {}),
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
        if secure:  # the vehicle's own file: a TLS client with its certificate
            command += ["--config", f"{CREDENTIALS_MOUNT}/{agent.vehicle}.json5"]
        else:
            command += ["--mode", "client"]
        command += ["--connect", f"{protocol}/{ROUTER_SERVICE}:{ROUTER_PORT}"]
        others = [v for v in vehicles if v != agent.vehicle]
        if others:  # a team that never meets is an error: give slow starts (first compilation) time
            command += ["--wait-for", ",".join(others), "--wait-timeout", f"{WAIT_FOR_TEAM_S:g}"]
        command.append("--json")
        services[name] = {
            **_image(image, context),
            "command": command,
            **({"volumes": _volumes(credentials, agent.vehicle)} if secure else {}),
            "depends_on": {ROUTER_SERVICE: {"condition": "service_healthy"}},
            "stop_signal": "SIGTERM",
            "stop_grace_period": "10s",
            "init": True,
        }
    return {"services": services}


def compose_header(scenario: FleetScenario, variant: str | None = None, *, image: str = DEFAULT_IMAGE,
                   context: str = ".", secure: bool = False, credentials: str = DEFAULT_CREDENTIALS) -> str:
    """The comment at the top of the file: how it was generated, and that it must not be edited."""
    chosen = scenario.variant(variant) if variant is not None else scenario.spec.variants[0]
    args = [scenario.name]
    if variant is not None:
        args += ["--variant", variant]
    if image != DEFAULT_IMAGE:
        args += ["--image", image]
    if context != ".":
        args += ["--context", context]
    if secure:
        args.append("--secure")
        if credentials != DEFAULT_CREDENTIALS:
            args += ["--credentials", credentials]
    lines = [f"# Generated by `evopose scenario compose {' '.join(args)}`: do not edit by hand;",
             "# run `make compose` to regenerate.",
             f"# Fleet scenario {scenario.name}, variant {chosen.name}"
             + (f": {scenario.spec.description}" if scenario.spec.description else "")]
    if secure:
        make = credentials_command(scenario, variant).replace(f" {DEFAULT_CREDENTIALS} ", f" {credentials} ", 1)
        lines += ["# Secure (docs/security.md): TLS, a certificate per service, the router's deny-by-default ACL.",
                  f"# First, beside this file: {make}",
                  f"# Meter from the host: evopose meter --config {credentials}/{OBSERVER}.json5 --fleet "
                  f"{scenario.name}"]
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
                 context: str = ".", secure: bool = False, credentials: str = DEFAULT_CREDENTIALS) -> str:
    """:func:`compose_document` as YAML text, after the generated-file header."""
    document = compose_document(scenario, variant, image=image, context=context, secure=secure,
                                credentials=credentials)
    body = yaml.dump(_flow_string_lists(document), Dumper=_Dumper, sort_keys=False, default_flow_style=False,
                     width=1000, allow_unicode=True)
    return compose_header(scenario, variant, image=image, context=context, secure=secure,
                          credentials=credentials) + body


__all__ = ["compose_document", "compose_header", "compose_yaml", "credentials_command", "world_path_in_repo"]
