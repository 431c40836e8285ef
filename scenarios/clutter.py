"""Clutter objects (``render.clutter``: boxes, cylinders, spheres, discs) as low-polygon meshes for the OpenCV
renderer, which draws them like the target's body and casts the marks' occlusion rays against the same faces.

The conventions are the world schema's (:class:`scenarios.world.ClutterSpec`), shared with the photoreal
renderer: ``centre`` is the object's centre (world frame, metres), ``size`` a box's sides or a cylinder's, disc's
or sphere's diameters along x and y and its height (an elliptic cylinder, an ellipsoid), ``yaw`` a turn about
the vertical through the centre. Curved sides are faceted (:data:`CYLINDER_SIDES`, :data:`SPHERE_SEGMENTS`): few
enough faces that a frame stays fast, enough that an object a few pixels across looks round.
"""

from __future__ import annotations

import numpy as np

from .mesh import Mesh, box_mesh, ellipsoid_mesh
from .world import ClutterSpec

#: Sides of a cylinder's or disc's prism.
CYLINDER_SIDES = 16
#: (around, along) segments of a sphere's latitude-longitude mesh.
SPHERE_SEGMENTS = (16, 8)


def prism_mesh(radius_x: float, radius_y: float, height: float, colour, sides: int = CYLINDER_SIDES) -> Mesh:
    """An upright elliptic prism centred on the origin: ``sides`` quads and two caps, normals outwards."""
    a = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.column_stack([radius_x * np.cos(a), radius_y * np.sin(a), np.zeros(sides)])
    vertices = np.concatenate([ring - [0, 0, height / 2], ring + [0, 0, height / 2]])
    n = sides
    faces = [np.array([j, (j + 1) % n, n + (j + 1) % n, n + j]) for j in range(n)]  # counter-clockwise outside
    faces += [np.arange(n)[::-1].copy(), np.arange(n, 2 * n)]  # bottom (seen from below), top
    return Mesh(vertices, tuple(faces), np.tile(np.asarray(colour, float), (len(faces), 1)),
                np.zeros(len(faces), bool))


def clutter_object_mesh(spec: ClutterSpec) -> Mesh:
    """One clutter object in the world frame."""
    sx, sy, sz = spec.size
    colour = tuple(spec.colour)
    if spec.shape == "box":
        mesh = box_mesh([0, 0, 0], spec.size, colour)
    elif spec.shape in ("cylinder", "disc"):
        mesh = prism_mesh(sx / 2, sy / 2, sz, colour)
    else:
        mesh = ellipsoid_mesh([0, 0, 0], [sx / 2, sy / 2, sz / 2], colour, SPHERE_SEGMENTS)
    c, s = np.cos(spec.yaw), np.sin(spec.yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = spec.centre
    return mesh.transformed(T)


def clutter_mesh(clutter: list[ClutterSpec]) -> Mesh:
    """Every clutter object of a world as one mesh (world frame)."""
    mesh = Mesh.empty()
    for spec in clutter:
        mesh = mesh + clutter_object_mesh(spec)
    return mesh
