"""The fleet commands: ``evopose router``, ``meter``, ``publish``, ``listen`` and ``fleet credentials``; thin wrappers
over the services in agents/tools/runners.py and agents/transport/credentials.py.

Registered on the main typer app by :func:`register` (called from agents/cli/main.py).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from agents.cli.options import (ConfigFile, Connect, Fleet, Listen, Mode, Multicast, Vehicle, emit_json,
                                session_options)
from agents.cli.signals import stop_on_signals
from agents.errors import FleetError

#: Topics a command can name (protocol.Topic's values; kept here so that --help does not import the protocol).
TOPICS = ("image", "features", "hint", "attitude", "pose", "stats")
#: What ``publish --payload`` can send.
PAYLOADS = ("valid", "garbage", "oversized", "truncated")


def _topics(text: str) -> tuple:
    from protocol import Topic

    try:
        return tuple(Topic(name.strip()) for name in text.split(",") if name.strip())
    except ValueError:
        raise FleetError(f"--topics must be names from {', '.join(t.value for t in Topic)}, got {text!r}") from None


def human_rate(bytes_per_s: float) -> str:
    """``123 B/s``, ``12.3 KB/s`` or ``1.23 MB/s`` (powers of 1000, like ``ros2 topic bw``)."""
    for unit, scale in (("MB/s", 1e6), ("KB/s", 1e3)):
        if bytes_per_s >= scale:
            return f"{bytes_per_s / scale:.3g} {unit}"
    return f"{bytes_per_s:.0f} B/s"


def human_size(size: float) -> str:
    for unit, scale in (("MB", 1e6), ("KB", 1e3)):
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{size:.0f} B"


def format_period(seconds: float | None) -> str:
    return "-" if seconds is None or math.isnan(seconds) else f"{seconds * 1e3:.2f} ms"


def meter_table(records: list[dict]) -> Table:
    """Per key: rate, period min/max/std, window, bandwidth, message sizes."""
    table = Table(title="evopose meter", title_justify="left")
    for name in ("key", "rate", "min", "max", "std dev", "window", "bandwidth", "mean", "min size", "max size"):
        table.add_column(name, justify="left" if name == "key" else "right")
    for r in records:
        table.add_row(r["key"], f"{r['rate_hz']:.2f} Hz", format_period(r["period_min_s"]),
                      format_period(r["period_max_s"]), format_period(r["period_std_s"]), str(r["window"]),
                      human_rate(r["bandwidth_Bps"]), human_size(r["size_mean"]), human_size(r["size_min"]),
                      human_size(r["size_max"]))
    return table


def print_ros2_lines(records: list[dict], period_s: float = 1.0) -> None:
    """Per key with a message in the last period (as ``ros2 topic hz`` prints only then): the key, then exactly the
    lines of ``ros2 topic hz`` and ``ros2 topic bw`` (agents/tools/meter.py)."""
    from agents.tools.meter import ros2_bw_line, ros2_hz_line

    for record in records:
        if record["age_s"] > period_s or record.get("ros2_hz") is None:
            continue
        lines = [f"[{record['key']}]", ros2_hz_line(record["ros2_hz"])]
        if record.get("ros2_bw") is not None:
            lines.append(ros2_bw_line(record["ros2_bw"]))
        sys.stdout.write("\n".join(lines) + "\n")
    sys.stdout.flush()


def agents_table(agents: dict[str, dict]) -> Table:
    """The agents' own sent/received counts per topic."""
    table = Table(title="agents' own counts", title_justify="left")
    for name in ("agent", "topic", "sent", "received", "bytes sent", "bytes received"):
        table.add_column(name, justify="left" if name in ("agent", "topic") else "right")
    for agent, stats in sorted(agents.items()):
        for topic in sorted(set(stats["sent"]) | set(stats["received"])):
            table.add_row(agent, topic, str(stats["sent"].get(topic, 0)), str(stats["received"].get(topic, 0)),
                          human_size(stats["bytes_sent"].get(topic, 0)),
                          human_size(stats["bytes_received"].get(topic, 0)))
        if stats["rejected"]:
            table.add_row(agent, "rejected", "", json.dumps(stats["rejected"]), "", "")
    return table


