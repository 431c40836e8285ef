"""Bake Blender's view transforms into 3D LUTs for the camera model (``tone: blender-*``, docs/camera-model.md).

Run with Blender's interpreter (``bpy`` 4.5; standard library, numpy and ``bpy`` only)::

    .venv-photoreal/bin/python scenarios/photoreal/bake_view_luts.py --out scenarios/view_luts.npz

For each view (transform, look) it makes one float image holding a grid of scene-linear values, Rec.709 primaries
(Blender's scene-linear), ``STEPS`` per channel: 0, then ``STEPS - 1`` values log2-spaced from ``EV_MIN`` to
``EV_MAX`` stops around 1.0 (the camera's saturation is a node; mid grey 0.18 is 2.47 stops below it). The image is saved through colour management
(``Image.save_render(path, scene=scene)``: the scene's view transform, look and display, sRGB) to a 16-bit PNG,
read back, and the display-referred values (sRGB-encoded, 0-65535) are stored as ``lut_<name>`` with shape
(STEPS, STEPS, STEPS, 3), indexed ``[b, g, r]`` and holding B, G, R (the project's order), plus the grid's
``levels`` (its nodes per channel) and the Blender version. ``--check`` saves a few grey levels through ``Standard`` and compares
them with the sRGB formula: proof that ``save_render`` applies the view transform.

``--develop LEVELS.npy --view NAME --png OUT`` saves linear values (float32 (H, W, 3), RGB, e.g. a camera's sensor
levels of an EXR) through a view directly, 8 bits: the fidelity check of the LUT path (docs/camera-model.md, "Looks";
``python -m scenarios.photoreal.view_fidelity`` prepares the levels and compares).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

import bpy

#: Grid: 0, then STEPS - 1 nodes from EV_MIN to EV_MAX stops around 1.0 (log2-spaced, half a stop apart): about -12
#: to +5 stops around mid grey, with the sensor's saturation (1.0) a node, where a clipping view (Standard) has its
#: kink.
STEPS = 36
EV_MIN, EV_MAX = -14.5, 2.5
#: name -> (view transform, look) as Blender 4.5 names them.
VIEWS = {
    "blender-standard": ("Standard", "None"),
    "blender-agx": ("AgX", "None"),
    "blender-agx-punchy": ("AgX", "AgX - Punchy"),
    "blender-filmic": ("Filmic", "None"),
    "blender-filmic-high-contrast": ("Filmic", "High Contrast"),
    "blender-khronos-pbr-neutral": ("Khronos PBR Neutral", "None"),
}


def grid_values(steps: int = STEPS) -> np.ndarray:
    """The grid's nodes per channel: 0, then log2-spaced from EV_MIN to EV_MAX stops around 1.0."""
    return np.concatenate([[0.0], 2.0 ** np.linspace(EV_MIN, EV_MAX, steps - 1)])


def _scene(view: str, look: str, depth: int = 16):
    scene = bpy.context.scene
    scene.render.dither_intensity = 0.0
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = view
    scene.view_settings.look = look
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.view_settings.use_curve_mapping = False
    scene.sequencer_colorspace_settings.name = "sRGB"
    settings = scene.render.image_settings
    settings.file_format = "PNG"
    settings.color_mode = "RGB"
    settings.color_depth = str(depth)
    settings.compression = 0
    if hasattr(settings, "color_management"):
        settings.color_management = "FOLLOW_SCENE"
    return scene


def save_through_view(rgb: np.ndarray, view: str, look: str, path: str, depth: int = 16) -> np.ndarray:
    """Linear Rec.709 RGB (H, W, 3, float) saved through ``view``/``look`` to a PNG of ``depth`` bits (16 or 8);
    its RGB codes back (uint16, (H, W, 3), top row first)."""
    h, w = rgb.shape[:2]
    image = bpy.data.images.new("evopose-bake", width=w, height=h, alpha=False, float_buffer=True)
    image.colorspace_settings.name = "Linear Rec.709"
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = rgb
    image.pixels.foreach_set(rgba[::-1].ravel())  # Blender's rows go bottom-up
    scene = _scene(view, look, depth)
    if scene.view_settings.view_transform != view or scene.view_settings.look != look:
        raise RuntimeError(f"Blender did not take view {view!r} look {look!r}")
    image.save_render(path, scene=scene)
    bpy.data.images.remove(image)
    back = bpy.data.images.load(path)
    back.colorspace_settings.name = "Non-Color"  # the stored code values, not decoded
    px = np.empty(back.size[0] * back.size[1] * back.channels, np.float32)
    back.pixels.foreach_get(px)
    px = px.reshape(back.size[1], back.size[0], back.channels)[::-1, :, :3]
    bpy.data.images.remove(back)
    return np.round(px * float((1 << depth) - 1)).astype(np.uint16)


def bake(steps: int) -> dict[str, np.ndarray]:
    nodes = grid_values(steps)
    b, g, r = np.meshgrid(nodes, nodes, nodes, indexing="ij")  # [b, g, r] order
    rgb = np.stack([r, g, b], axis=-1).reshape(steps * steps, steps, 3)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (view, look) in VIEWS.items():
            codes = save_through_view(rgb, view, look, os.path.join(tmp, f"{name}.png"))
            out[f"lut_{name}"] = codes.reshape(steps, steps, steps, 3)[..., ::-1].copy()  # RGB -> BGR
            print(f"{name}: {view} / {look}: saturation (1.0) -> {codes.reshape(steps, steps, steps, 3)[-6, -6, -6]}",
                  file=sys.stderr)
    return out


def check_standard() -> float:
    """Grey levels through Standard vs the sRGB formula: the largest difference in 16-bit codes."""
    levels = np.array([0.0, 0.001, 0.01, 0.05, 0.18, 0.5, 0.9, 1.0])
    rgb = np.repeat(levels[None, :, None], 3, axis=2)
    with tempfile.TemporaryDirectory() as tmp:
        codes = save_through_view(rgb, "Standard", "None", os.path.join(tmp, "check.png"))[0, :, 0]
    srgb = np.where(levels <= 0.0031308, 12.92 * levels, 1.055 * levels ** (1 / 2.4) - 0.055)
    return float(np.abs(codes - srgb * 65535).max())


def develop(levels: str, name: str, png: str) -> None:
    """Linear Rec.709 RGB values (a float32 (H, W, 3) .npy) saved through the view ``name`` to ``png``, 8 bits."""
    view, look = VIEWS[name]
    save_through_view(np.load(levels).astype(np.float32), view, look, png, depth=8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="the .npz to write")
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--check", action="store_true")
    parser.add_argument("--develop", metavar="LEVELS.npy")
    parser.add_argument("--view", default="blender-agx")
    parser.add_argument("--png")
    args = parser.parse_args()
    if args.check:
        print(f"Standard vs sRGB formula: max {check_standard():.1f} of 65535")
    if args.develop:
        develop(args.develop, args.view, args.png)
    if args.out:
        luts = bake(args.steps)
        np.savez_compressed(args.out, levels=grid_values(args.steps),
                            blender=np.array(bpy.app.version_string), views=np.array(list(VIEWS)),
                            transforms=np.array([f"{v} / {lk}" for v, lk in VIEWS.values()]), **luts)
        print(f"{args.out}: {os.path.getsize(args.out)} bytes", file=sys.stderr)


if __name__ == "__main__":
    main()
