"""The report's figures: Fig. 6 (fitness of the best per generation), error over time per vehicle, the driving
Pioneer's track from above with each helicopter's estimates, and bandwidth per share mode.

Errors over time come from the poses each agent published (its summary's ``poses``, read as
:class:`agents.runs.PoseRow`) against the world's truth at that frame (the fleet clock's frame ``n`` shows the world's frame
``n mod frames``, as the agents' simulated cameras do).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agents.runs import pose_rows, pose_table
from geometry import angle_difference
from scenarios.world import load_scenario

#: Line style of each share mode.
SHARE_LABELS = {"exp2-solo": "alone", "exp2a-features": "(a) feature sets", "exp2b-hints": "(b) hints"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def error_series(summary: dict, world: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Frame numbers (from the first published), position error (m), yaw error (deg) and good flags, each (K,),
    of one agent's published poses against ``world``'s truth."""
    frames, poses, good = pose_table(pose_rows(summary))
    if not len(frames):
        empty = np.zeros(0)
        return empty, empty, empty, np.zeros(0, bool)
    scenario = load_scenario(world)
    truth = np.array([scenario.target_pose(int(n) % scenario.frames) for n in frames])
    position = np.linalg.norm(poses[:, :3] - truth[:, :3], axis=1)
    yaw = np.degrees(np.abs(angle_difference(poses[:, 5], truth[:, 5])))
    return frames - frames[0], position, yaw, good


def _first_run(records: list[dict], scenario: str, world: str) -> dict | None:
    chosen = [r for r in records if r["scenario"] == scenario and r.get("world") == world and r.get("agents")]
    return min(chosen, key=lambda r: (r["variant"], r["run"])) if chosen else None


def figure_6(rows_by: dict[str, dict | None], path: Path, world: str) -> Path:
    """Fitness of the best individual over generations of the first search (paper Fig. 6); ``rows_by``:
    label -> result row (with its ``history``)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=120)
    for label, row in rows_by.items():
        if row and row["history"]:
            ax.plot(range(1, len(row["history"]) + 1), row["history"], marker="o", ms=3, label=label)
    ax.set_xlabel("generation")
    ax.set_ylabel("fitness of the best (px)")
    ax.set_title(f"Fitness of the best individual, strategy (a), {world}")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def error_over_time(records: list[dict], path: Path, world: str, vehicles: tuple[str, ...] = ("H1", "H2")) -> Path:
    """Position error per frame of each helicopter (run 0), alone and with each share mode; hollow markers where
    the frame was not marked good."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(vehicles), figsize=(6 * len(vehicles), 3.6), dpi=120, sharey=True)
    for ax, vehicle in zip(np.atleast_1d(axes), vehicles):
        for scenario, label in SHARE_LABELS.items():
            record = _first_run(records, scenario, world)
            summary = (record or {}).get("agents", {}).get(vehicle)
            if not summary:
                continue
            frames, position, _, good = error_series(summary, world)
            position = np.maximum(position, 1e-5)  # log scale: an exact pose is drawn at 10 um
            line, = ax.plot(frames, position, label=label, lw=1)
            ax.plot(frames[~good], position[~good], "o", mfc="none", ms=3, color=line.get_color())
        ax.set_yscale("log")
        ax.set_xlabel("frame (from the first published pose)")
        ax.set_title(f"{vehicle}, {world}")
        ax.grid(alpha=0.3, which="both")
    np.atleast_1d(axes)[0].set_ylabel("position error (m)")
    np.atleast_1d(axes)[0].legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def tracks_from_above(records: list[dict], path: Path, world: str, vehicles: tuple[str, ...] = ("H1", "H2")) -> Path:
    """The target's true track (x, y) and each helicopter's estimates (run 0 of each share mode), with the
    helicopters' positions: the driving world seen from above."""
    plt = _pyplot()
    scenario = load_scenario(world)
    truth = np.array([scenario.target_pose(k) for k in range(scenario.frames)])
    modes = [(s, label) for s, label in SHARE_LABELS.items() if _first_run(records, s, world)]
    fig, axes = plt.subplots(1, max(len(modes), 1), figsize=(5 * max(len(modes), 1), 4.6), dpi=120, squeeze=False)
    for ax, (scenario_name, label) in zip(axes[0], modes):
        ax.plot(truth[:, 0], truth[:, 1], "k-", lw=2, label="truth")
        record = _first_run(records, scenario_name, world)
        for vehicle in vehicles:
            _, poses, _ = pose_table(pose_rows(record["agents"].get(vehicle, {})))
            if len(poses):
                ax.plot(poses[:, 0], poses[:, 1], ".", ms=3, label=f"{vehicle} estimates")
        for vehicle in scenario.vehicles:
            position = vehicle.camera_at(0.0).world_from_camera[:3, 3]
            ax.annotate(f"{vehicle.name} ({position[0]:.0f}, {position[1]:.0f}) m", (0.02, 0.97 - 0.06 * vehicle.index),
                        xycoords="axes fraction", fontsize=7, va="top")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{label}, {world}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def bandwidth(rows: list[dict], path: Path, worlds: list[str]) -> Path:
    """Bytes/s sent by H1 per share mode (log scale), one group per world."""
    plt = _pyplot()
    modes = (("exp2-raw", "raw images", "image"), ("exp2a-features", "(a) feature sets", "features"),
             ("exp2b-hints", "(b) hints", "hint"))
    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=120)
    width = 0.8 / max(len(worlds), 1)
    for i, world in enumerate(worlds):
        values = []
        for scenario, _, topic in modes:
            row = next((r for r in rows if r["scenario"] == scenario and r["vehicle"] == "H1"
                        and r["world"] == world), None)
            values.append(row["traffic"].get(topic, {}).get("bytes_per_s", 0.0) if row else 0.0)
        bars = ax.bar(np.arange(len(modes)) + i * width, values, width, label=world)
        ax.bar_label(bars, labels=[f"{v:,.0f}" for v in values], fontsize=7)
    ax.set_xticks(np.arange(len(modes)) + width * (len(worlds) - 1) / 2, [label for _, label, _ in modes])
    ax.set_yscale("log")
    ax.set_ylabel("bytes/s sent by H1")
    ax.set_title("Bandwidth per share mode")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


__all__ = ["bandwidth", "error_over_time", "error_series", "figure_6", "tracks_from_above"]
