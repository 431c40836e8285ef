"""``evopose report``: run the paper's experiments with the fleet and write ``report.md`` and its figures.

Experiment 2 runs on two worlds: ``exp2-paper-scale`` (the paper's image scale: the Pioneer ~25 px wide; the
headline) and ``exp2`` (telephoto lenses, ~180 px), each also with the Pioneer driving (tracking, eq. 2).
Tables I and II in the paper's layout with the paper's numbers beside ours, the bandwidth of each share
mode, Fig. 6 (fitness of the best individual over generations) and the pose agreement of the two
helicopters, frame by frame; then each of the paper's qualitative findings, checked against our numbers
at each scale.
"""

from __future__ import annotations

import os
import platform
import statistics
import threading
import time
from pathlib import Path

from scenarios.fleet import load_fleet_scenario

from agents.experiments import DEFAULT_ENDPOINT, figures
from agents.experiments.paper_tables import (ANGLES, AXES, HEADER, PAPER_TABLE_I, PAPER_TABLE_II, above_paper, cell,
                                            find_row, find_variant, our_row, paper_row, table_ii)
from agents.experiments.results import agreement, frame_agreement, improves, rows
from agents.experiments.runner import run_scenario

SCENARIOS = ("exp1-airship", "exp2-solo", "exp2a-features", "exp2b-hints", "exp2-raw")
#: Experiment 2's worlds, headline first: (world, its driving variant, what to call it).
WORLDS = (("exp2-paper-scale", "exp2-paper-scale-driving", "paper scale (Pioneer ~25 px)"),
          ("exp2", "exp2-driving", "telephoto (Pioneer ~180 px)"))
#: Experiment 2 through the project's camera model (docs/camera-model.md: Bayer mosaic, noise, JPEG 4:2:0) on its
#: own renderer, with the front-end made for camera images: (world, what to call it), and that front-end.
CAMERA_WORLDS = (("exp2-paper-scale-camera", "paper scale"), ("exp2-camera", "telephoto"))
CAMERA_FEATURES = "contrast"
CAMERA_SCENARIOS = ("exp2-solo", "exp2a-features", "exp2b-hints")
#: The scenarios run with the Pioneer driving (tracking, eq. 2).
DRIVING = ("exp2a-features", "exp2b-hints")
#: Issue 13's team-size sweep (1, 2, 4, 8 UAVs on one world) and its runs: at most this many, as each run of
#: its seven variants starts up to nine processes on this 2-core machine.
TEAM_SIZE, TEAM_SIZE_RUNS = "exp2-team-size", 3

