"""Photoreal benchmark worlds: 3 geometries x 3 lightings x 2 scales, and their datasets (docs/datasets.md).

Run from the repository root::

    .venv/bin/python -m benchmarks.photoreal_worlds                     # (re)write the 18 world files
    .venv/bin/python -m benchmarks.photoreal_worlds --render --frames 5 --out datasets/photoreal
    .venv/bin/python -m benchmarks.photoreal_worlds --set husky --render --frames 4 --out datasets/photoreal-husky

The worlds (``benchmarks/worlds/photoreal/<name>.yaml``, committed) extend ``exp2-photoreal`` (the paper's scale:
robot ~25 px) and ``exp2-photoreal-telephoto`` (robot ~180 px); each keeps H1 ~30 m and H2 ~20 m from the
robot, their gimbals on it (``look_at``), the crate and the clutter:

- geometry **g1**: the shipped one (H1 from the -x side, H2 from +x, 23-25 deg elevation, robot yaw 0.6);
- **g2**: the helicopters around the robot from other sides (H1 at azimuth 75 deg, H2 at -120 deg), robot yaw -1.2;
- **g3**: lower, more oblique views (H1 at 17 deg, H2 at 15 deg elevation; azimuths 120 and -60 deg), robot yaw 2.4;

- lighting **high**: the sun 60 deg high in a clear sky; **low**: the sun 12 deg high (long shadows, a warmer
  sky), 3 W/m^2; **overcast**: no direct sun, a bright grey sky, soft shadows.

``--set husky`` writes 12 worlds of the second marked target, the Husky-like UGV of ``scenarios/models/husky.yaml``
(``benchmarks/worlds/photoreal-husky/photoreal-husky-<scale>-<geometry>-<lighting>.yaml``): the same geometries g1-g3
and the lightings high and low at both scales, extending ``exp2-photoreal-husky`` and
``exp2-photoreal-telephoto-husky`` (the Pioneer's worlds with only the target's model changed).

``--set bodies-dev`` writes the same worlds with 24 other random robots (seeds from 100): front-end rules are
chosen on them, and judged on ``bodies`` and the second robot, which they never saw.

``--set palettes`` writes 12 *training* worlds of recoloured robots at the paper's scale (the training geometries
t1-t6 under the mid and dawn suns): each world's robot has the Pioneer's shape and marks, a body paint and four mark
paints of its own (:func:`random_paints`, seeded by the world; its model file beside the world in ``models/``), so
that what is fitted at the paper's scale (the mark scorer) sees other bodies and palettes than the Pioneer's. Neither
the Pioneer's benchmark worlds nor the second robot are among them.

``--render`` renders every world (``<out>/<world name>/``, the Cycles engine) and, per scale, the g1-high world
without its target (``<out>/<scale>-absent/``, absent-target frames; for ``--set husky`` too: the same scene, its
``model.yaml`` the Husky's, so a front-end looks there for the Husky's palette). Each dataset resumes where it stopped, so an
interrupted run is continued by running the command again. A line per dataset reports its wall time.
"""

from __future__ import annotations

