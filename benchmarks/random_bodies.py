"""Random marked robots for training: other bodies than the Pioneer's (docs/datasets.md, "Rendering").

The mark scorer (vision/mark_scorer.py) learns which contrast spots on a robot's paint are its marks. Trained on the
Pioneer's body alone (recoloured or not, :func:`benchmarks.photoreal_worlds.recoloured_model`), it never meets what
other robots carry beside their paint: a dark payload plate, bumpers, wheels outside the body, whose corners and
edges make spots of their own. :func:`random_body_model` draws a robot the way a lab builds one: a painted box of
any proportions, 0.4-1.0 m long, on or between dark wheels, with or without dark bumpers and a top plate, marked
on the faces a helicopter sees (top, ends, sides) where no dark part covers them, in :func:`random_paints`' paints.
Seeded: the same seed gives the same robot.
"""

from __future__ import annotations

import numpy as np

from .photoreal_worlds import random_paints

#: Dark parts' paint (BGR grey levels) and roughness range.
DARK_GREYS, DARK_ROUGHNESS = (22, 60), (0.4, 0.9)
#: A mark keeps this many radii from a face's edge and from a dark part's footprint.
EDGE_RADII = 1.6
#: Least marks on a robot (a lab marks enough for a pose from any side).
MIN_MARKS = 8


def _grey(rng: np.random.Generator) -> list[int]:
    g = int(rng.integers(*DARK_GREYS))
    return [g, g, g]


def _spots(rng: np.random.Generator, count: int, half_u: float, half_v: float, keep_out: list[tuple],
           clearance: float) -> list[tuple[float, float]]:
    """Up to ``count`` points (u, v) on a face of half sizes ``half_u``, ``half_v``, ``clearance`` from its edges,
    from each other (two clearances) and from the rectangles ``keep_out`` ((u0, u1, v0, v1), face coordinates)."""
    out: list[tuple[float, float]] = []
    lo_u, lo_v = half_u - clearance, half_v - clearance
    if lo_u <= 0 or lo_v <= 0:
        return out
    for _ in range(60 * count):
        if len(out) >= count:
            break
        u, v = float(rng.uniform(-lo_u, lo_u)), float(rng.uniform(-lo_v, lo_v))
        if any(u0 - clearance < u < u1 + clearance and v0 - clearance < v < v1 + clearance
               for u0, u1, v0, v1 in keep_out):
            continue
        if all(np.hypot(u - a, v - b) >= 2 * clearance for a, b in out):
            out.append((u, v))
    return out


