"""Render a scene description (:mod:`scenarios.photoreal.scene`) with Blender's Cycles: run by Blender's interpreter.

    .venv-photoreal/bin/python scenarios/photoreal/blender_job.py JOB.json

Standard library and ``bpy`` only (Blender's interpreter has neither the project nor numpy 2). The static scene is
built once; then, frame by frame, the target, the moving occluders and the camera are placed and each image is
rendered to an OpenEXR file of linear radiance (half float, no view transform, no tone mapping), written under a
temporary name and renamed, so an existing file is always whole: an image whose file exists is skipped (resume).
One line per image goes to stdout: ``EVOPOSE-PROGRESS {"frame": k, "camera": "H1", "path": ..., "seconds": s,
"skipped": false}``.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import traceback

PROGRESS = "EVOPOSE-PROGRESS"
#: Nishita sky: scale of its physical radiance so that ``sky_strength: 1`` with the sun 60 deg high gives the
#: ground about 0.8 W/m^2 of sky irradiance (a fifth of the default sun's 4 W/m^2, as on a clear day).
NISHITA_SCALE = 0.085
#: Overcast sky: zenith radiance at ``sky_strength: 1`` (CIE overcast sky: horizontal irradiance 7 pi / 9 of it,
#: ~1.2 W/m^2, under a third of a clear day's).
OVERCAST_ZENITH = 0.5
OVERCAST_TINT = (0.92, 0.95, 1.0)


def _principled(bpy, name: str, spec: dict):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*spec["base_colour"], 1.0)
    bsdf.inputs["Roughness"].default_value = spec["roughness"]
    if spec.get("emission"):  # a light source (the camera-mapping check renders a glowing ball)
        bsdf.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bsdf.inputs["Emission Strength"].default_value = float(spec["emission"])
    if spec.get("texture"):
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(spec["texture"])
        tex.image.colorspace_settings.name = "sRGB"
        tex.extension = "REPEAT"
        tex.interpolation = "Linear"
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (1.0 / spec["tile"],) * 3
        links.new(coords.outputs["Object"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Strength"].default_value = 0.3
        bump.inputs["Distance"].default_value = 0.002
        links.new(tex.outputs["Color"], bump.inputs["Height"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    return mat


def _mesh_object(bpy, name: str, spec: dict, material):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(spec["vertices"], [], spec["faces"])
    mesh.update()
    mesh.polygons.foreach_set("use_smooth", [bool(s) for s in spec["smooth"]])
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _engine(scene, engine: dict) -> None:
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = int(engine["samples"])
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = bool(engine["denoise"])
    cycles.pixel_filter_type = engine["filter"]
    cycles.filter_width = float(engine["filter_width"])
    cycles.max_bounces = int(engine["max_bounces"])
    cycles.diffuse_bounces = int(engine["diffuse_bounces"])
    cycles.glossy_bounces = int(engine["glossy_bounces"])
    cycles.transmission_bounces = 0
    cycles.volume_bounces = 0
    cycles.transparent_max_bounces = int(engine["transparent_bounces"])
    cycles.caustics_reflective = False
    cycles.caustics_refractive = False
    cycles.sample_clamp_indirect = float(engine["clamp_indirect"])
    cycles.use_animated_seed = False
    scene.render.film_transparent = False
    scene.render.use_persistent_data = True
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    if engine.get("threads"):
        scene.render.threads_mode = "FIXED"
        scene.render.threads = int(engine["threads"])
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGB"
    settings.color_depth = "16"
    settings.exr_codec = "ZIP"
    scene.render.use_file_extension = False
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0


def _sky(bpy, scene, lighting: dict) -> None:
    from mathutils import Vector

    world = bpy.data.worlds.new("sky")
    scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = nodes["Background"]
    if lighting["sky"] == "clear":
        sky = nodes.new("ShaderNodeTexSky")
        sky.sky_type = "NISHITA"
        sky.sun_disc = False  # the sun is the lamp below: its strength and its shadows are the world's
        sky.sun_elevation = max(lighting["sun_elevation"], 0.0)
        # Nishita's sun at rotation r lies at azimuth r - pi/2 from +x (measured: the sky is brightest there)
        sky.sun_rotation = (lighting["sun_azimuth"] + math.pi / 2) % (2 * math.pi)
        links.new(sky.outputs["Color"], background.inputs["Color"])
        background.inputs["Strength"].default_value = NISHITA_SCALE * lighting["sky_strength"]
        if lighting["sun_strength"] > 0 and lighting["sun_elevation"] > 0:
            light = bpy.data.lights.new("sun", "SUN")
            light.energy = lighting["sun_strength"]
            light.angle = lighting["sun_angle"]
            sun = bpy.data.objects.new("sun", light)
            # a sun lamp shines along its -z: its +z points at the sun
            sun.rotation_mode = "QUATERNION"
            sun.rotation_quaternion = Vector(lighting["sun_direction"]).to_track_quat("Z", "Y")
            scene.collection.objects.link(sun)
    else:
        # CIE overcast sky: L(theta) = L_zenith (1 + 2 cos theta) / 3, no sun
        coords = nodes.new("ShaderNodeTexCoord")
        split = nodes.new("ShaderNodeSeparateXYZ")
        clamp = nodes.new("ShaderNodeMath")
        clamp.operation = "MAXIMUM"
        clamp.inputs[1].default_value = 0.0
        shape = nodes.new("ShaderNodeMath")
        shape.operation = "MULTIPLY_ADD"
        shape.inputs[1].default_value = 2.0 / 3.0
        shape.inputs[2].default_value = 1.0 / 3.0
        links.new(coords.outputs["Generated"], split.inputs["Vector"])
        links.new(split.outputs["Z"], clamp.inputs[0])
        links.new(clamp.outputs["Value"], shape.inputs[0])
        links.new(shape.outputs["Value"], background.inputs["Strength"])
        background.inputs["Color"].default_value = (*(OVERCAST_ZENITH * lighting["sky_strength"] * c
                                                      for c in OVERCAST_TINT), 1.0)


def build(bpy, job: dict) -> dict:
    """The static scene of ``job``; returns the objects moved per frame (target, movers, cameras)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    _engine(scene, job["engine"])
    _sky(bpy, scene, job["lighting"])
    materials = {name: _principled(bpy, name, spec) for name, spec in job["materials"].items()}
    target = bpy.data.objects.new("target", None)
    scene.collection.objects.link(target)
    movers = {}
    for spec in job["objects"]:
        obj = _mesh_object(bpy, spec["name"], spec, materials[spec["material"]])
        if spec["parent"] == "target":
            obj.parent = target
        elif spec["parent"] == "mover":
            movers[spec["name"]] = obj
    half = job["ground"]["half_size"]
    _mesh_object(bpy, "ground", {"vertices": [[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]],
                                 "faces": [[0, 1, 2, 3]], "smooth": [False]}, materials[job["ground"]["material"]])
    cameras = {}
    for name, spec in job["cameras"].items():
        data = bpy.data.cameras.new(name)
        data.type = "PERSP"
        data.sensor_fit = spec["sensor_fit"]
        data.sensor_width = spec["sensor_width"]
        data.lens = spec["lens"]
        data.shift_x, data.shift_y = spec["shift_x"], spec["shift_y"]
        data.clip_start, data.clip_end = spec["clip_start"], spec["clip_end"]
        cameras[name] = bpy.data.objects.new(name, data)
        scene.collection.objects.link(cameras[name])
    return {"scene": scene, "target": target, "movers": movers, "cameras": cameras}