def findings(result_rows: list[dict], agree_a: dict, agree_b: dict, world: str,
             with_exp1: bool = True) -> list[tuple[str, bool, str]]:
    """The paper's qualitative findings on ``world``, each with whether our numbers show it and the numbers."""
    out = []
    plain, imu = find_variant(result_rows, "EvoPose", "ground-station"), find_variant(result_rows, "EvoPose+IMU",
                                                                                        "ground-station")
    if plain and imu and with_exp1:
        out.append(("The IMU cuts the time to a good pose (Table I)", imu["first_good_s"] < plain["first_good_s"],
                    f"{plain['first_good_s']:.3f} s -> {imu['first_good_s']:.3f} s"))
        out.append(("The IMU cuts the roll error (Table I)", imu["roll"] < plain["roll"],
                    f"{plain['roll']:.2f}° -> {imu['roll']:.2f}°"))
    h1, h2 = find_row(result_rows, "exp2-solo", "H1", world), find_row(result_rows, "exp2-solo", "H2", world)
    both = find_row(result_rows, "exp2a-features", "H1", world)
    h1h, h2h = find_row(result_rows, "exp2b-hints", "H1", world), find_row(result_rows, "exp2b-hints", "H2", world)
    if h1 and h2 and both:
        out.append(("Both cameras beat either alone (position error)", both["position"] < min(h1["position"],
                                                                                               h2["position"]),
                    f"H1 {h1['position'] * 100:.2f} cm, H2 {h2['position'] * 100:.2f} cm, "
                    f"H1+H2 {both['position'] * 100:.2f} cm"))
    if h1 and h2 and both and h1["history"] and h2["history"] and both["history"]:
        alone = 0.5 * (h1["history"][-1] + h2["history"][-1])
        out.append(("Fig. 6: the stereo fitness (eq. 4) ends below the weighted sum of the single-view fitnesses",
                    both["history"][-1] < alone,
                    f"{both['history'][-1]:.3f} px vs 0.5 x H1 + 0.5 x H2 = {alone:.3f} px"))
    if h1 and h2 and h1h and h2h:
        gain1, gain2 = h1["position"] - h1h["position"], h2["position"] - h2h["position"]
        out.append(("Hints improve each helicopter",
                    improves(h1h["position"], h1["position"]) and improves(h2h["position"], h2["position"]),
                    f"H1 {h1['position'] * 100:.2f} -> {h1h['position'] * 100:.2f} cm, "
                    f"H2 {h2['position'] * 100:.2f} -> {h2h['position'] * 100:.2f} cm"))
        out.append(("...and H2 most", gain2 > gain1, f"gain H1 {gain1 * 100:.2f} cm, H2 {gain2 * 100:.2f} cm"))
    if agree_a["frames"]:
        out.append(("In (a) the two helicopters publish the same pose (within 1 cm, 0.1°) on >= 95 % of frames",
                    agree_a["fraction"] >= 0.95,
                    f"{agree_a['agreed']} of {agree_a['frames']} frames ({agree_a['fraction']:.1%})"))
    if agree_b["frames"] and agree_a["frames"]:
        out.append(("In (b) they can differ (agree on fewer frames than in (a))",
                    agree_b["fraction"] < agree_a["fraction"],
                    f"same pose on {agree_b['fraction']:.1%} of frames in (b), {agree_a['fraction']:.1%} in (a)"))
    paper_times = {"H1": (h1, 2.3), "H2": (h2, 5.0), "H1 + H2": (both, 1.6), "H1 + hint": (h1h, 0.6),
                   "H2 + hint": (h2h, 1.3)}
    if with_exp1:
        paper_times.update({"EvoPose": (plain, 3.2), "EvoPose+IMU": (imu, 2.3)})
    ratios = {k: t / r["first_good_s"] for k, (r, t) in paper_times.items() if r and r["first_good_s"] > 0}
    if ratios:
        slowest = min(ratios, key=ratios.get)
        out.append(("Time to a good pose at least 20x shorter than the paper's, row by row", ratios[slowest] >= 20,
                    f"least gain: {slowest} {ratios[slowest]:.0f}x; "
                    + ", ".join(f"{k} {v:.0f}x" for k, v in ratios.items())))
    if h1 and h2 and both:
        ours = {"H1": h1, "H2": h2, "H1 + H2": both, "H1 + hint": h1h, "H2 + hint": h2h}
        below = all(r is None or all(r[a] < PAPER_TABLE_II[k][3 + i][0] for i, a in enumerate(AXES))
                    for k, r in ours.items())
        out.append(("Position errors below the paper's Table II at the same geometry", below,
                    "every X, Y, Z mean of every row"))
        worst = max((max(r[a] for a in ANGLES), k) for k, r in ours.items() if r is not None)
        out.append(("No row's mean angle error over 2° (no wrong basins)", worst[0] <= 2.0,
                    f"largest: {worst[1]} {worst[0]:.2f}°"))
    return out


def bandwidth_rows(result_rows: list[dict], world: str) -> list[str]:
    lines = []
    for scenario, label, topic in (("exp2-raw", "raw images", "image"), ("exp2a-features", "feature sets (a)",
                                                                          "features"),
                                   ("exp2b-hints", "hints (b)", "hint")):
        r = find_row(result_rows, scenario, "H1", world)
        if r and topic in r["traffic"]:
            t = r["traffic"][topic]
            lines.append(f"| {label} | {topic} | {t['rate_hz']:.1f} | {t['bytes_per_message']:,.0f} | "
                         f"{t['bytes_per_s']:,.0f} |")
    return lines


