"""One Zenoh session per process, configured from ``--mode``, ``--connect``, ``--listen`` and ``ZENOH_CONFIG``.

Precedence: the file (``config_file``, else the ``ZENOH_CONFIG`` environment variable), then the
command-line options on top of it. Open the session in the process that uses it: a Zenoh session does
not survive ``fork`` (docs/design.md §4).

Safe defaults (docs/security.md), where Zenoh's own are wide open:

- multicast scouting is off unless ``multicast=True`` (``--multicast``), whatever the file says;
- a router or peer listens on loopback unless endpoints are given (``--listen``, or a file that sets
  ``listen/endpoints``): a router on :data:`ROUTER_LISTEN` ``tcp/127.0.0.1:7447``, a peer on
  :data:`PEER_LISTEN` ``tcp/127.0.0.1:0`` (a free port, so that peers on this host that learn of it by
  gossip can still connect to it). Zenoh's defaults would be ``tcp/[::]:7447`` and ``tcp/[::]:0``:
  every interface. A peer that must be reachable from other hosts says so: ``--listen tcp/0.0.0.0:0``.
- a message is reassembled up to :data:`MAX_MESSAGE_BYTES` (16 MiB, twice the largest payload any topic
  accepts, ``protocol.limits``) instead of Zenoh's 1 GiB, unless the file sets
  ``transport/link/rx/max_message_size``: a larger message is dropped by Zenoh before it is assembled, and
  the link stays up for the messages after it (docs/security.md);
- TLS file names in a configuration file that are relative (as ``evopose fleet credentials`` writes
  them) are resolved against the file's directory, not the working directory.

Reconnection (docs/scaling.md, "Faults"): Zenoh 1.x re-opens a session that closed on a ``connect``
endpoint (a router killed and restarted, a link lost for longer than the lease) by itself, in client,
peer and router mode, retrying for ever; its declarations (subscribers, liveliness tokens) are declared
again on the new session. Zenoh's retry period doubles from 1 s up to 4 s, so a router back after 5 s
was found up to 4 s later; :data:`CONNECT_RETRY` (unless the file sets ``connect/retry``) retries every
0.25-1 s, so agents are back within about a second of their router. ``connect/timeout_ms`` and
``exit_on_failure`` concern the first connection only (a client still fails at once when its router is
not there at start: Zenoh's default, kept).

Shared memory: Zenoh 1.x by default copies every message over 3 KB into a 16 MiB shared-memory pool of the
sender, which a peer on the same host maps too. Two agents sharing raw images held both pools resident, about
45 MB of each agent (``benchmarks/bench_footprint.py``, ``--share raw``: 290 MB at 30 s with it, 245 MB without,
the same images sent and received). Agents of a fleet run on separate vehicles, where shared memory is not used,
so sessions turn it off (:data:`SHARED_MEMORY_KEY`) unless the file changes anything in that section (a file
that sets ``mode: "init"`` or its own ``pool_size`` keeps it on).
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from agents.errors import BusConfigError
from agents.transport.ports import listening, next_port
from protocol.limits import SIZE_LIMITS

MODES = ("peer", "client", "router")
#: Where a router listens by default (loopback only).
ROUTER_LISTEN = "tcp/127.0.0.1:7447"
#: Where a peer listens by default: loopback, a free port.
PEER_LISTEN = "tcp/127.0.0.1:0"
#: File-path keys of ``transport/link/tls`` resolved against the configuration file's directory.
TLS_FILE_KEYS = ("root_ca_certificate", "listen_private_key", "listen_certificate", "connect_private_key",
                 "connect_certificate")
#: How often a lost ``connect`` endpoint is tried again, ms: Zenoh's default is 1000 doubling up to 4000.
CONNECT_RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}
#: Largest message a session reassembles, bytes: twice the largest payload a topic accepts (room for the key,
#: attachments and other Zenoh traffic of the same size class, e.g. a ROS 2 mirror's image).
MAX_MESSAGE_BYTES = 2 * max(SIZE_LIMITS.values())
_MAX_MESSAGE_KEY = "transport/link/rx/max_message_size"
#: Zenoh's shared-memory section: off unless the file changed it (module doc).
SHARED_MEMORY_KEY = "transport/shared_memory"
_ENDPOINT = re.compile(r"[a-z][a-z0-9\-]*/\S+")


@dataclass(frozen=True)
class SessionOptions:
    """How to open the process's Zenoh session.

    Attributes
    ----------
    mode : str or None
        ``peer``, ``client`` or ``router``; ``None`` keeps the file's (Zenoh's default: peer).
    connect, listen : tuple of str
        Endpoints such as ``tcp/127.0.0.1:7447``.
    config_file : Path or None
        A Zenoh JSON5 configuration; ``None`` reads ``ZENOH_CONFIG`` when set.
    multicast : bool
        Multicast scouting (discovery of peers on the LAN); off by default.
    """

    mode: str | None = None
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: Path | None = None
    multicast: bool = False
    extra: dict[str, object] = field(default_factory=dict)  #: more ``path -> value`` insertions


def _zenoh_message(err: Exception) -> str:
    text = str(err)
    found = re.search(r'msg: "(.*?)(?: at /[^"]*)?"', text)
    message = found.group(1) if found else text.split(" at /")[0]
    return message.replace('\\"', '"')


def _insert(config: zenoh.Config, path: str, value: object, what: str) -> None:
    try:
        config.insert_json5(path, json.dumps(value))
    except zenoh.ZError as err:
        raise BusConfigError(f"{what}: {_zenoh_message(err)}") from None


def _get(config: zenoh.Config, path: str) -> object:
    return json.loads(config.get_json(path))


def _left_default(config: zenoh.Config, path: str) -> bool:
    """Whether ``path`` still holds Zenoh's default (no file chose it)."""
    return _get(config, path) == _get(zenoh.Config(), path)


