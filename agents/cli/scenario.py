"""``evopose scenario list | show | run``: the shipped fleet scenarios, and running one as separate processes."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from agents.cli.options import emit_json
from agents.cli.signals import stop_on_signals
from agents.experiments import DEFAULT_CREDENTIALS, DEFAULT_ENDPOINT, DEFAULT_IMAGE

scenario_app = typer.Typer(name="scenario", help="Fleet scenarios: list, show, run, compose.", no_args_is_help=True)


def _fmt(value: float, sd: float, scale: float = 1.0, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value * scale:.{digits}f} ({sd * scale:.{digits}f})"


def results_table(result_rows: list[dict], title: str) -> Table:
    """Roll/pitch/yaw error (deg), X/Y/Z error (cm), σ over runs, time to the first good pose, traffic."""
    table = Table(title=title, title_justify="left")
    for name in ("variant", "vehicle", "runs", "roll °", "pitch °", "yaw °", "X cm", "Y cm", "Z cm",
                 "first good s", "good", "sent"):
        table.add_column(name, justify="left" if name in ("variant", "vehicle", "sent") else "right")
    for r in result_rows:
        sent = ", ".join(f"{t} {v['rate_hz']:.0f}/s × {v['bytes_per_message']:.0f} B"
                         for t, v in sorted(r["traffic"].items()))
        table.add_row(r["variant"], r["vehicle"], str(r["runs"]),
                      *(_fmt(r[n], r[f"{n}_sd"]) for n in ("roll", "pitch", "yaw")),
                      *(_fmt(r[n], r[f"{n}_sd"], 100, 1) for n in ("x", "y", "z")),
                      _fmt(r["first_good_s"], r["first_good_sd"], 1, 3), f"{r['good_fraction']:.0%}", sent or "-")
    return table


@scenario_app.command("list")
def list_command(as_json: Annotated[bool, typer.Option("--json")] = False) -> None:
    """The shipped fleet scenarios."""
    from scenarios.fleet import fleet_scenario_names, load_fleet_scenario

    items = []
    for name in fleet_scenario_names():
        s = load_fleet_scenario(name)
        items.append({"name": name, "description": s.spec.description, "world": s.world.name,
                      "variants": [v.name for v in s.spec.variants]})
    if as_json:
        print(json.dumps(items))
        return
    table = Table(title="fleet scenarios", title_justify="left")
    for col in ("name", "world", "variants", "description"):
        table.add_column(col)
    for item in items:
        table.add_row(item["name"], item["world"], ", ".join(item["variants"]), item["description"])
    Console().print(table)


@scenario_app.command("show")
def show_command(name: Annotated[str, typer.Argument(help="Scenario name or file.")],
                 as_json: Annotated[bool, typer.Option("--json")] = False) -> None:
    """One fleet scenario: its world, frames, and each variant's agents."""
    from scenarios.fleet import load_fleet_scenario

    s = load_fleet_scenario(name)
    doc = {"name": s.name, "file": str(s.path), "world": str(s.world_path), "frames": s.frames, "fps": s.fps,
           "router": s.spec.router, "description": s.spec.description, "paper": s.spec.paper,
           "variants": [{"name": v.name, "agents": [a.model_dump() for a in v.agents]} for v in s.spec.variants]}
    if as_json:
        print(json.dumps(doc))
        return
    console = Console()
    console.print(f"[bold]{s.name}[/bold]: {s.spec.description}\nworld {s.world_path} ({s.world.name}), "
                  f"{s.frames} frames at {s.fps:g} fps, {'router' if s.spec.router else 'peer to peer'}")
    for v in s.spec.variants:
        console.print(f"  variant [bold]{v.name}[/bold]:")
        for a in v.agents:
            console.print(f"    evopose agent {' '.join(a.cli_args())}")