def run_all(*, runs: int, frames: int | None, seed: int, endpoint: str, stop: threading.Event,
            on_run=None) -> list[dict]:
    """Every experiment: Experiment 1 on its world; Experiment 2 on each of :data:`WORLDS`, also driving."""
    records: list[dict] = []
    plan = [("exp1-airship", None, runs, None)]
    for world, driving, _ in WORLDS:
        plan += [(name, world, runs, None) for name in SCENARIOS if name != "exp1-airship"]
        plan += [(name, driving, runs, None) for name in DRIVING]
    plan += [(name, world, runs, CAMERA_FEATURES) for world, _ in CAMERA_WORLDS for name in CAMERA_SCENARIOS]
    plan.append((TEAM_SIZE, None, min(runs, TEAM_SIZE_RUNS), None))
    for name, world, n, features in plan:
        if stop.is_set():
            break
        scenario = load_fleet_scenario(name, world)
        scenario = scenario if features is None else scenario.with_features(features)
        records += run_scenario(scenario, runs=n, frames=frames, seed=seed, endpoint=endpoint, stop=stop,
                                on_run=on_run, keep_going=True)
    return records


def _agreement_lines(records: list[dict], worlds: list[str]) -> list[str]:
    lines = ["| world | strategy | frames both published | same pose (1 cm, 0.1°) | both good | "
             "final poses: mean / max distance, cm |", "|---|---|---|---|---|---|"]
    for world in worlds:
        for label, scenario in (("(a) feature sets", "exp2a-features"), ("(b) hints", "exp2b-hints")):
            chosen = [r for r in records if r["scenario"] == scenario and r.get("world") == world]
            fa, ag = frame_agreement(chosen, "H1", "H2"), agreement(chosen, "H1", "H2")
            if fa["frames"]:
                lines.append(f"| {world} | {label} | {fa['frames']} | {fa['agreed']} ({fa['fraction']:.1%}) | "
                             f"{fa['both_good']} | {ag['position_mean'] * 100:.3f} / {ag['position_max'] * 100:.3f} |")
    return lines


def _tracking_lines(result_rows: list[dict]) -> list[str]:
    lines = ["| world | scenario | vehicle | good frames | position error, cm (σ) | yaw error, ° (σ) |",
             "|---|---|---|---|---|---|"]
    for _, driving, _ in WORLDS:
        for r in (r for r in result_rows if r["world"] == driving):
            lines.append(f"| {driving} | {r['scenario']} | {r['vehicle']} | {r['good_fraction']:.0%} | "
                         f"{cell(r['position'] * 100, r['position_sd'] * 100, 1)} | {cell(r['yaw'], r['yaw_sd'], 2)} |")
    return lines