def render_frames(bpy, job: dict, built: dict) -> None:
    from mathutils import Matrix

    scene, target = built["scene"], built["target"]
    for frame in job["frames"]:
        if frame["target"] is not None:
            target.matrix_world = Matrix(frame["target"])
        for name, matrix in frame["movers"].items():
            built["movers"][name].matrix_world = Matrix(matrix)
        for item in frame["renders"]:
            path = item["path"]
            report = {"frame": frame["frame"], "camera": item["camera"], "path": path}
            if os.path.exists(path):
                print(PROGRESS, json.dumps({**report, "seconds": 0.0, "skipped": True}), flush=True)
                continue
            start = time.perf_counter()
            camera = built["cameras"][item["camera"]]
            camera.matrix_world = Matrix(item["matrix"])
            spec = job["cameras"][item["camera"]]
            scene.camera = camera
            scene.render.resolution_x, scene.render.resolution_y = spec["width"], spec["height"]
            scene.cycles.seed = int(item["seed"])
            os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
            partial = path + ".partial"
            scene.render.filepath = partial
            bpy.ops.render.render(write_still=True)
            os.replace(partial, path)
            print(PROGRESS, json.dumps({**report, "seconds": round(time.perf_counter() - start, 3),
                                        "skipped": False}), flush=True)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: blender_job.py JOB.json", file=sys.stderr)
        return 2
    with open(argv[0], encoding="utf-8") as f:
        job = json.load(f)
    if job.get("format") != "evopose-blender-job/1":
        print(f"{argv[0]}: not an evopose Blender job (format {job.get('format')!r})", file=sys.stderr)
        return 2
    import bpy

    try:
        render_frames(bpy, job, build(bpy, job))
    except Exception:  # noqa: BLE001 - the parent reports the last line
        traceback.print_exc()
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
