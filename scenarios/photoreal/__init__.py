"""Photoreal rendering with Blender's Cycles path tracer (``bpy``, run in its own interpreter).

- :mod:`.scene`: a world and its frames as a JSON scene description (cameras, poses, meshes, materials, light);
- :mod:`.blender_job`: the script Blender's interpreter runs on that description (stdlib and ``bpy`` only);
- :mod:`.runner`: finding that interpreter and running a job, frame by frame;
- :mod:`.exr`: reading the linear radiance Blender writes (OpenEXR; the project's OpenCV has no EXR codec);
- :mod:`.develop`: radiance -> the camera's image (lens distortion, then the camera model);
- :mod:`.shapes`: clutter and mark meshes shared by Blender and the ground truth's occlusion rays.

``bpy`` 4.5 needs numpy < 2 and the project pins numpy 2: ``make photoreal`` creates ``.venv-photoreal``.
"""