@scenario_app.command("run")
def run_command(
    name: Annotated[str, typer.Argument(help="Scenario name or file.")],
    runs: Annotated[int, typer.Option(min=1, help="Runs per variant (each with other seeds).")] = 1,
    frames: Annotated[int | None, typer.Option(min=1, help="Frames per run (default: the scenario's).")] = None,
    seed: Annotated[int, typer.Option(min=0, help="Search seed of run 0.")] = 0,
    fps: Annotated[float | None, typer.Option(min=0.1, max=1000, help="Camera rate (default: the scenario's).")]
    = None,
    variant: Annotated[list[str] | None, typer.Option(help="Run only this variant (repeatable).")] = None,
    world: Annotated[str | None, typer.Option(help="Run on this world instead (a shipped name such as "
                                                   "exp2-paper-scale, or a file) with the same vehicle names.")]
    = None,
    listen: Annotated[str, typer.Option("--listen", help="Where the fleet can be reached from outside.")]
    = DEFAULT_ENDPOINT,
    secure: Annotated[bool, typer.Option("--secure", help="TLS with a certificate per vehicle and a router with a "
                                                          "deny-by-default ACL on the --listen address, as tls/ "
                                                          "(docs/security.md).")] = False,
    credentials: Annotated[Path | None, typer.Option(
        "--credentials", metavar="DIR", help="With --secure: keep each run's credentials in DIR/<fleet> "
                                             "(default: a temporary directory, removed).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object with every run's summaries.")] = False,
    ros2: Annotated[bool, typer.Option("--ros2", help="Also mirror each run onto ROS 2 topics (evopose ros2, "
                                                      "docs/ros2.md).")] = False,
    ros2_domain: Annotated[int, typer.Option(min=0, max=232, help="ROS_DOMAIN_ID of --ros2.")] = 0,
    record: Annotated[Path | None, typer.Option("--record", metavar="DIR", help="Record each run's traffic into "
                                                "the rosbag2 bag directory DIR/<fleet> (evopose record: "
                                                "<fleet>.mcap and metadata.yaml, what ros2 bag info opens; the "
                                                "raw channels, for evopose replay, in <fleet>.raw.mcap).")] = None,
    dataset: Annotated[Path | None, typer.Option(
        "--dataset", metavar="DIR", help="Run on a rendered dataset (docs/datasets.md): each camera vehicle plays "
                                         "its camera's folder (evopose agent --source DIR), on the dataset's world "
                                         "and frames.")] = None,
    features: Annotated[str | None, typer.Option(
        "--features", metavar="KIND", help="Every camera vehicle's feature front-end: auto (contrast on camera "
                                           "images, marks on drawn worlds), marks (preset hue bands), contrast "
                                           "(camera images: docs/datasets.md) or corners (default: the "
                                           "scenario's).")] = None,
) -> None:
    """Start every agent of the scenario as its own process, run, stop them all, print the results."""
    if credentials is not None and not secure:
        raise typer.BadParameter("needs --secure", param_hint="--credentials")
    if ros2 and secure:
        raise typer.BadParameter("the ROS 2 mirror has no fleet certificate; run evopose ros2 with one instead",
                                 param_hint="--ros2")
    if record is not None and secure:
        raise typer.BadParameter("the recorder has no fleet certificate; run evopose record with one instead",
                                 param_hint="--record")
    if record is not None and record.exists() and not record.is_dir():
        raise typer.BadParameter(f"{record} exists and is not a directory", param_hint="--record")
    if dataset is not None and world is not None:
        raise typer.BadParameter("a dataset has its own world (its world.yaml)", param_hint="--world")
    from agents.errors import FleetError
    from agents.transport.ports import listening, next_port

    if listening(listen):  # the fleet's first listener would fail, and its team-mates would wait for it in vain
        raise FleetError(f"{listen} is already in use (another fleet, router or agent listens there): stop it, or "
                         f"run on another port (--listen {next_port(listen)}; make demo PORT=...)")
    mirror_domain = ros2_domain if ros2 else None
    from scenarios.fleet import load_fleet_scenario

    from agents.experiments.results import rows
    from agents.experiments.runner import dataset_scenario, run_scenario

    if dataset is None:
        scenario = load_fleet_scenario(name, world)
    else:
        scenario, dataset_frames = dataset_scenario(name, dataset, variant)
        if frames is not None and frames > dataset_frames:
            raise typer.BadParameter(f"the dataset has {dataset_frames} frames, not {frames}", param_hint="--frames")
        frames = frames or dataset_frames
    if features is not None:
        from scenarios.fleet import FEATURE_KINDS

        if features not in FEATURE_KINDS:
            raise typer.BadParameter(f"must be one of {', '.join(FEATURE_KINDS)}, got {features!r}",
                                     param_hint="--features")
        scenario = scenario.with_features(features)
    console = Console(stderr=True)
    with stop_on_signals() as stop:
        if as_json:
            records = run_scenario(scenario, runs=runs, frames=frames, seed=seed, endpoint=listen,
                                   variants=variant, stop=stop, fps=fps, secure=secure, credentials=credentials,
                                   ros2_domain=mirror_domain, record_dir=record, dataset=dataset)
        else:
            with console.status(f"{scenario.name}: starting") as status:
                def progress(p: dict) -> None:
                    status.update(f"{scenario.name} / {p['variant']}: run {p['run'] + 1} of {runs}, "
                                  f"frame {p['frames']} of {frames or scenario.frames}")

                def finished(record: dict) -> None:
                    console.print(f"{record['variant']} run {record['run'] + 1}/{runs} done "
                                  f"({record['seconds']:.1f} s)")

                records = run_scenario(scenario, runs=runs, frames=frames, seed=seed, endpoint=listen,
                                       variants=variant, stop=stop, on_run=finished, on_progress=progress,
                                       fps=fps, secure=secure, credentials=credentials, ros2_domain=mirror_domain,
                                       record_dir=record, dataset=dataset)
    result_rows = rows(records)
    if as_json:
        emit_json({"scenario": scenario.name, "dataset": None if dataset is None else str(dataset),
                   "interrupted": stop.is_set(), "rows": result_rows, "runs": records})
        return
    on = scenario.world.name if dataset is None else f"dataset {dataset} ({scenario.world.name})"
    table = results_table(result_rows, f"{scenario.name} on {on}: mean error (σ over runs)")
    Console(width=None if sys.stdout.isatty() else 200).print(table)
    if stop.is_set():
        console.print("interrupted: every agent was stopped")