def _team_size_lines(records: list[dict], result_rows: list[dict]) -> list[str]:
    """Issue 13: per team size and share mode, the UAVs' errors, agreement with H1, and per-UAV costs."""
    lines = ["| share | UAVs | frames good | H1's position error, cm | position error, cm: mean (worst UAV) | "
             "yaw error, °: mean (worst) | same pose as H1 (1 cm, 0.1°) | CPU per frame, ms (of which rendering) | "
             "sent, B/s | received, B/s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    variants = dict.fromkeys(r["variant"] for r in result_rows if r["scenario"] == TEAM_SIZE)
    for variant in variants:
        uavs = sorted((r for r in result_rows if r["scenario"] == TEAM_SIZE and r["variant"] == variant
                       and r["role"] == "uav"), key=lambda r: int(r["vehicle"].lstrip("H") or 0))
        if not uavs:
            continue
        mean = {key: statistics.fmean(r[key] for r in uavs)
                for key in ("good_fraction", "position", "yaw", "cpu_per_frame_s", "render_per_frame_s",
                            "bytes_sent_per_s", "bytes_received_per_s")}
        worst = {key: max(r[key] for r in uavs) for key in ("position", "yaw")}
        runs = [r for r in records if r["scenario"] == TEAM_SIZE and r["variant"] == variant]
        shares = [frame_agreement(runs, "H1", r["vehicle"]) for r in uavs[1:]]
        same = (f"{min(a['fraction'] for a in shares):.0%} (worst pair)" if shares else "-")
        lines.append(f"| {uavs[0]['share']} | {len(uavs)} | {mean['good_fraction']:.0%} | "
                     f"{cell(uavs[0]['position'] * 100, uavs[0]['position_sd'] * 100, 1)} | "
                     f"{mean['position'] * 100:.1f} ({worst['position'] * 100:.1f}) | "
                     f"{mean['yaw']:.2f} ({worst['yaw']:.2f}) | {same} | "
                     f"{mean['cpu_per_frame_s'] * 1e3:.0f} ({mean['render_per_frame_s'] * 1e3:.0f}) | "
                     f"{mean['bytes_sent_per_s']:,.0f} | {mean['bytes_received_per_s']:,.0f} |")
    return lines


def write_report(out: Path, *, runs: int, frames: int | None, seed: int, endpoint: str,
                 stop: threading.Event, on_run=None, photoreal: Path | None = None) -> Path:
    """Run every experiment, write ``out/report.md`` and one Fig. 6 per world; returns the report path.

    ``photoreal``: the rendered dataset of the section "Table II on a photoreal dataset" (default: the first of
    :data:`agents.experiments.photoreal.DEFAULT_DATASETS` that exists; none: the section says it was skipped).
    """
    from agents.experiments.photoreal import dataset_info, photoreal_section, resolve_dataset, run_photoreal

    dataset, dataset_source = resolve_dataset(photoreal)  # a bad --photoreal fails here, before anything runs
    out.mkdir(parents=True, exist_ok=True)
    started = time.time()
    records = run_all(runs=runs, frames=frames, seed=seed, endpoint=endpoint, stop=stop, on_run=on_run)
    photoreal_records = [] if dataset is None else run_photoreal(dataset, runs=runs, frames=frames, seed=seed,
                                                                 endpoint=endpoint, stop=stop, on_run=on_run)
    result_rows = rows(records)
    lines = ["# EvoPose Fleet: the paper's experiments, reproduced",
             "",
             f"Produced by `evopose report --runs {runs}{'' if frames is None else f' --frames {frames}'}"
             f" --seed {seed}` on {time.strftime('%Y-%m-%d', time.gmtime(started))}, "
             f"{platform.machine()} with {os.cpu_count()} cores (shared, noisy), in "
             f"{(time.time() - started) / 60:.1f} min. Every vehicle ran as its own process over Zenoh on loopback; "
             "each run used other search seeds and another world seed (image noise, IMU bias). Errors are per run the "
             "mean absolute error over the frames whose estimate is in the right basin (converged and confident; a good "
             "frame is also precise), then mean and σ over the runs. "
             "Time to a good pose: from the acquisition of the first frame to the first good estimate. Experiment 2 "
             "runs on two worlds of the same geometry: at the paper's image scale (the headline) and with telephoto "
             "lenses.",
             ""]
    for world, _, title in WORLDS:
        lines += [f"## Table II at {title}: `{world}`", "", *table_ii(result_rows, world), ""]
    lines += [f"## Table II through a camera model (`--features {CAMERA_FEATURES}`)", "",
              "The same experiments on the project's renderer with Lambert and specular shading and its camera model "
              "(auto exposure, Bayer mosaic demosaiced bilinearly, shot and read noise, 12-bit ADC, sRGB, JPEG 85 "
              "with 4:2:0 chroma; docs/camera-model.md), the marks found by their contrast on the body "
              "(`vision/blobs.py`).", ""]
    for world, title in CAMERA_WORLDS:
        above = above_paper(result_rows, world)
        lines += [f"### {title}: `{world}`", "", *table_ii(result_rows, world), "",
                  ("Every cell below the paper's." if not above else "**Above the paper's:** " + "; ".join(above)
                   + "."), ""]
    lines += photoreal_section(photoreal_records, None if dataset is None else dataset_info(dataset), dataset_source)
    lines += ["## Table I: the airship localized by the ground station (Experiment 1, `exp1-airship`)", "",
              HEADER.format(what="algorithm", u="cm")]
    for variant in ("EvoPose", "EvoPose+IMU"):
        r = find_variant(result_rows, variant, "ground-station")
        if r:
            lines.append(our_row(variant, r, 100, (2, 1), PAPER_TABLE_I[variant][6]))
        lines.append(paper_row(variant, PAPER_TABLE_I[variant]))
    airship = [r for r in result_rows if r["vehicle"] == "airship"]
    if airship:
        lines += ["", "The airship received its pose back from the station: "
                  + "; ".join(f"{r['variant']}: {r['good_fraction']:.0%} of its frames, position error "
                              f"{r['position'] * 100:.1f} cm" for r in airship) + "."]
    lines += ["", "## Bandwidth per share mode (H1's sending side)", "",
              "| world | share | topic | messages/s | bytes/message | bytes/s |", "|---|---|---|---|---|---|"]
    for world, _, _ in WORLDS:
        lines += [f"| {world} " + line for line in bandwidth_rows(result_rows, world)]
    lines += ["", "The paper: about 10 frames/s of features (tens of points, hundreds of bytes) in (a), over 100 Hz of "
              "24-byte hints in (b); raw images are the alternative it rejects for their bandwidth.",
              "", "## Pose agreement between H1 and H2, frame by frame", "",
              *_agreement_lines(records, [w for w, _, _ in WORLDS] + [d for _, d, _ in WORLDS]),
              "", "## Tracking a driving Pioneer (eq. 2): 0.5 m/s, turning at 0.2 rad/s", "",
              *_tracking_lines(result_rows), "",
              f"## Team size: 1, 2, 4 and 8 UAVs (`{TEAM_SIZE}`, world `exp2-eight`, 2 frames/s)", "",
              *_team_size_lines(records, result_rows), "",
              f"Up to {TEAM_SIZE_RUNS} runs per size. Errors over each UAV's frames in the right basin. CPU: the whole agent process "
              "(every thread) per frame, of which rendering its simulated camera, which a real vehicle does not "
              "pay. Bytes: every topic, per second of the run, per UAV (the router's and the meter's traffic "
              "aside).", "", "## Fig. 6: fitness of the best individual", ""]
    for world, _, title in WORLDS:
        fig = figures.figure_6({"H1 alone": find_row(result_rows, "exp2-solo", "H1", world),
                                "H2 alone": find_row(result_rows, "exp2-solo", "H2", world),
                                "H1 + H2 (eq. 4)": find_row(result_rows, "exp2a-features", "H1", world)},
                               out / f"fig6_{world}.png", world)
        lines += [f"![Fig. 6, {title}]({fig.name})", ""]
    lines += ["First search of run 0: fitness (eq. 4, pixels) of the best individual per generation.", "",
              "## Error over time, per helicopter", ""]
    for world, driving, title in WORLDS:
        for shown in (world, driving):
            fig = figures.error_over_time(records, out / f"error_{shown}.png", shown)
            lines += [f"![Position error per frame, {shown}]({fig.name})", ""]
    lines += ["Run 0 of each strategy: the distance between each published pose and the truth at its frame (log "
              "scale); hollow markers: frames not marked good.", "", "## The driving Pioneer from above", ""]
    for _, driving, title in WORLDS:
        fig = figures.tracks_from_above(records, out / f"tracks_{driving}.png", driving)
        lines += [f"![Tracks from above, {title}]({fig.name})", ""]
    fig = figures.bandwidth(result_rows, out / "bandwidth.png", [w for w, _, _ in WORLDS])
    lines += ["## Bandwidth per share mode, as a figure", "", f"![Bytes/s per share mode]({fig.name})", ""]
    for world, _, title in WORLDS:
        a = [r for r in records if r["scenario"] == "exp2a-features" and r.get("world") == world]
        b = [r for r in records if r["scenario"] == "exp2b-hints" and r.get("world") == world]
        lines += [f"## The paper's findings at {title}", "", "| finding | holds | numbers |", "|---|---|---|"]
        for text, holds, numbers in findings(result_rows, frame_agreement(a, "H1", "H2"),
                                             frame_agreement(b, "H1", "H2"), world, world == WORLDS[0][0]):
            lines.append(f"| {text} | {'yes' if holds else '**no**'} | {numbers} |")
        lines.append("")
    failed = [r for r in records if r.get("error")]
    if failed:
        lines += [f"**{len(failed)} of {len(records)} runs failed** and are left out of the tables:"]
        lines += [f"- {r['scenario']} on {r.get('world')} / {r['variant']} run {r['run']}: {r['error']}"
                  for r in failed]
    slow = [r for r in records if r.get("slow")]
    if slow:
        lines += ["", f"{len(slow)} runs were slow (stopped at their deadline; their frames so far are counted): "
                  + ", ".join(f"{r['scenario']} on {r.get('world')} run {r['run']}" for r in slow)]
    seconds = [r["seconds"] for r in records if r.get("seconds")]
    if seconds:
        lines += ["", f"Wall time per run (start-up margin included): median {statistics.median(seconds):.1f} s, "
                  f"longest {max(seconds):.1f} s."]
    if stop.is_set():
        lines += ["", "**Interrupted**: the tables hold only the runs that finished."]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


__all__ = ["DEFAULT_ENDPOINT", "SCENARIOS", "WORLDS", "run_all", "write_report"]