fleet_app = typer.Typer(name="fleet", help="A fleet's set-up: credentials.", no_args_is_help=True)


def _names(text: str) -> list[str]:
    return [name.strip() for name in text.split(",") if name.strip()]


@fleet_app.command("credentials")
def credentials_command(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="Where to write them (created, mode 0700).")],
    fleet: Fleet,
    vehicles: Annotated[str, typer.Option(help="Comma-separated vehicles, e.g. H1,H2,pioneer.")],
    observers: Annotated[str, typer.Option(help="Comma-separated members that only receive (e.g. meter).")] = "",
    router_host: Annotated[list[str] | None, typer.Option(
        "--router-host", metavar="HOST", help="Another name or address of the router (repeatable); 127.0.0.1 "
                                              "and localhost are always in its certificate.")] = None,
    listen: Annotated[str, typer.Option("--listen", metavar="ENDPOINT", help="The router's TLS endpoint.")]
    = "tls/127.0.0.1:7447",
    connect: Annotated[str | None, typer.Option("--connect", metavar="ENDPOINT",
                                                help="Where vehicles connect (default: the router's endpoint).")]
    = None,
    days: Annotated[int, typer.Option(min=1, help="Validity of the certificates, days.")] = 365,
    force: Annotated[bool, typer.Option("--force", help="Replace credentials already in DIR.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print what was written as one JSON object.")] = False,
) -> None:
    """A fleet CA, a certificate and key per vehicle (common name = vehicle) and for the router, and ready Zenoh
    configs: DIR/router.json5 (TLS, mTLS, deny-by-default ACL) and DIR/<vehicle>.json5 (TLS clients)."""
    from agents.transport.credentials import create_credentials

    made = create_credentials(directory, fleet, _names(vehicles), observers=_names(observers),
                              router_hosts=router_host or (), listen=listen, connect=connect, days=days,
                              overwrite=force)
    if as_json:
        emit_json(made.as_dict())
        return
    console = Console(stderr=True)
    console.print(f"fleet {fleet}: credentials for {', '.join((*made.vehicles, *made.observers))} in {directory}")
    console.print(f"  evopose router --config {made.router_config}")
    first = made.vehicles[0]
    console.print(f"  evopose agent --fleet {fleet} --vehicle {first} ... --config {made.config(first)}")
    console.print(f"  keep {directory / 'ca.key'} offline: only new certificates need it")


