"""Named looks: camera models that differ from the home camera the way other cameras do (docs/camera-model.md,
"Looks"), for measuring the image front-end on looks it was never tuned on.

A look is a mapping of :class:`scenarios.camera_model.CameraModelSpec` fields put over a base camera model (the
world's): :func:`look_spec` applies one by name, :func:`random_look` draws one for training and development,
:func:`corner_look` one at the edges of those ranges (the hard looks, where a camera's settings add up).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .camera_model import CameraModelSpec
from .documents import validate
from .errors import WorldError
from .view_luts import VIEW_TONES

#: The named looks: overrides of CameraModelSpec fields (white balance B, G, R like every colour of the project).
LOOKS: dict[str, dict[str, Any]] = {
    # The home look: the camera model as the world gives it (the default camera: sRGB, JPEG 85 4:2:0).
    "camera": {},
    # Blender's default view since 4.0: chroma-compressing film curve, highlights never clip to white.
    "agx": {"tone": "blender-agx"},
    # AgX with the Punchy look: darker mid-tones, more contrast and saturation.
    "agx-punchy": {"tone": "blender-agx-punchy"},
    # Blender's Filmic (the default view of 2.80-3.6): brighter mid-tones, a long soft shoulder.
    "filmic": {"tone": "blender-filmic"},
    # A blown, warm sunlit scene: saturated, white balance off towards red, over-exposed by a stop.
    "vivid-warm": {"saturation": 1.5, "white_balance": [0.75, 1.0, 1.3], "exposure_bias_ev": 1.0,
                   "jpeg_quality": 90},
    # A cheap camera's cold, flat, dark stream: washed-out colour, blue cast, under-exposed, JPEG 50.
    "flat-cool": {"saturation": 0.45, "white_balance": [1.3, 1.0, 0.75], "exposure_bias_ev": -1.5,
                  "jpeg_quality": 50},
    # A faded film-like grade: Hable's filmic curve, desaturated, hue off by 8 deg, soft lens, JPEG 60.
    "hable-faded": {"tone": "filmic", "saturation": 0.7, "hue_rotation_deg": 8.0, "lens_blur_px": 1.0,
                    "jpeg_quality": 60},
    # A dark, contrasty, green-cast stream: display gamma 2.6 instead of sRGB, a stop under, more saturation.
    "gamma-dark": {"tone": "gamma", "gamma": 2.6, "exposure_bias_ev": -1.0, "saturation": 1.2,
                   "white_balance": [1.0, 1.2, 1.0]},
}

#: The tones :func:`random_look` draws from: the built-in curves and every baked Blender view.
RANDOM_TONES = ("srgb", "gamma", "filmic", *VIEW_TONES)


def look_overrides(name: str) -> dict[str, Any]:
    """The fields of the named look (a copy). Raises WorldError for an unknown name."""
    if name not in LOOKS:
        raise WorldError(f"unknown look {name!r} (looks: {', '.join(LOOKS)})")
    return {k: (list(v) if isinstance(v, list) else v) for k, v in LOOKS[name].items()}


def apply_look(base: CameraModelSpec, overrides: dict[str, Any]) -> CameraModelSpec:
    """``base`` with the fields of ``overrides`` replaced, validated (a bad field is a WorldError)."""
    if not isinstance(overrides, dict):
        raise WorldError(f"look: expected a mapping of camera model fields, got {type(overrides).__name__}")
    return validate(CameraModelSpec, {**base.model_dump(), **overrides}, "look", WorldError)


def look_spec(base: CameraModelSpec, name: str) -> CameraModelSpec:
    """The camera model ``base`` seen through the named look (:data:`LOOKS`)."""
    return apply_look(base, look_overrides(name))


def random_look(rng: np.random.Generator) -> dict[str, Any]:
    """A random look (overrides of CameraModelSpec fields) for training and development: any tone, saturation
    0.4-1.5, white balance 0.7-1.3 per channel, exposure bias -1.5..+1.5 EV, hue rotation within +-10 deg,
    JPEG quality 50-95, lens blur 0-1.5 px (sigma)."""
    look: dict[str, Any] = {"tone": str(rng.choice(RANDOM_TONES))}
    if look["tone"] == "gamma":
        look["gamma"] = round(float(rng.uniform(1.8, 2.8)), 3)
    look.update({
        "saturation": round(float(rng.uniform(0.4, 1.5)), 3),
        "white_balance": [round(float(g), 3) for g in rng.uniform(0.7, 1.3, 3)],
        "exposure_bias_ev": round(float(rng.uniform(-1.5, 1.5)), 3),
        "hue_rotation_deg": round(float(rng.uniform(-10.0, 10.0)), 2),
        "jpeg_quality": int(rng.integers(50, 96)),
        "lens_blur_px": round(float(rng.uniform(0.0, 1.5)), 3),
    })
    return look


def corner_look(rng: np.random.Generator) -> dict[str, Any]:
    """A random look at the edges of :func:`random_look`'s ranges, for development: its tone, hue turn and lens
    blur drawn as there, saturation 0.4, 0.45 or 1.5, each white-balance gain 0.7, 1.0 or 1.3, exposure bias -1.5 or
    +1.5 EV, JPEG quality 50 or 55. The named looks ``flat-cool`` and ``vivid-warm`` lie at such corners; a front-end
    chosen on random looks alone meets them rarely."""
    look = random_look(rng)
    look.update({
        "saturation": float(rng.choice([0.4, 0.45, 1.5])),
        "white_balance": [float(g) for g in rng.choice([0.7, 1.0, 1.3], 3)],
        "exposure_bias_ev": float(rng.choice([-1.5, 1.5])),
        "jpeg_quality": int(rng.choice([50, 55])),
    })
    return look