import argparse
import colorsys
import math
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
WORLDS = ROOT / "benchmarks" / "worlds" / "photoreal"
SCALES = {"paper": "exp2-photoreal", "telephoto": "exp2-photoreal-telephoto"}
#: H1 and H2 (range m, elevation deg, azimuth deg from the robot), robot yaw (rad); None: the shipped geometry.
GEOMETRIES = {
    "g1": None,
    "g2": {"H1": (30.0, 23.5, 75.0), "H2": (20.0, 25.0, -120.0), "yaw": -1.2},
    "g3": {"H1": (30.0, 17.0, 120.0), "H2": (20.0, 15.0, -60.0), "yaw": 2.4},
}
#: lighting block per name: sun (elevation, azimuth deg), strength, sky
LIGHTINGS = {
    "high": {"sun": (60.0, 53.0), "sun_strength": 4.0, "sky": "clear"},
    "low": {"sun": (12.0, -30.0), "sun_strength": 3.0, "sky": "clear"},
    "overcast": {"sun": (60.0, 53.0), "sun_strength": 4.0, "sky": "overcast"},
}
#: Geometries and lightings of the *training* worlds (``--set train``): other sides, heights and suns than the
#: benchmark's, so that what is fitted on them (the mark scorer, vision/mark_scorer.py) is measured on worlds
#: it never saw.
TRAIN_GEOMETRIES = {
    "t1": {"H1": (30.0, 20.0, 30.0), "H2": (20.0, 28.0, -150.0), "yaw": 0.0},
    "t2": {"H1": (30.0, 26.0, -100.0), "H2": (20.0, 19.0, 160.0), "yaw": 1.8},
    "t3": {"H1": (30.0, 21.0, 170.0), "H2": (20.0, 22.0, 20.0), "yaw": -2.4},
    "t4": {"H1": (30.0, 18.0, -45.0), "H2": (20.0, 24.0, 95.0), "yaw": 0.9},
    "t5": {"H1": (30.0, 24.0, 140.0), "H2": (20.0, 17.0, -75.0), "yaw": -0.5},
    "t6": {"H1": (30.0, 22.0, 5.0), "H2": (20.0, 21.0, -170.0), "yaw": 3.0},
}
TRAIN_LIGHTINGS = {
    "mid": {"sun": (38.0, 140.0), "sun_strength": 3.5, "sky": "clear"},
    "dawn": {"sun": (15.0, 110.0), "sun_strength": 3.0, "sky": "clear"},
    "overcast": {"sun": (60.0, 53.0), "sun_strength": 4.0, "sky": "overcast"},
}
#: The second marked target's shipped worlds per scale (``--set husky``): the Pioneer's with the Husky-like UGV.
HUSKY_SCALES = {"paper": "exp2-photoreal-husky", "telephoto": "exp2-photoreal-telephoto-husky"}
#: The recoloured training robots' folder (``--set palettes``), the model they recolour and the Pioneer's body paint.
PALETTE_WORLDS = ROOT / "benchmarks" / "worlds" / "photoreal-palettes"
PALETTE_BASE_MODEL = ROOT / "scenarios" / "models" / "pioneer.yaml"
#: The random training robots' folder (``--set bodies``: other shapes, dark parts, marks; benchmarks/random_bodies.py).
BODY_WORLDS = ROOT / "benchmarks" / "worlds" / "photoreal-bodies"
#: World sets: folder, geometries, lightings, scales.
SETS = {"benchmark": (WORLDS, GEOMETRIES, LIGHTINGS, tuple(SCALES)),
        "train": (ROOT / "benchmarks" / "worlds" / "photoreal-train", TRAIN_GEOMETRIES, TRAIN_LIGHTINGS, tuple(SCALES)),
        "husky": (ROOT / "benchmarks" / "worlds" / "photoreal-husky", GEOMETRIES,
                  {k: LIGHTINGS[k] for k in ("high", "low")}, tuple(SCALES)),
        "palettes": (PALETTE_WORLDS, TRAIN_GEOMETRIES, {k: TRAIN_LIGHTINGS[k] for k in ("mid", "dawn")}, ("paper",)),
        "bodies": (BODY_WORLDS, TRAIN_GEOMETRIES, {k: TRAIN_LIGHTINGS[k] for k in ("mid", "dawn")}, tuple(SCALES)),
        "bodies-dev": (ROOT / "benchmarks" / "worlds" / "photoreal-bodies-dev", TRAIN_GEOMETRIES,
                       {k: TRAIN_LIGHTINGS[k] for k in ("mid", "dawn")}, tuple(SCALES))}
#: Per set: the shipped world each scale extends and the worlds' name prefix (default: SCALES, "photoreal").
SET_BASES = {"husky": (HUSKY_SCALES, "photoreal-husky"), "palettes": (SCALES, "photoreal-palettes"),
             "bodies": (SCALES, "photoreal-bodies"), "bodies-dev": (SCALES, "photoreal-bodies-dev")}
