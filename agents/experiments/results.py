"""From the agents' run summaries to the paper's tables: errors over runs, time to a good pose, bandwidth.

Per run and estimating vehicle the error is the mean absolute error over the frames with a good
(converged) estimate; the table gives its mean over the runs and, like the paper's Tables I and II, the
standard deviation over the runs (σ). Angles in degrees, positions in metres (Table I: centimetres).
"""

from __future__ import annotations

import statistics

import numpy as np

PARAMS = ("roll", "pitch", "yaw", "x", "y", "z")


def _mean_sd(values: list[float]) -> tuple[float, float]:
    values = [v for v in values if v is not None]
    if not values:
        return float("nan"), float("nan")
    return statistics.fmean(values), (statistics.pstdev(values) if len(values) > 1 else 0.0)


def estimating(summary: dict | None) -> bool:
    """Whether an agent summary is of a vehicle that estimates (a camera vehicle, or the airship receiving
    its pose)."""
    return bool(summary) and summary.get("role") in ("uav", "ground-station", "airship")


def rows(records: list[dict]) -> list[dict]:
    """One row per (variant, estimating vehicle): mean and σ over runs of each error, times, rates."""
    grouped: dict[tuple[str, str, str], list[dict]] = {}
    for record in records:
        for vehicle, summary in record["agents"].items():
            if estimating(summary):
                grouped.setdefault((record["scenario"], record["variant"], vehicle), []).append(summary)
    out = []
    for (scenario, variant, vehicle), summaries in grouped.items():
        row = {"scenario": scenario, "variant": variant, "vehicle": vehicle, "role": summaries[0]["role"],
               "share": summaries[0]["share"], "runs": len(summaries)}
        for name in PARAMS:
            row[name], row[f"{name}_sd"] = _mean_sd([s.get(f"error_{name}") for s in summaries])
        row["position"], row["position_sd"] = _mean_sd([s.get("error_position") for s in summaries])
        row["first_good_s"], row["first_good_sd"] = _mean_sd([s.get("first_good_s") for s in summaries])
        row["good_fraction"] = sum(s["good"] for s in summaries) / max(sum(s["frames"] for s in summaries), 1)
        row["multi_view_fraction"] = (sum(s.get("multi_view_frames", 0) for s in summaries)
                                      / max(sum(s["estimates"] for s in summaries), 1))
        row["history"] = next((s["first_history"] for s in summaries if s.get("first_history")), [])
        row["traffic"] = traffic_rates(summaries)
        out.append(row)
    return out


def traffic_rates(summaries: list[dict]) -> dict[str, dict]:
    """Per topic sent by the vehicle: messages/s, bytes per message, bytes/s (averaged over runs)."""
    per_topic: dict[str, list[tuple[float, float]]] = {}
    for s in summaries:
        seconds = s["frames"] / s["fps"] if s.get("fps") else 0.0
        if seconds <= 0:
            continue
        for topic, count in s["traffic"]["sent"].items():
            if topic == "stats" or not count:
                continue
            per_topic.setdefault(topic, []).append((count / seconds, s["traffic"]["bytes_sent"][topic] / count))
    return {topic: {"rate_hz": statistics.fmean(r for r, _ in v),
                    "bytes_per_message": statistics.fmean(b for _, b in v),
                    "bytes_per_s": statistics.fmean(r * b for r, b in v)} for topic, v in per_topic.items()}


def agreement(records: list[dict], a: str, b: str) -> dict:
    """Distance between the final poses of vehicles ``a`` and ``b`` over runs: position (m), angles (deg)."""
    position, angle = [], []
    for record in records:
        sa, sb = record["agents"].get(a), record["agents"].get(b)
        if not (sa and sb and sa.get("last_pose") and sb.get("last_pose")):
            continue
        pa, pb = np.array(sa["last_pose"]), np.array(sb["last_pose"])
        position.append(float(np.linalg.norm(pa[:3] - pb[:3])))
        d = (pa[3:] - pb[3:] + np.pi) % (2 * np.pi) - np.pi
        angle.append(float(np.degrees(np.max(np.abs(d)))))
    return {"runs": len(position), "position_mean": _mean_sd(position)[0],
            "position_max": max(position, default=float("nan")), "angle_max": max(angle, default=float("nan"))}