def register(app: typer.Typer) -> None:
    """Add the fleet commands to ``app``."""
    app.add_typer(fleet_app, name="fleet")

    @app.command("router")
    def router_command(listen: Listen = None, connect: Connect = None, config: ConfigFile = None,
                       multicast: Multicast = False,
                       as_json: Annotated[bool, typer.Option("--json", help="Print JSON lines.")] = False) -> None:
        """Run a Zenoh router (a Python session in router mode) until SIGINT/SIGTERM.

        Listens on tcp/127.0.0.1:7447 unless --listen or the --config file says otherwise."""
        from agents.tools.runners import run_router
        from agents.transport.session import listen_endpoints

        options = session_options("router", connect, listen, config, multicast)
        options = replace(options, listen=listen_endpoints(options))

        console = Console(stderr=True)

        def ready(info: dict) -> None:
            if as_json:
                emit_json({"event": "ready", **info})
            else:
                console.print(f"router {info['zid']} listening on {', '.join(info['listen'])}; Ctrl-C stops it")

        with stop_on_signals() as stop:
            summary = run_router(options, stop, ready)
        if as_json:
            emit_json({"event": "stopped", **summary})

    @app.command("meter")
    def meter_command(fleet: Annotated[str | None, typer.Option(help="Fleet to meter (default: every fleet).")] = None,
                      connect: Connect = None, listen: Listen = None, mode: Mode = None, config: ConfigFile = None,
                      multicast: Multicast = False,
                      window: Annotated[int, typer.Option(min=2, help="Messages per key in the window.")] = 100,
                      duration: Annotated[float | None, typer.Option(min=0, help="Stop after S seconds.")] = None,
                      as_json: Annotated[bool, typer.Option("--json", help="One JSON object per key per second.")]
                      = False,
                      table: Annotated[bool, typer.Option("--table", help="A table per second instead of the "
                                                                          "ros2 topic hz / bw lines.")] = False) -> None:
        """Print per key, once a second, what `ros2 topic hz` and `ros2 topic bw` print (--table: a table)."""
        from agents.tools.runners import run_meter

        console = Console(width=None if sys.stdout.isatty() else 160)

        def emit(records: list[dict]) -> None:
            if as_json:
                for record in records:
                    emit_json({"type": "rate", **record})
            elif table:
                if records:
                    console.print(meter_table(records))
            else:
                print_ros2_lines(records)

        with stop_on_signals() as stop:
            summary = run_meter(session_options(mode, connect, listen, config, multicast), stop, emit, fleet=fleet,
                                window=window, duration=duration)
        if as_json:
            emit_json({"type": "summary", **summary})
        else:
            console.print(meter_table(summary["keys"]))
            if summary["agents"]:
                console.print(agents_table(summary["agents"]))

    @app.command("publish")
    def publish_command(fleet: Fleet, vehicle: Vehicle,
                        topic: Annotated[str, typer.Option(help=f"What to send: {', '.join(TOPICS)}.")] = "hint",
                        rate: Annotated[float, typer.Option(min=0, help="Messages per second (0: flat out).")] = 10.0,
                        count: Annotated[int | None, typer.Option(min=0, help="Stop after N messages.")] = None,
                        duration: Annotated[float | None, typer.Option(min=0, help="Stop after S seconds.")] = None,
                        payload: Annotated[str, typer.Option(help=f"One of {', '.join(PAYLOADS)}.")] = "valid",
                        points: Annotated[int, typer.Option(min=0, help="Feature points per set.")] = 30,
                        width: Annotated[int, typer.Option(min=1, help="Image width, pixels.")] = 640,
                        height: Annotated[int, typer.Option(min=1, help="Image height, pixels.")] = 480,
                        seed: Annotated[int, typer.Option(min=0)] = 0,
                        wait: Annotated[float, typer.Option(min=0, help="Wait up to S seconds for a subscriber.")]
                        = 3.0,
                        stay: Annotated[bool, typer.Option(help="Stay alive after sending until SIGINT.")] = False,
                        connect: Connect = None, listen: Listen = None, mode: Mode = None, config: ConfigFile = None,
                        multicast: Multicast = False) -> None:
        """Send well-formed (or deliberately bad) messages of one topic at a rate: a test and demo tool."""
        if payload not in PAYLOADS:
            raise FleetError(f"--payload must be one of {', '.join(PAYLOADS)}, got {payload!r}")
        from protocol import Topic

        from agents.tools.runners import PublishSpec, run_publisher

        if topic not in TOPICS:
            raise FleetError(f"--topic must be one of {', '.join(TOPICS)}, got {topic!r}")
        spec = PublishSpec(Topic(topic), rate, count, duration, payload, points, width, height, seed)
        with stop_on_signals() as stop:
            emit_json(run_publisher(session_options(mode, connect, listen, config, multicast), stop, fleet, vehicle,
                                    spec, wait_s=wait, stay=stay))

    @app.command("listen")
    def listen_command(fleet: Fleet, vehicle: Vehicle,
                       topics: Annotated[str, typer.Option(help="Comma-separated topics to receive.")]
                       = "image,features,hint,attitude,pose",
                       duration: Annotated[float | None, typer.Option(min=0, help="Stop after S seconds.")] = None,
                       max_age: Annotated[float, typer.Option(min=0, help="Ignore data older than S seconds.")] = 1.0,
                       connect: Connect = None, listen: Listen = None, mode: Mode = None, config: ConfigFile = None,
                       multicast: Multicast = False) -> None:
        """Join the fleet as a receiving vehicle; print join/leave events and, at the end, the counters (JSON)."""
        from agents.tools.runners import run_listener

        with stop_on_signals() as stop:
            emit_json(run_listener(session_options(mode, connect, listen, config, multicast), stop, fleet, vehicle,
                                   _topics(topics), duration=duration, max_age_s=max_age, emit=emit_json))
