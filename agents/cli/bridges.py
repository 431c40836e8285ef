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
                         "--legacy-attachment", help="For Jazzy's rmw_zenoh_cpp 0.2.0-0.2.3 (before April 2025): "
                                                     "the keyed attachment layout, and each token's durability "
                                                     "written out (0.2.0-0.2.2 read an empty one as transient "
                                                     "local).")] = False,
                     hints_from: Annotated[str | None, typer.Option(
                         "--hints-from", metavar="TOPIC", help="Also send each geometry_msgs/msg/PoseStamped of this "
                                                               "ROS topic (the target's pose in map) to the fleet as a "
                                                               "hint.")] = None,
                     hint_vehicle: Annotated[str, typer.Option(help="The fleet vehicle name those hints come "
                                                                    "from.")] = "ros",
                     duration: Duration = None, as_json: Json = False, connect: Connect = None, listen: Listen = None,
                     mode: Mode = None, config: ConfigFile = None, multicast: Multicast = False) -> None:
        """Mirror the fleet onto ROS 2 topics in the rmw_zenoh format: poses, /tf, camera info (docs/ros2.md)."""
        from agents.bridges.mirror import run_mirror

        if hints_from is not None and not (hints_from.startswith("/") and len(hints_from) > 1):
            raise typer.BadParameter(f"{hints_from!r} is not an absolute ROS topic (/name)", param_hint="--hints-from")
        emit = _printer(as_json)
        with stop_on_signals() as stop:
            summary = run_mirror(session_options(mode, connect, listen, config, multicast), stop, fleet,
                                 domain=domain, legacy_attachment=legacy_attachment, duration=duration,
                                 hints_from=hints_from, hint_vehicle=hint_vehicle, emit=emit)
        emit_json(summary) if as_json else Console(stderr=True).print(summary)

    @app.command("record")
    def record_command(fleet: Fleet,
                       out: Annotated[Path, typer.Option("--out", "-o", help="A new rosbag2 bag directory DIR "
                                                         "(DIR/DIR.mcap, metadata.yaml and the raw channels in "
                                                         "DIR/DIR.raw.mcap), or the ROS 2 MCAP file X.mcap (the raw "
                                                         "channels beside it: X.raw.mcap).")],
                       duration: Duration = None,
                       ros: Annotated[bool, typer.Option("--ros/--no-ros", help="The ROS 2 channels (CDR).")] = True,
                       raw: Annotated[bool, typer.Option("--raw/--no-raw", help="The raw fleet channels (msgpack): "
                                                         "what replay publishes.")] = True,
                       as_json: Json = False, connect: Connect = None, listen: Listen = None, mode: Mode = None,
                       config: ConfigFile = None, multicast: Multicast = False) -> None:
        """Record every key of the fleet: a ROS 2 profile MCAP file (CDR, what rosbag2 reads) and the raw channels
        beside it (X.raw.mcap, what replay publishes)."""
        from agents.bridges.recording import run_record

        emit = _printer(as_json)
        with stop_on_signals() as stop:
            summary = run_record(session_options(mode, connect, listen, config, multicast), stop, fleet, out,
                                 duration=duration, ros=ros, raw=raw, emit=emit)
        emit_json(summary) if as_json else Console(stderr=True).print(summary)

    @app.command("replay")
    def replay_command(path: Annotated[Path, typer.Argument(metavar="RECORDING", help="A recording of evopose "
                                                                                      "record (a bag directory, X.mcap "
                                                                                      "or X.raw.mcap)."
                                                                                      )],
                       rate: Annotated[float, typer.Option(min=0.01, max=100, help="Speed: 2 replays twice as fast.")]
                       = 1.0,
                       fleet: Annotated[str | None, typer.Option(help="Replay under this fleet name (default: the "
                                                                      "recorded one).")] = None,
                       keep_stamps: Annotated[bool, typer.Option("--keep-stamps", help="Send the recorded stamps "
                                                                 "(receivers drop data older than their max age).")]
                       = False,
                       presence: Annotated[bool, typer.Option("--presence/--no-presence", help="Declare the recorded "
                                                              "vehicles' liveliness while replaying.")] = True,
                       wait: Annotated[float, typer.Option(min=0, help="Wait up to S seconds for subscribers.")] = 3.0,
                       as_json: Json = False, connect: Connect = None, listen: Listen = None, mode: Mode = None,
                       config: ConfigFile = None, multicast: Multicast = False) -> None:
        """Publish a recording's raw channels back on the fleet keys with their original timing."""
        from agents.bridges.recording import run_replay

        emit = _printer(as_json)
        with stop_on_signals() as stop:
            summary = run_replay(session_options(mode, connect, listen, config, multicast), stop, path, rate=rate,
                                 fleet=fleet, keep_stamps=keep_stamps, presence=presence, wait_s=wait, emit=emit)
        emit_json(summary) if as_json else Console(stderr=True).print(summary)

    @app.command("view")
    def view_command(fleet: Fleet,
                     port: Annotated[int, typer.Option(min=0, max=65535, help="WebSocket port (0: a free one).")]
                     = 8765,
                     host: Annotated[str, typer.Option(help="Address to serve on (default: loopback only).")]
                     = "127.0.0.1",
                     model: Annotated[str, typer.Option(help="Target model drawn at the estimates (a shipped name "
                                                             "or a file; 'none' for none).")] = "pioneer",
                     duration: Duration = None, as_json: Json = False, connect: Connect = None,
                     listen: Listen = None, mode: Mode = None, config: ConfigFile = None,
                     multicast: Multicast = False) -> None:
        """A live Foxglove view of the fleet: 3-D scene, feature points, fitness and error plots (open
        docs/foxglove-layout.json in Foxglove and connect to ws://HOST:PORT)."""
        from agents.bridges.view import run_view

        emit = _printer(as_json)
        with stop_on_signals() as stop:
            summary = run_view(session_options(mode, connect, listen, config, multicast), stop, fleet, host=host,
                               port=port, model=None if model == "none" else model, duration=duration, emit=emit)
        emit_json(summary) if as_json else Console(stderr=True).print(summary)
