"""The report's "Table II on a photoreal dataset": Experiment 2 on images the fleet did not draw.

``evopose report --photoreal DIR`` runs exp2-solo, exp2a-features and exp2b-hints on a rendered dataset
(docs/datasets.md; every camera vehicle plays its camera's folder, ``evopose scenario run NAME --dataset DIR``) and
writes the Table II rows beside the paper's, in the layout of the report's other Table II, then checks the paper's
findings on them: H1 + H2 more precise than either alone, H1 + H2 faster to the first good pose, both helicopters
publishing the same pose with feature sets, hints improving H2. Without ``--photoreal`` the dataset is the first of
:data:`DEFAULT_DATASETS` that exists; with none the section says it was skipped and why.
"""

from __future__ import annotations

import math
import threading
from pathlib import Path

from agents.experiments.paper_tables import table_ii
from agents.experiments.results import frame_agreement, improves, rows
from agents.experiments.runner import dataset_scenario, run_scenario

#: The project's root: the default datasets are relative to it.
ROOT = Path(__file__).resolve().parents[2]
#: Where the section's dataset is looked for, first found: one rendered for the report (``make photoreal``, then
#: ``evopose render exp2-photoreal --out datasets/photoreal-report``), then the small one committed for the tests.
DEFAULT_DATASETS = (Path("datasets/photoreal-report"), Path("tests/data/photoreal/paper"))
#: Experiment 2's fleet scenarios the section runs.
SCENARIOS = ("exp2-solo", "exp2a-features", "exp2b-hints")
#: The camera vehicles' feature front-end on a dataset's images: by contrast, with the body as context
#: (vision.blobs), not the preset hue bands made for the project's own flat-coloured drawings.
FEATURES = "contrast"
#: Feature sets: "the same pose" on at least this share of the frames both published (as the report's other check).
SAME_POSE_SHARE = 0.95


def check_dataset(path: Path) -> None:
    """Raise (one line) unless every scenario of the section can run on ``path``: the dataset reads, and each camera
    vehicle of :data:`SCENARIOS` has its folder in it."""
    for name in SCENARIOS:
        dataset_scenario(name, path)


def resolve_dataset(given: Path | None) -> tuple[Path | None, str]:
    """The dataset the section runs on, and the sentence saying where it came from (or why there is none).

    An explicit ``given`` is checked before any experiment runs (a bad one raises ``WorldError``: one line, exit 2);
    of the defaults, the first that exists is taken, and skipped with the reason when it is not usable.
    """
    from scenarios.errors import WorldError

    if given is not None:
        check_dataset(Path(given))
        return Path(given), f"`--photoreal {given}`"
    for candidate in DEFAULT_DATASETS:
        path = candidate if candidate.is_absolute() else ROOT / candidate
        if (path / "manifest.yaml").is_file():
            try:
                check_dataset(path)
            except WorldError as err:
                return None, f"the default `{candidate}` is not a usable dataset: {err}"
            return path, f"the default `{candidate}`"
    return None, ("no dataset: neither " + " nor ".join(f"`{p}`" for p in DEFAULT_DATASETS) + " exists. Render one "
                  "(`make photoreal`, then `evopose render exp2-photoreal --out datasets/photoreal-report`) or give "
                  "`evopose report --photoreal DIR`")


def dataset_info(path: Path) -> dict:
    """What the section's heading says about the dataset: world, engine and its settings, frames, fps, cameras."""
    from scenarios.dataset import open_dataset

    data = open_dataset(path)
    engine = data.manifest.engine.model_dump(mode="json")
    return {"path": str(path), "world": data.manifest.world, "engine": engine, "frames": data.frames,
            "fps": data.fps, "cameras": list(data.cameras)}


def run_photoreal(dataset: Path, *, runs: int, frames: int | None, seed: int, endpoint: str, stop: threading.Event,
                  on_run=None) -> list[dict]:
    """Every run of :data:`SCENARIOS` on ``dataset`` (at most its frames); a failed run is recorded, not raised."""
    records: list[dict] = []
    for name in SCENARIOS:
        if stop.is_set():
            break
        scenario, dataset_frames = dataset_scenario(name, dataset)
        records += run_scenario(scenario.with_features(FEATURES), runs=runs,
                                frames=min(frames or dataset_frames, dataset_frames), seed=seed,
                                endpoint=endpoint, stop=stop, on_run=on_run, keep_going=True, dataset=dataset)
    return records


def _value(row: dict | None, key: str) -> float:
    """``row[key]``; a vehicle that never had a good pose has no error and no time: +inf, worse than any."""
    value = None if row is None else row[key]
    return math.inf if value is None or math.isnan(value) else value


