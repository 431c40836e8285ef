"""One Zenoh session per process, configured from ``--mode``, ``--connect``, ``--listen`` and ``ZENOH_CONFIG``.

Precedence: the file (``config_file``, else the ``ZENOH_CONFIG`` environment variable), then the
command-line options on top of it. ``multicast=False`` turns multicast scouting off, as tests do
on loopback. Open the session in the process that uses it: a Zenoh session does not survive
``fork`` (DESIGN.md §4).
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from agents.errors import BusConfigError

MODES = ("peer", "client", "router")
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
        Multicast scouting (discovery of peers on the LAN); off for tests.
    """

    mode: str | None = None
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: Path | None = None
    multicast: bool = True
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


def make_config(options: SessionOptions) -> zenoh.Config:
    """The Zenoh configuration of ``options``; raise :class:`BusConfigError` naming the bad option."""
    path = options.config_file
    if path is None and os.environ.get("ZENOH_CONFIG"):
        path = Path(os.environ["ZENOH_CONFIG"])
    if path is not None:
        if not Path(path).is_file():
            raise BusConfigError(f"Zenoh config file {str(path)!r} does not exist or is not a file")
        try:
            config = zenoh.Config.from_file(str(path))
        except zenoh.ZError as err:
            raise BusConfigError(f"Zenoh config file {str(path)!r}: {_zenoh_message(err)}") from None
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
    if not options.multicast:
        _insert(config, "scouting/multicast/enabled", False, "multicast")
    for key, value in options.extra.items():
        _insert(config, key, value, key)
    return config


def open_session(options: SessionOptions) -> zenoh.Session:
    """Open the process's Zenoh session; raise :class:`BusConfigError` if it cannot be opened."""
    config = make_config(options)
    try:
        return zenoh.open(config)
    except zenoh.ZError as err:
        raise BusConfigError(f"cannot open the Zenoh session: {_zenoh_message(err)}") from None