@scenario_app.command("compose")
def compose_command(
    name: Annotated[str, typer.Argument(help="Scenario name or file.")],
    variant: Annotated[str | None, typer.Option(help="The variant to run (default: the first).")] = None,
    out: Annotated[Path | None, typer.Option("--out", metavar="FILE", help="Write here, not to stdout.")] = None,
    image: Annotated[str, typer.Option(help="Image of every service.")] = DEFAULT_IMAGE,
    context: Annotated[str, typer.Option(help="Build context relative to the file (.. for compose/).")] = ".",
    secure: Annotated[bool, typer.Option("--secure", help="TLS, a certificate per service and the router's ACL, "
                                                          "from a credentials directory (evopose fleet "
                                                          "credentials ... --router-host router).")] = False,
    credentials: Annotated[str, typer.Option("--credentials", metavar="DIR",
                                             help="With --secure: the credentials directory, relative to the "
                                                  "file.")] = DEFAULT_CREDENTIALS,
) -> None:
    """A docker-compose file of the scenario: a Zenoh router, and one service per agent joining it."""
    from scenarios.fleet import load_fleet_scenario

    from agents.experiments.compose import compose_yaml

    if credentials != DEFAULT_CREDENTIALS and not secure:
        raise typer.BadParameter("needs --secure", param_hint="--credentials")
    text = compose_yaml(load_fleet_scenario(name), variant, image=image, context=context, secure=secure,
                        credentials=credentials)
    if out is None:
        sys.stdout.write(text)
    else:
        out.write_text(text, encoding="utf-8")


def register(app: typer.Typer) -> None:
    app.add_typer(scenario_app, name="scenario")


def register_report(app: typer.Typer) -> None:
    """Add ``evopose report`` to ``app``."""

    @app.command("report")
    def report_command(
        runs: Annotated[int, typer.Option(min=1, help="Runs per variant.")] = 10,
        frames: Annotated[int | None, typer.Option(min=1, help="Frames per run (default: each scenario's).")] = None,
        seed: Annotated[int, typer.Option(min=0, help="Search seed of run 0.")] = 0,
        out: Annotated[Path, typer.Option(help="Directory for report.md and the figures.")] = Path("report"),
        listen: Annotated[str, typer.Option("--listen", help="Where each scenario's fleet listens.")]
        = DEFAULT_ENDPOINT,
        photoreal: Annotated[Path | None, typer.Option(
            "--photoreal", metavar="DIR", help="The rendered dataset of 'Table II on a photoreal dataset' "
                                               "(default: datasets/photoreal-report if it exists, else "
                                               "tests/data/photoreal/paper; neither: the section is skipped).")]
        = None,
    ) -> None:
        """Run the paper's experiments and write report.md: Tables I and II, bandwidth, Fig. 6, findings."""
        from agents.experiments.report import write_report

        console = Console(stderr=True)
        with stop_on_signals() as stop:
            path = write_report(out, runs=runs, frames=frames, seed=seed, endpoint=listen, stop=stop,
                                on_run=lambda r: console.print(f"{r['scenario']} / {r['variant']}: run "
                                                               f"{r['run'] + 1} "
                                                               + (f"failed: {r['error']}" if r.get("error") else
                                                                  f"done in {r['seconds']:.1f} s")),
                                photoreal=photoreal)
        print(path)
