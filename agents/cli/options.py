"""What every fleet command shares: the Zenoh session options, and printing one JSON object per line.

Light on purpose: the CLI builds its options from here without importing Zenoh.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

if TYPE_CHECKING:
    from agents.transport.session import SessionOptions

Connect = Annotated[list[str] | None, typer.Option("--connect", "-e", metavar="ENDPOINT",
                                                   help="Endpoint to connect to, e.g. tcp/10.0.0.1:7447 (repeatable).")]
Listen = Annotated[list[str] | None, typer.Option("--listen", "-l", metavar="ENDPOINT",
                                                  help="Endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable; "
                                                       "default: loopback only).")]
Mode = Annotated[str | None, typer.Option(help="Zenoh mode: peer, client or router.")]
ConfigFile = Annotated[Path | None, typer.Option("--config", metavar="FILE",
                                                 help="Zenoh JSON5 config file (default: $ZENOH_CONFIG).")]
Multicast = Annotated[bool, typer.Option("--multicast/--no-multicast",
                                         help="Multicast scouting: find peers on the LAN (off by default; "
                                              "--no-multicast is accepted and changes nothing).")]
Fleet = Annotated[str, typer.Option(help="Fleet name.")]
Vehicle = Annotated[str, typer.Option(help="This vehicle's name.")]


def session_options(mode: str | None, connect: list[str] | None, listen: list[str] | None, config: Path | None,
                    multicast: bool) -> SessionOptions:
    """The :class:`~agents.transport.session.SessionOptions` of a command's network options."""
    from agents.transport.session import SessionOptions

    return SessionOptions(mode=mode, connect=tuple(connect or ()), listen=tuple(listen or ()), config_file=config,
                          multicast=multicast)


def finite(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, inf) made None, so that it is valid JSON."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def json_line(record: Any) -> str:
    """One line of valid JSON (RFC 8259: no NaN or Infinity)."""
    return json.dumps(finite(record), allow_nan=False)


def emit_json(record: dict) -> None:
    """Print one JSON object on its own line, flushed (for pipes and tests)."""
    sys.stdout.write(json_line(record) + "\n")
    sys.stdout.flush()
