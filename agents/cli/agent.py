"""``evopose agent``: one vehicle of the fleet as its own process (a thin wrapper over :mod:`agents.vehicle`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from agents.cli.options import ConfigFile, Connect, Listen, Mode, Multicast, emit_json, session_options
from agents.cli.signals import stop_on_signals
from agents.vehicle.config import ENCODINGS, FEATURES, ROLES, SHARES, VIEW_WEIGHTS, AgentConfig


def summary_table(summary: dict) -> Table:
    """The end-of-run summary of one agent, for people."""
    table = Table(title=f"{summary['vehicle']} ({summary['role']}, share {summary['share']})", show_header=False,
                  title_justify="left")
    table.add_column(style="bold")
    table.add_column(justify="right")
    halved = f", {summary['halved_frames']} halved" if summary.get("halved_frames") else ""
    table.add_row("frames", f"{summary['frames']} ({summary['late_frames']} skipped late{halved})")
    table.add_row("estimates (good)", f"{summary['estimates']} ({summary['good']})")
    if summary.get("set_aside"):
        table.add_row("set aside (jumped off the track)", f"{summary['set_aside']}")
    if summary.get("first_good_s") is not None:
        table.add_row("first good pose after", f"{summary['first_good_s']:.3f} s")
    if "error_position" in summary:
        table.add_row("mean position error", f"{summary['error_position'] * 100:.2f} cm")
        table.add_row("mean roll/pitch/yaw error",
                      " / ".join(f"{summary[f'error_{n}']:.2f}°" for n in ("roll", "pitch", "yaw")))
    if summary.get("frame_seconds_median") is not None:
        table.add_row("median estimate time", f"{summary['frame_seconds_median'] * 1e3:.1f} ms")
    traffic = summary["traffic"]
    for topic in sorted(set(traffic["sent"]) | set(traffic["received"])):
        table.add_row(f"{topic} sent / received",
                      f"{traffic['sent'].get(topic, 0)} / {traffic['received'].get(topic, 0)}")
    if traffic["rejected"]:
        table.add_row("rejected", json.dumps(traffic["rejected"]))
    return table


def register(app: typer.Typer) -> None:
    """Add ``agent`` to ``app``."""

    @app.command("agent")
    def agent_command(
        fleet: Annotated[str, typer.Option(help="Fleet name.")],
        vehicle: Annotated[str, typer.Option(help="This vehicle: a vehicle of the scenario, or its target.")],
        scenario: Annotated[str | None, typer.Option(
            "--scenario", "--world", help="Scenario file or shipped name (the simulated world; default: the world of "
                                          "a dataset --source, else exp2).")] = None,
        role: Annotated[str | None, typer.Option(help=f"One of {', '.join(ROLES)} (default: the scenario's).")]
        = None,
        share: Annotated[str, typer.Option(help=f"What to share with team-mates: {', '.join(SHARES)}.")] = "none",
        frames: Annotated[int | None, typer.Option(min=1, help="Stop after N frames (default: run until "
                                                                "SIGINT/SIGTERM).")] = None,
        fps: Annotated[float | None, typer.Option(help="Camera rate (default: the scenario's).")] = None,
        epoch_ns: Annotated[int, typer.Option(help="Fleet time of frame 0, ns since the Unix epoch; agents of a "
                                                   "fleet share it.")] = 0,
        epoch_from_stdin: Annotated[bool, typer.Option(
            "--epoch-from-stdin", help="Once warm (a 'warm' record), wait for the epoch on standard input: one line, "
                                       "ns since the Unix epoch (evopose scenario run gives it when every agent of "
                                       "a run is warm).")] = False,
        seed: Annotated[int, typer.Option(min=0, help="Seed of the searches.")] = 0,
        world_seed: Annotated[int | None, typer.Option(min=0, help="Replace the scenario's seed (image noise, "
                                                                   "IMU bias).")] = None,
        max_age: Annotated[float, typer.Option(help="Ignore team-mates' data older than S seconds.")] = 1.0,
        sync_wait: Annotated[float | None, typer.Option(min=0, help="Wait up to S seconds for team-mates' data "
                                                                    "of each frame (default: half a frame; the first "
                                                                    "frame: at least --max-age).")]
        = None,
        hint_rate: Annotated[float, typer.Option(help="Most hints per second.")] = 200.0,
        image_encoding: Annotated[str, typer.Option(help=f"Shared images: {', '.join(ENCODINGS)}.")] = "raw",
        imu: Annotated[bool, typer.Option("--imu/--no-imu", help="Ground station: hold the attitude within the "
                                                                 "airship's IMU reading (eq. 3).")] = True,
        imu_sigmas: Annotated[float, typer.Option(
            help="IMU tolerance eps of eq. (3), in the reading's standard deviations (1: the paper's interval of the "
                 "IMU's precision).")] = 1.0,
        wait_for: Annotated[str, typer.Option(help="Comma-separated team-mates to wait for before frame 0.")] = "",
        wait_timeout: Annotated[float, typer.Option(min=0, help="How long to wait for them, s.")] = 10.0,
        time_budget: Annotated[float | None, typer.Option(min=0, help="Seconds per search from scratch.")] = None,
        view_weights: Annotated[str, typer.Option(help=f"Eq. (4)'s view weights in searches: "
                                                       f"{', '.join(VIEW_WEIGHTS)} (BENCHMARKS.md, weights).")]
        = "step",
        operating_radius: Annotated[float, typer.Option(help="Refuse team-mates' cameras and poses farther than "
                                                             "this from the operating area, m.")] = 1000.0,
        max_clock_offset: Annotated[float, typer.Option(help="Refuse data stamped further ahead than this, s "
                                                             "(team-mates' clocks must agree to within it).")] = 0.5,
        source: Annotated[str | None, typer.Option(
            help="Real images instead of the renderer: a video file, an image sequence (printf pattern like "
                 "left%02d.jpg, a glob, or a directory), a rendered dataset (its root, or a camera's folder in it: "
                 "that camera's images with each frame's camera and truth; docs/datasets.md), a V4L2 device "
                 "(/dev/videoN or N), or a ROS 2 topic in the rmw_zenoh format, ros2:/camera/image_raw "
                 "(sensor_msgs/msg/Image or CompressedImage). A file source is played one frame per tick and ends the "
                 "run; a device or a topic gives its newest frame.")] = None,
        camera_info: Annotated[str | None, typer.Option(
            help="--source's intrinsics: a ROS camera_info YAML, or ros2:/TOPIC (its first valid "
                 "sensor_msgs/msg/CameraInfo); default: a dataset's camera_info, else the scenario vehicle's.")] = None,
        camera_pose: Annotated[str | None, typer.Option(
            help="--source's world_from_camera: a YAML/JSON file with a static x, y, z, roll, pitch, yaw (m, rad), or "
                 "ros2:/TOPIC (the newest geometry_msgs/msg/PoseStamped of the optical frame in map at each frame); "
                 "default: a dataset's per-frame pose, else the scenario vehicle's pose.")] = None,
        ros_domain: Annotated[int, typer.Option(min=0, max=232, help="ROS_DOMAIN_ID of the ros2: inputs.")] = 0,
        source_max_age: Annotated[float, typer.Option(
            help="A ros2: image or camera pose received longer ago than S seconds is stale: the frame is skipped "
                 "(no estimate; counted 'ros2 stale').")] = 1.0,
        camera_frame: Annotated[str | None, typer.Option(
            help="With --camera-pose ros2:/tf: the camera's optical frame, composed from map through /tf and "
                 "/tf_static (e.g. H1/camera_optical).")] = None,
        features: Annotated[str, typer.Option(help=f"Feature points: {', '.join(FEATURES)}: auto is contrast (the "
                                                   "marks by their contrast, any camera look) on camera images "
                                                   "(--source, worlds with a camera model) and marks (preset hue "
                                                   "bands) on drawn worlds; corners: a chessboard's inner corners.")]
        = "auto",
        mark_scorer: Annotated[str | None, typer.Option(
            help="With --features contrast: which spots are marks. shipped (the default): the shipped scorers, fitted "
                 "on rendered worlds through random looks; bars: the hand-set bars; or a JSON file of `evopose "
                 "train-scorer`, replacing the shipped one of its kind (the scorer of 2-4 px marks, or with --scale "
                 "telephoto the context model of marks of 3 px and more).")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="One JSON object per event on stdout.")] = False,
        connect: Connect = None, listen: Listen = None, mode: Mode = None, config: ConfigFile = None,
        multicast: Multicast = False,
    ) -> None:
        """Run one vehicle: acquire, extract, share, estimate (eq. 1-4 and hints), publish; until stopped."""
        from agents.vehicle.agent import run_agent

        agent_config = AgentConfig(
            fleet=fleet, vehicle=vehicle, scenario=scenario, role=role, share=share, frames=frames, fps=fps,
            epoch_ns=epoch_ns, epoch_from_stdin=epoch_from_stdin, seed=seed, world_seed=world_seed, max_age_s=max_age,
            sync_wait_s=sync_wait, hint_rate_hz=hint_rate, image_encoding=image_encoding, use_attitude=imu,
            attitude_sigmas=imu_sigmas,
            wait_for=tuple(v.strip() for v in wait_for.split(",") if v.strip()), wait_timeout_s=wait_timeout,
            time_budget_s=time_budget, operating_radius_m=operating_radius, max_clock_offset_s=max_clock_offset,
            source=source, camera_info=camera_info, camera_pose=camera_pose, ros_domain=ros_domain, features=features,
            mark_scorer=mark_scorer, view_weights=view_weights, source_max_age_s=source_max_age, camera_frame=camera_frame)
        console = Console(stderr=True)

        def emit(record: dict) -> None:
            if as_json:
                emit_json(record)
            elif record["event"] in ("warm", "ready", "join", "leave"):
                console.print(f"{record['event']}: {record.get('vehicle')}")
            elif record["event"] == "no-estimate":
                console.print(f"frame {record['frame']}: {record['reason']} ({record['points']})")
            elif record["event"] == "end-of-source":
                console.print(f"end of --source after {record['frames']} frames")
            elif record["event"] == "frame":
                e, p = record.get("error"), record["pose"]  # no error without ground truth (a real source)
                measured = (f"error {e['position'] * 100:.1f} cm {max(e['roll'], e['pitch'], e['yaw']):.2f}°"
                            if e is not None else f"pose x {p['x']:.3f} y {p['y']:.3f} z {p['z']:.3f} m")
                console.print(f"frame {record['frame']}: views {','.join(record['views'])} {measured} "
                              f"{record['trust']}{'' if record['good'] else ': ' + record['reason']} "
                              f"{record['seconds'] * 1e3:.0f} ms")

        with stop_on_signals() as stop:
            summary = run_agent(session_options(mode, connect, listen, config, multicast), agent_config, stop, emit)
        if summary is None:  # stopped before frame 0 (--epoch-from-stdin): nothing ran
            return
        if as_json:
            emit_json(summary)
        else:
            Console().print(summary_table(summary))


__all__ = ["register", "summary_table"]