def config_path(options: SessionOptions) -> Path | None:
    """The configuration file ``options`` read: ``config_file``, else ``$ZENOH_CONFIG``, else None."""
    if options.config_file is not None:
        return Path(options.config_file)
    return Path(os.environ["ZENOH_CONFIG"]) if os.environ.get("ZENOH_CONFIG") else None


def _resolve_tls_files(config: zenoh.Config, directory: Path) -> None:
    for key in TLS_FILE_KEYS:
        value = _get(config, f"transport/link/tls/{key}")
        if isinstance(value, str) and value and not Path(value).is_absolute():
            _insert(config, f"transport/link/tls/{key}", str((directory / value).absolute()), key)


def make_config(options: SessionOptions) -> zenoh.Config:
    """The Zenoh configuration of ``options``; raise :class:`BusConfigError` naming the bad option."""
    path = config_path(options)
    if path is not None:
        if not Path(path).is_file():
            raise BusConfigError(f"Zenoh config file {str(path)!r} does not exist or is not a file")
        try:
            config = zenoh.Config.from_file(str(path))
        except zenoh.ZError as err:
            raise BusConfigError(f"Zenoh config file {str(path)!r}: {_zenoh_message(err)}") from None
        _resolve_tls_files(config, Path(path).parent)
    else:
        config = zenoh.Config()
    if options.mode is not None:
        if options.mode not in MODES:
            raise BusConfigError(f"--mode must be one of {', '.join(MODES)}, got {options.mode!r}")
        _insert(config, "mode", options.mode, "--mode")
    for option, endpoints in (("connect", options.connect), ("listen", options.listen)):
        for endpoint in endpoints:
            if not _ENDPOINT.fullmatch(endpoint):
                raise BusConfigError(f"--{option} endpoint {endpoint!r} must look like tcp/127.0.0.1:7447")
        if endpoints:
            _insert(config, f"{option}/endpoints", list(endpoints), f"--{option} {' '.join(endpoints)}")
    if not options.listen:
        _listen_on_loopback_by_default(config)
    _insert(config, "scouting/multicast/enabled", bool(options.multicast), "multicast")
    if _left_default(config, _MAX_MESSAGE_KEY):
        _insert(config, _MAX_MESSAGE_KEY, MAX_MESSAGE_BYTES, _MAX_MESSAGE_KEY)
    if _left_default(config, SHARED_MEMORY_KEY):  # the file did not choose: no pools (module doc)
        _insert(config, f"{SHARED_MEMORY_KEY}/enabled", False, f"{SHARED_MEMORY_KEY}/enabled")
    if _get(config, "connect/retry") is None:  # the file did not choose
        _insert(config, "connect/retry", CONNECT_RETRY, "connect/retry")
    for key, value in options.extra.items():
        _insert(config, key, value, key)
    return config


def _listen_on_loopback_by_default(config: zenoh.Config) -> None:
    """Replace Zenoh's default listen endpoints (every interface) by loopback ones; keep endpoints a file set."""
    if not _left_default(config, "listen/endpoints"):
        return  # the file chose
    mode = _get(config, "mode") or "peer"
    if mode == "router":
        _insert(config, "listen/endpoints", [ROUTER_LISTEN], "listen")
    elif mode == "peer":
        _insert(config, "listen/endpoints", [PEER_LISTEN], "listen")


def listen_endpoints(options: SessionOptions) -> tuple[str, ...]:
    """Where a session opened with ``options`` will listen (after the file and the loopback defaults)."""
    config = make_config(options)
    endpoints = _get(config, "listen/endpoints")
    if isinstance(endpoints, dict):
        endpoints = endpoints.get(_get(config, "mode") or "peer") or []
    return tuple(endpoints)


def open_session(options: SessionOptions) -> zenoh.Session:
    """Open the process's Zenoh session; raise :class:`BusConfigError` if it cannot be opened."""
    config = make_config(options)
    try:
        return zenoh.open(config)
    except zenoh.ZError as err:
        message = _zenoh_message(err)
        in_use = re.search(r"bound to (\S+?):\s.*Address already in use", message)
        if in_use:
            endpoint = in_use.group(1)
            raise BusConfigError(f"{endpoint} is already in use (another fleet, router or agent listens there): "
                                 f"stop it, or listen on another port (--listen {next_port(endpoint)}; "
                                 "make demo PORT=...)") from None
        if "Unable to connect to any of" in message and options.connect and not any(
                listening(endpoint) for endpoint in options.connect):
            where = ", ".join(options.connect) or "the --connect endpoints of the configuration"
            raise BusConfigError(f"could not reach the fleet's router at {where}: nothing listens there; start "
                                 f"it (evopose router --listen {options.connect[0]}) or fix --connect") from None
        raise BusConfigError(f"cannot open the Zenoh session: {message}") from None