def random_body_model(seed: int) -> dict:
    """A model file (a mapping, :mod:`scenarios.target`'s schema) of a random marked robot, ``seed``'s."""
    rng = np.random.default_rng([35, seed])
    body_paint, mark_paints = random_paints(1000 + seed)
    length = float(rng.uniform(0.4, 1.0))
    width = float(rng.uniform(0.55, 0.8)) * length
    height = float(rng.uniform(0.18, 0.4))
    wheels = rng.uniform() < 0.7
    wheel_r = float(rng.uniform(0.25, 0.45)) * height if wheels else 0.0
    lift = float(rng.uniform(0.3, 0.6)) * wheel_r if wheels else 0.0   # the body's underside above the ground
    z0, z1 = lift, lift + height
    radius = float(rng.uniform(0.025, 0.04))
    parts: list[dict] = [{"box": {"centre": [0.0, 0.0, round((z0 + z1) / 2, 4)],
                                  "size": [round(length, 4), round(width, 4), round(height, 4)]},
                          "colour": body_paint, "roughness": round(float(rng.uniform(0.3, 0.6)), 3)}]
    top_out: list[tuple] = []
    end_out: list[tuple] = []
    side_out: list[tuple] = []
    if rng.uniform() < 0.6:   # a dark plate on the top
        pl, pw = float(rng.uniform(0.3, 0.6)) * length, float(rng.uniform(0.4, 0.8)) * width
        px = float(rng.uniform(-0.2, 0.2)) * length
        parts.append({"box": {"centre": [round(px, 4), 0.0, round(z1 + 0.005, 4)], "size": [round(pl, 4), round(pw, 4), 0.01]},
                      "colour": _grey(rng), "roughness": round(float(rng.uniform(*DARK_ROUGHNESS)), 3)})
        top_out.append((px - pl / 2, px + pl / 2, -pw / 2, pw / 2))
    if rng.uniform() < 0.5:   # dark bumpers at both ends, a little wider than the body
        t, bh = float(rng.uniform(0.04, 0.09)), float(rng.uniform(0.2, 0.35)) * height
        bz = z0 + float(rng.uniform(0.1, 0.3)) * height + bh / 2
        for sign in (1.0, -1.0):
            parts.append({"box": {"centre": [round(sign * (length + t) / 2, 4), 0.0, round(bz, 4)],
                                  "size": [round(t, 4), round(width * float(rng.uniform(1.0, 1.25)), 4), round(bh, 4)]},
                          "colour": _grey(rng), "roughness": round(float(rng.uniform(*DARK_ROUGHNESS)), 3)})
        end_out.append((-width, width, bz - bh / 2 - (z0 + z1) / 2, bz + bh / 2 - (z0 + z1) / 2))
    if wheels:   # four dark wheels outside the body
        ww, wx = float(rng.uniform(0.05, 0.12)), float(rng.uniform(0.25, 0.35)) * length
        grey, rough = _grey(rng), round(float(rng.uniform(*DARK_ROUGHNESS)), 3)
        for sx in (1.0, -1.0):
            for sy in (1.0, -1.0):
                parts.append({"ellipsoid": {"centre": [round(sx * wx, 4), round(sy * (width + ww) / 2, 4), round(wheel_r, 4)],
                                            "semi_axes": [round(wheel_r, 4), round(ww / 2, 4), round(wheel_r, 4)]},
                              "colour": grey, "roughness": rough})
            # the wheel's disc, seen from the side, covers the side face's lower part around x = +-wx
            side_out.append((sx * wx - wheel_r, sx * wx + wheel_r, -height, 2 * wheel_r - lift - height / 2))
    names = [f"paint{i}" for i in range(4)]
    marks: list[dict] = []
    faces = [  # (normal, count range, half sizes, keep-outs, to model coordinates)
        ([0.0, 0.0, 1.0], (4, 9), length / 2, width / 2, top_out, lambda u, v: [u, v, z1]),
        ([1.0, 0.0, 0.0], (2, 5), width / 2, height / 2, end_out, lambda u, v: [length / 2, u, (z0 + z1) / 2 + v]),
        ([-1.0, 0.0, 0.0], (2, 5), width / 2, height / 2, end_out, lambda u, v: [-length / 2, u, (z0 + z1) / 2 + v]),
        ([0.0, 1.0, 0.0], (2, 5), length / 2, height / 2, side_out, lambda u, v: [u, width / 2, (z0 + z1) / 2 + v]),
        ([0.0, -1.0, 0.0], (2, 5), length / 2, height / 2, side_out, lambda u, v: [u, -width / 2, (z0 + z1) / 2 + v]),
    ]
    largest = radius
    for shrink in (1.0, 0.8, 0.65):   # too few marks for a pose (a small robot, a large plate): smaller marks
        marks, radius = [], largest * shrink
        clearance = EDGE_RADII * radius
        for normal, (lo, hi), half_u, half_v, keep_out, at in faces:
            for u, v in _spots(rng, int(rng.integers(lo, hi)), half_u, half_v, keep_out, clearance):
                marks.append({"position": [round(c, 4) for c in at(u, v)], "normal": normal,
                              "colour": names[len(marks) % 4]})
        if len(marks) >= MIN_MARKS:
            break
    order = rng.permutation(4)   # which paint the cycle starts on, face by face, varies with the seed
    for mark in marks:
        mark["colour"] = names[int(order[names.index(mark["colour"])])]
    return {"name": f"random-body-{seed}",
            "description": f"a random marked robot (benchmarks/random_bodies.py, seed {seed}): {length:.2f} x "
                           f"{width:.2f} x {height:.2f} m" + (", wheels" if wheels else ""),
            "mark_radius": round(radius, 4),
            "colours": dict(zip(names, mark_paints)),
            "parts": parts, "marks": marks}


__all__ = ["random_body_model"]
