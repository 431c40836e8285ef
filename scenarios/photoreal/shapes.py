"""Solid shapes of the photoreal scene as polygon meshes: clutter objects and the marks' thin discs.

One mesh serves both ends: Blender builds the object from its vertices and faces (curved sides smooth-shaded),
and the ground truth casts its occlusion rays against the same faces (:class:`scenarios.mesh.Mesh`), so a
mark hidden in the image is hidden in the truth. Curved sides and flat caps have their own vertices, so
smooth shading never bends a cap's rim.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh import Mesh, box_mesh, ellipsoid_mesh
from ..world import ClutterSpec

#: Segments around a cylinder (a bucket, a disc) and a mark's disc.
CYLINDER_SEGMENTS = 48
MARK_SEGMENTS = 32
#: (around, along) segments of a sphere (a ball).
SPHERE_SEGMENTS = (40, 20)
#: A mark's disc: its thickness and how far its centre stands off the face it is painted on (metres).
MARK_THICKNESS = 0.001
MARK_STANDOFF = 0.001


@dataclass(frozen=True)
class Solid:
    """Vertices (V, 3), faces (index lists) and per-face smooth flags of one object, in its parent's frame."""

    vertices: np.ndarray
    faces: tuple[np.ndarray, ...]
    smooth: tuple[bool, ...]

    def mesh(self, colour=(0, 0, 0)) -> Mesh:
        return Mesh(self.vertices, self.faces, np.tile(np.asarray(colour, float), (len(self.faces), 1)),
                    np.zeros(len(self.faces), bool))

    def moved(self, T: np.ndarray) -> "Solid":
        return Solid(self.vertices @ T[:3, :3].T + T[:3, 3], self.faces, self.smooth)

    def to_json(self) -> dict:
        return {"vertices": np.round(self.vertices, 7).tolist(), "faces": [f.tolist() for f in self.faces],
                "smooth": list(self.smooth)}


def join(solids: list[Solid]) -> Solid:
    """Several solids as one object (e.g. all marks of one colour)."""
    vertices, faces, smooth, offset = [], [], [], 0
    for s in solids:
        vertices.append(s.vertices)
        faces += [f + offset for f in s.faces]
        smooth += list(s.smooth)
        offset += len(s.vertices)
    return Solid(np.concatenate(vertices) if vertices else np.zeros((0, 3)), tuple(faces), tuple(smooth))


def from_mesh(mesh: Mesh, smooth: bool = False) -> Solid:
    return Solid(np.asarray(mesh.vertices, float), tuple(np.asarray(f) for f in mesh.faces), (smooth,) * len(mesh))


def cylinder(radius_x: float, radius_y: float, height: float, segments: int = CYLINDER_SEGMENTS) -> Solid:
    """An upright elliptic cylinder centred on the origin: smooth side quads, flat caps with their own vertices."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([radius_x * np.cos(a), radius_y * np.sin(a), np.zeros(segments)])
    lo, hi = ring - [0, 0, height / 2], ring + [0, 0, height / 2]
    vertices = np.concatenate([lo, hi, lo, hi])  # sides use 0..2n, caps 2n..4n
    n = segments
    sides = [np.array([j, (j + 1) % n, n + (j + 1) % n, n + j]) for j in range(n)]
    bottom = np.arange(2 * n, 3 * n)[::-1].copy()   # seen from below: clockwise from above
    top = np.arange(3 * n, 4 * n)
    return Solid(vertices, tuple(sides) + (bottom, top), (True,) * n + (False, False))


def _placed(solid: Solid, centre, yaw: float = 0.0, axis=None) -> Solid:
    """``solid`` (built around the origin, z up) rotated by ``yaw`` about z, or with its z axis along ``axis``,
    then moved to ``centre``."""
    T = np.eye(4)
    if axis is not None:
        z = np.asarray(axis, float) / np.linalg.norm(axis)
        helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    else:
        c, s = np.cos(yaw), np.sin(yaw)
        T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = centre
    return solid.moved(T)


def clutter_solid(spec: ClutterSpec) -> Solid:
    """A clutter object in the world frame. ``size``: a box's sides; a cylinder's or disc's diameters along x and
    y and its height; a sphere's diameters (an ellipsoid)."""
    sx, sy, sz = spec.size
    if spec.shape == "box":
        solid = from_mesh(box_mesh([0, 0, 0], spec.size, (0, 0, 0)))
    elif spec.shape in ("cylinder", "disc"):
        solid = cylinder(sx / 2, sy / 2, sz)
    else:
        # ellipsoid_mesh's long axis is x; its segments are (around x, along x)
        solid = from_mesh(ellipsoid_mesh([0, 0, 0], [sx / 2, sy / 2, sz / 2], (0, 0, 0), SPHERE_SEGMENTS), True)
    return _placed(solid, spec.centre, spec.yaw)


def clutter_mesh(clutter: list[ClutterSpec]) -> Mesh:
    """Every clutter object as one :class:`Mesh` (world frame), for occlusion rays."""
    mesh = Mesh.empty()
    for spec in clutter:
        mesh = mesh + clutter_solid(spec).mesh(spec.colour)
    return mesh


def mark_disc(position, normal, radius: float) -> Solid:
    """A mark as a thin disc on its face (target frame): ``MARK_THICKNESS`` thick, its centre
    ``MARK_STANDOFF`` off the face along ``normal``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    disc = cylinder(radius, radius, MARK_THICKNESS, MARK_SEGMENTS)
    disc = Solid(disc.vertices, disc.faces, (False,) * len(disc.faces))
    return _placed(disc, np.asarray(position, float) + MARK_STANDOFF * n, axis=n)