#: The sets whose worlds each carry a model of their own (written beside them in ``models/``).
MODEL_SETS = ("palettes", "bodies", "bodies-dev")
#: Per set of random robots, the seed of its first robot (:func:`benchmarks.random_bodies.random_body_model`): the
#: development robots (``--set bodies-dev``), on which front-end rules are chosen, are other robots than the ``bodies``
#: that fit the scorers and judge those rules.
MODEL_SEEDS = {"bodies-dev": 100}
#: The sets whose ``--render`` adds, per scale, the g1-high world without its target.
ABSENT_SETS = ("benchmark", "husky")
#: The gimbals' aim (the robot's centre).
LOOK_AT = [0.0, 0.0, 0.12]


def _direction(elevation_deg: float, azimuth_deg: float) -> list[float]:
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return [round(math.cos(e) * math.cos(a), 4), round(math.cos(e) * math.sin(a), 4), round(math.sin(e), 4)]


def _vehicle(name: str, rng_m: float, elevation_deg: float, azimuth_deg: float) -> dict:
    d = _direction(elevation_deg, azimuth_deg)
    x, y, z = (round(rng_m * c + l, 3) for c, l in zip(d, LOOK_AT))
    yaw = round(math.atan2(-y, -x), 4)  # the helicopter faces the robot
    return {"name": name, "trajectory": {"start": {"x": x, "y": y, "z": z, "yaw": yaw}}}


def _bgr(hue: float, saturation: float, value: float) -> list[int]:
    r, g, b = colorsys.hsv_to_rgb(hue % 1.0, saturation, value)
    return [int(round(255 * b)), int(round(255 * g)), int(round(255 * r))]


def random_paints(seed: int) -> tuple[list[int], list[list[int]]]:
    """A body paint and four mark paints (BGR), seeded: the body any hue, saturation 0.45-0.9, value 0.45-0.95; the
    marks' hues drawn until each lies at least 45 deg from the body's and from one another, except that a draw too
    near is kept one time in fifty (so some robots carry two near paints, harder to tell apart: of the 12 worlds'
    robots, t2-dawn's come 9 deg and t4-mid's 28 deg apart); saturation 0.55-1, value 0.55-1; one mark paint black
    or white in a quarter of the robots (labs mark with those too)."""
    rng = np.random.default_rng([32, seed])
    body_hue = float(rng.uniform())
    body = _bgr(body_hue, float(rng.uniform(0.45, 0.9)), float(rng.uniform(0.45, 0.95)))
    hues: list[float] = []
    while len(hues) < 4:
        h = float(rng.uniform())
        if all(min(abs(h - o) % 1.0, 1 - abs(h - o) % 1.0) >= 45 / 360 for o in [body_hue, *hues]):
            hues.append(h)
        elif rng.uniform() < 0.02:   # now and then two near paints (see above)
            hues.append(h)
    marks = [_bgr(h, float(rng.uniform(0.55, 1.0)), float(rng.uniform(0.55, 1.0))) for h in hues]
    if rng.uniform() < 0.25:
        marks[int(rng.integers(4))] = [30, 30, 30] if rng.uniform() < 0.5 else [235, 235, 235]
    return body, marks


def recoloured_model(seed: int) -> dict:
    """The Pioneer's model file (shape, parts, marks) with :func:`random_paints` ``seed``'s body and mark paints
    (marks named ``paint0``-``paint3`` in the Pioneer's colour order)."""
    doc = yaml.safe_load(PALETTE_BASE_MODEL.read_text(encoding="utf-8"))
    body, marks = random_paints(seed)
    names = {old: f"paint{i}" for i, old in enumerate(doc["colours"])}
    old_body = doc["parts"][0]["colour"]
    doc["name"] = f"recoloured-{seed}"
    doc["description"] = f"the Pioneer-2 DX's shape and marks recoloured (benchmarks/photoreal_worlds.py, seed {seed})"
    doc["colours"] = {names[old]: colour for old, colour in zip(doc["colours"], marks)}
    for part in doc["parts"]:
        if part["colour"] == old_body:
            part["colour"] = body
    for mark in doc["marks"]:
        mark["colour"] = names[mark["colour"]]
    return doc