def photoreal_findings(result_rows: list[dict], records: list[dict], world: str) -> list[tuple[str, str, str]]:
    """The paper's findings on the dataset: ``(finding, "holds" | "does not hold" | "not measured", numbers)``.

    "Not measured" when a run the finding compares is missing; a helicopter that never had a good pose counts as
    worse than any error or time (and a finding whose better side never had one does not hold); "better" is by at
    least :data:`agents.experiments.results.MIN_GAIN`."""
    def find(scenario: str, vehicle: str) -> dict | None:
        return next((r for r in result_rows if r["scenario"] == scenario and r["vehicle"] == vehicle
                     and r["world"] == world), None)

    def verdict(rows_needed: tuple, better: float, than: float) -> str:
        if any(r is None for r in rows_needed):
            return "not measured"
        return "holds" if improves(better, than) else "does not hold"

    def cm(r: dict | None) -> str:
        return "not run" if r is None else ("no good pose" if math.isinf(_value(r, "position")) else
                                            f"{r['position'] * 100:.2f} cm")

    def s(r: dict | None) -> str:
        return "not run" if r is None else ("no good pose" if math.isinf(_value(r, "first_good_s")) else
                                            f"{r['first_good_s']:.3f} s")

    h1, h2, both = find("exp2-solo", "H1"), find("exp2-solo", "H2"), find("exp2a-features", "H1")
    h2h = find("exp2b-hints", "H2")
    out = [("H1 + H2 more precise than either alone (position error)",
            verdict((h1, h2, both), _value(both, "position"), min(_value(h1, "position"), _value(h2, "position"))),
            f"H1 {cm(h1)}, H2 {cm(h2)}, H1 + H2 {cm(both)}"),
           ("H1 + H2 faster to the first good pose than either alone",
            verdict((h1, h2, both), _value(both, "first_good_s"),
                    min(_value(h1, "first_good_s"), _value(h2, "first_good_s"))),
            f"H1 {s(h1)}, H2 {s(h2)}, H1 + H2 {s(both)}")]
    a = frame_agreement([r for r in records if r["scenario"] == "exp2a-features" and r.get("world") == world],
                        "H1", "H2")
    out.append((f"With feature sets both helicopters publish the same pose (within 1 cm and 0.1° on >= "
                f"{SAME_POSE_SHARE:.0%} of frames)",
                "not measured" if not a["frames"] else ("holds" if a["fraction"] >= SAME_POSE_SHARE
                                                        else "does not hold"),
                f"{a['agreed']} of {a['frames']} frames ({a['fraction']:.1%})" if a["frames"] else "no frame"))
    change = _value(h2h, "position") - _value(h2, "position")
    out.append(("Hints improve H2 (position error)",
                verdict((h2, h2h), _value(h2h, "position"), _value(h2, "position")),
                f"H2 alone {cm(h2)}, H2 + hint {cm(h2h)}" + (f" ({change * 100:+.3f} cm)" if math.isfinite(change)
                                                               else "")))
    return out


def photoreal_section(records: list[dict], info: dict | None, source: str) -> list[str]:
    """The report's section: the Table II rows on the dataset beside the paper's, and the findings checked; or,
    with no dataset (``info`` None), that the section was skipped and why (``source``)."""
    lines = ["## Table II on a photoreal dataset", ""]
    if info is None:
        return lines + [f"Skipped: {source}.", ""]
    engine = info["engine"]
    settings = ", ".join(f"{k} {v}" for k, v in engine.items() if k != "name")
    done = [r for r in records if not r.get("error")]
    lines += [f"Dataset `{info['path']}` ({source}): world `{info['world']}` rendered by {engine['name']}"
              + (f" ({settings})" if settings else "") + f", {info['frames']} frames at {info['fps']:g} fps per "
              f"camera ({', '.join(info['cameras'])}). Every camera vehicle played its camera's images "
              f"(`evopose scenario run NAME --dataset DIR --features {FEATURES}`) with each frame's camera "
              f"pose from the dataset; errors against the dataset's truth. {len(done)} runs"
              + (f", {len(records) - len(done)} failed" if len(records) > len(done) else "") + ".", ""]
    result_rows = rows(done)
    lines += table_ii(result_rows, info["world"])
    lines += ["", "| the paper's finding | on this dataset | numbers |", "|---|---|---|"]
    for text, verdict, numbers in photoreal_findings(result_rows, done, info["world"]):
        shown = verdict if verdict == "holds" else f"**{verdict}**"
        lines.append(f"| {text} | {shown} | {numbers} |")
    failed = [r for r in records if r.get("error")]
    if failed:
        lines += [""] + [f"- failed: {r['scenario']} / {r['variant']} run {r['run']}: {r['error']}" for r in failed]
    return lines + [""]


__all__ = ["DEFAULT_DATASETS", "SCENARIOS", "dataset_info", "photoreal_findings", "photoreal_section",
           "resolve_dataset", "run_photoreal"]
