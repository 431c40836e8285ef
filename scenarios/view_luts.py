"""Blender's view transforms as 3D LUTs: the camera model's ``tone: blender-*`` (docs/camera-model.md, "Looks").

``view_luts.npz`` (beside this module) holds one LUT per view, baked from Blender 4.5 by
``scenarios/photoreal/bake_view_luts.py``: (N, N, N, 3) uint16 display-referred (sRGB-encoded) codes, indexed
``[b, g, r]`` by the grid's scene-linear ``levels`` (0, then log2-spaced, half a stop apart, 1.0 a node), holding
B, G, R. :func:`apply_view_lut` interpolates trilinearly in the grid's log2 domain; :func:`view_transform` takes
sensor levels (1.0 = saturation) as Blender's scene-linear values and gives 8-bit BGR; :func:`view_transform_codes`
does the same for raw ADC codes, looking the grid coordinates up per code (fast).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

#: Blender's view transforms (Blender 4.5, display sRGB) baked as 3D LUTs by scenarios/photoreal/bake_view_luts.py.
VIEW_LUTS_FILE = Path(__file__).with_name("view_luts.npz")
#: The views baked (transform / look, as the bake script names them): the camera model's Blender tones.
VIEW_TONES = ("blender-standard", "blender-agx", "blender-agx-punchy", "blender-filmic",
              "blender-filmic-high-contrast", "blender-khronos-pbr-neutral")


@lru_cache(maxsize=8)
def view_lut(tone: str) -> np.ndarray:
    """The 3D LUT of a Blender view transform: float32 (N, N, N, 3), indexed [b, g, r] by the grid's nodes
    (:func:`view_grid`), holding the display-referred (sRGB-encoded) B, G, R in 0-1."""
    if tone not in VIEW_TONES:
        raise ValueError(f"not a Blender view transform: {tone!r} (expected one of {', '.join(VIEW_TONES)})")
    with np.load(VIEW_LUTS_FILE) as luts:
        lut = luts[f"lut_{tone}"].astype(np.float32) / np.float32(65535)
    lut.setflags(write=False)
    return lut


@lru_cache(maxsize=1)
def view_grid() -> tuple[np.ndarray, float]:
    """The LUTs' grid per channel (0, then log2-spaced levels; float64) and its spacing in stops."""
    with np.load(VIEW_LUTS_FILE) as luts:
        nodes = luts["levels"].astype(np.float64)
    nodes.setflags(write=False)
    return nodes, float(np.log2(nodes[2] / nodes[1]))


def _lut_coordinate(level: np.ndarray) -> np.ndarray:
    """Scene-linear levels -> the grid's fractional index: log2-spaced nodes from node 1 on, linear between
    0 (node 0) and node 1; clamped to the grid."""
    nodes, step = view_grid()
    first = np.float32(nodes[1])
    x = np.maximum(np.asarray(level, np.float32), 0)
    with np.errstate(divide="ignore"):
        log = np.log2(np.maximum(x, first) / first) / np.float32(step) + 1
    coord = np.where(x < first, x / first, log)
    return np.clip(coord, 0, len(nodes) - 1).astype(np.float32)


def _split(coord: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Fractional grid indices -> the lower node (at most n - 2) and the fraction towards the next (0-1)."""
    i0 = np.minimum(coord.astype(np.int32), n - 2)
    return i0, (coord - i0).astype(np.float32)


def _trilinear(lut: np.ndarray, i0: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``lut`` (N, N, N, 3) interpolated at lower nodes ``i0`` and fractions ``f`` ((P, 3) each, [b, g, r])."""
    n = lut.shape[0]
    flat = lut.reshape(-1, 3)
    base = (i0[:, 0] * n + i0[:, 1]) * n + i0[:, 2]
    fb, fg, fr = f[:, 0:1], f[:, 1:2], f[:, 2:3]

    def lerp_r(offset: int) -> np.ndarray:
        a = np.take(flat, base + offset, axis=0)
        a += fr * (np.take(flat, base + (offset + 1), axis=0) - a)
        return a

    g0 = lerp_r(0)
    g0 += fg * (lerp_r(n) - g0)
    g1 = lerp_r(n * n)
    g1 += fg * (lerp_r(n * n + n) - g1)
    g0 += fb * (g1 - g0)
    return g0


def apply_view_lut(level: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """Trilinear interpolation of ``lut`` (N, N, N, 3, [b, g, r]) at scene-linear BGR ``level`` (..., 3) in
    the grid's log2 domain (linear between the nodes 0 and the first level): the display-referred values (..., 3),
    float32 0-1."""
    level = np.asarray(level, np.float32)
    i0, f = _split(_lut_coordinate(level.reshape(-1, 3)), lut.shape[0])
    return _trilinear(lut, i0, f).reshape(level.shape)


@lru_cache(maxsize=4)
def _code_coordinates(bit_depth: int) -> tuple[np.ndarray, np.ndarray]:
    """Per raw code (level = code / top), the grid's lower node and fraction: a table lookup instead of a log."""
    codes = np.arange(1 << bit_depth, dtype=np.float64) / ((1 << bit_depth) - 1)
    return _split(_lut_coordinate(codes), len(view_grid()[0]))


def _to_uint8(display: np.ndarray) -> np.ndarray:
    return np.clip(display * np.float32(255) + np.float32(0.5), 0, 255).astype(np.uint8)


def view_transform(level: np.ndarray, tone: str) -> np.ndarray:
    """Sensor levels (BGR, 1.0 = saturation) through a Blender view transform -> uint8 BGR. The level is
    Blender's scene-linear value as it is (auto exposure's 0.18 median is Blender's mid grey)."""
    return _to_uint8(apply_view_lut(level, view_lut(tone)))


def view_transform_codes(raw: np.ndarray, tone: str, bit_depth: int) -> np.ndarray:
    """Raw BGR codes (H, W, 3; level = code / (2**bit_depth - 1)) through a Blender view transform -> uint8
    BGR: :func:`view_transform` of the levels, its coordinates looked up per code (fast)."""
    index, fraction = _code_coordinates(bit_depth)
    flat = raw.reshape(-1, 3)
    out = _trilinear(view_lut(tone), np.take(index, flat), np.take(fraction, flat))
    return _to_uint8(out).reshape(raw.shape)