def world_document(scale: str, geometry: str, lighting: str, world_set: str = "benchmark") -> dict:
    """The world file of one combination (a mapping that ``extends`` the scale's shipped world)."""
    _, geometries, lightings, _ = SETS[world_set]
    bases, prefix = SET_BASES.get(world_set, (SCALES, "photoreal"))
    name = f"{prefix}-{scale}-{geometry}-{lighting}"
    light = lightings[lighting]
    doc: dict = {"extends": bases[scale], "name": name,
                 "description": f"{bases[scale]}: geometry {geometry}, lighting {lighting} (benchmarks/photoreal_worlds.py)",
                 "render": {"lighting": {"sun": _direction(*light["sun"]), "sun_strength": light["sun_strength"],
                                         "sky": light["sky"], "sky_strength": 1.0}}}
    g = geometries[geometry]
    if g is not None:
        doc["target"] = {"trajectory": {"start": {"yaw": g["yaw"]}}}
        doc["vehicles"] = [_vehicle(v, *g[v]) for v in ("H1", "H2")]
    if world_set in MODEL_SETS:
        doc.setdefault("target", {})["model"] = f"models/{name}.yaml"
    return doc


def write_worlds(world_set: str = "benchmark") -> list[Path]:
    """Write the world files of ``world_set`` (the benchmark's 18, the training set's 18, the Husky's 12); their
    paths."""
    folder, geometries, lightings, scales = SETS[world_set]
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for scale in scales:
        for geometry in geometries:
            for lighting in lightings:
                doc = world_document(scale, geometry, lighting, world_set)
                path = folder / f"{doc['name']}.yaml"
                header = "# Generated by benchmarks/photoreal_worlds.py: edit that, not this.\n"
                if world_set in MODEL_SETS:
                    from .random_bodies import random_body_model   # it draws its paints with random_paints
                    made = recoloured_model if world_set == "palettes" else random_body_model
                    model = folder / doc["target"]["model"]
                    model.parent.mkdir(parents=True, exist_ok=True)
                    seed = MODEL_SEEDS.get(world_set, 0) + len(paths)
                    model.write_text(header + yaml.safe_dump(made(seed), sort_keys=False, width=120,
                                                             default_flow_style=None), encoding="utf-8")
                path.write_text(header + yaml.safe_dump(doc, sort_keys=False, width=120, default_flow_style=None), encoding="utf-8")
                paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--render", action="store_true", help="render every world's dataset (Cycles)")
    parser.add_argument("--frames", type=int, default=5, help="frames per camera")
    parser.add_argument("--samples", type=int, default=24, help="Cycles samples per pixel")
    parser.add_argument("--out", type=Path, default=ROOT / "datasets" / "photoreal", help="datasets' folder")
    parser.add_argument("--only", default="", help="render only the worlds whose name contains this")
    parser.add_argument("--set", dest="world_set", choices=tuple(SETS), default="benchmark",
                        help="the benchmark's worlds, the training worlds (other geometries and suns), or the second "
                             "marked target's (husky: the Husky-like UGV, high and low sun), or recoloured training "
                             "robots (palettes), or random training robots (bodies), or other random robots to "
                             "develop rules on (bodies-dev)")
    args = parser.parse_args(argv)
    paths = write_worlds(args.world_set)
    folder, _, _, scales = SETS[args.world_set]
    print(f"{len(paths)} worlds in {folder.relative_to(ROOT)}", flush=True)
    if not args.render:
        return 0
    from agents.tools.render_dataset import render_dataset

    jobs = [(p.stem, p, True) for p in paths]
    if args.world_set in ABSENT_SETS:
        prefix = SET_BASES.get(args.world_set, (SCALES, "photoreal"))[1]
        jobs += [(f"{scale}-absent", folder / f"{prefix}-{scale}-g1-high.yaml", False) for scale in scales]
    total = time.perf_counter()
    for name, world, target in jobs:
        if args.only not in name:
            continue
        start = time.perf_counter()
        summary = render_dataset(world, args.out / name, engine="cycles", frames=args.frames, samples=args.samples,
                                 target=target)
        per = summary["seconds_per_image"]
        print(f"{name}: {summary['complete_frames']}/{summary['frames']} frames x {len(summary['cameras'])} cameras, "
              f"{summary['images_rendered']} rendered" + (f" at {per:.1f} s each" if per else "")
              + f", wall {time.perf_counter() - start:.0f} s", flush=True)
    print(f"all: wall {time.perf_counter() - total:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
