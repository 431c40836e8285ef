"""The bridge commands: ``evopose ros2`` (mirror a fleet onto ROS 2 topics in the rmw_zenoh format),
``record`` / ``replay`` (MCAP) and ``view`` (a live Foxglove view); thin wrappers over agents/bridges/ (docs/ros2.md).

Registered on the main typer app by :func:`register` (called from agents/cli/main.py). Zenoh, rosbags, mcap and
foxglove are imported inside the commands only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from agents.cli.options import ConfigFile, Connect, Fleet, Listen, Mode, Multicast, emit_json, session_options
from agents.cli.signals import stop_on_signals

Json = Annotated[bool, typer.Option("--json", help="Print events as JSON lines.")]
Duration = Annotated[float | None, typer.Option(min=0, help="Stop after S seconds.")]


def _printer(as_json: bool):
    console = Console(stderr=True)

    def emit(record: dict) -> None:
        if as_json:
            emit_json(record)
        elif record.get("event") == "ready":
            console.print(" ".join(f"{k}={v}" for k, v in record.items() if k != "event") + " (Ctrl-C stops)")
        elif record.get("event") == "publisher":
            console.print(f"publishing {record['topic']} [{record['type']}]")
        else:
            console.print(record)

    return emit


def register(app: typer.Typer) -> None:
    """Add the bridge commands to ``app``."""

    @app.command("ros2")
    def ros2_command(fleet: Fleet,
                     domain: Annotated[int, typer.Option(min=0, max=232, help="ROS_DOMAIN_ID.")] = 0,
                     legacy_attachment: Annotated[bool, typer.Option(
                         "--legacy-attachment", help="Attach the keyed layout of rmw_zenoh_cpp 0.2.0-0.2.3 (Jazzy "
                                                     "before April 2025) instead of today's.")] = False,
                     duration: Duration = None, as_json: Json = False, connect: Connect = None, listen: Listen = None,
                     mode: Mode = None, config: ConfigFile = None, multicast: Multicast = False) -> None:
        """Mirror the fleet onto ROS 2 topics in the rmw_zenoh format: poses, /tf, camera info (docs/ros2.md)."""
        from agents.bridges.mirror import run_mirror

        emit = _printer(as_json)
        with stop_on_signals() as stop:
            summary = run_mirror(session_options(mode, connect, listen, config, multicast), stop, fleet,
                                 domain=domain, legacy_attachment=legacy_attachment, duration=duration, emit=emit)
        emit_json(summary) if as_json else Console(stderr=True).print(summary)


__all__ = ["register", "Path"]
