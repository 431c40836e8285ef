"""Polygon meshes for drawing and self-occlusion: boxes, ellipsoids and flat polygons with flat colours.

A :class:`Mesh` holds convex planar faces (each a list of vertex indices, counter-clockwise seen
from outside, so the face normal points out). Two-sided faces (fins, panels) are drawn from both sides.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

Colour = tuple[int, int, int]


@dataclass(frozen=True, eq=False)
class Mesh:
    """Flat-coloured convex faces.

    Attributes
    ----------
    vertices : array, shape (V, 3)
        Metres, in the frame of the owner (target frame or world).
    faces : tuple of int arrays
        Vertex indices of each convex planar face, counter-clockwise seen from outside.
    colours : array, shape (F, 3)
        BGR 0-255.
    two_sided : bool array, shape (F,)
    """

    vertices: np.ndarray
    faces: tuple[np.ndarray, ...]
    colours: np.ndarray
    two_sided: np.ndarray

    @classmethod
    def empty(cls) -> "Mesh":
        return cls(np.zeros((0, 3)), (), np.zeros((0, 3)), np.zeros(0, bool))

    def __len__(self) -> int:
        return len(self.faces)

    @cached_property
    def normals(self) -> np.ndarray:
        """Unit face normals (Newell's method), shape (F, 3); made once per mesh (a moved mesh rotates them)."""
        out = np.zeros((len(self.faces), 3))
        for i, face in enumerate(self.faces):
            p = self.vertices[face]
            q = np.roll(p, -1, axis=0)
            n = np.array([np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
                          np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
                          np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1]))])
            out[i] = n / max(np.linalg.norm(n), 1e-12)
        return out

    @property
    def centres(self) -> np.ndarray:
        """Face centroids (vertex means), shape (F, 3)."""
        return np.array([self.vertices[f].mean(axis=0) for f in self.faces]).reshape(-1, 3)

    def triangles(self) -> np.ndarray:
        """Fan triangulation of every face, shape (T, 3, 3) (for ray occlusion tests)."""
        tris = [self.vertices[[f[0], f[k], f[k + 1]]] for f in self.faces for k in range(1, len(f) - 1)]
        return np.array(tris).reshape(-1, 3, 3)

    def transformed(self, T: np.ndarray) -> "Mesh":
        """The mesh moved by the 4x4 transform ``T`` (e.g. ``world_from_target``)."""
        v = self.vertices @ T[:3, :3].T + T[:3, 3]
        moved = Mesh(v, self.faces, self.colours, self.two_sided)
        moved.__dict__["normals"] = self.normals @ T[:3, :3].T  # a rigid motion rotates the normals
        return moved

    def __add__(self, other: "Mesh") -> "Mesh":
        offset = len(self.vertices)
        joined = Mesh(np.concatenate([self.vertices, other.vertices]),
                      self.faces + tuple(f + offset for f in other.faces),
                      np.concatenate([self.colours, other.colours]).reshape(-1, 3),
                      np.concatenate([self.two_sided, other.two_sided]))
        joined.__dict__["normals"] = np.concatenate([self.normals, other.normals]).reshape(-1, 3)  # face by face
        return joined


def _outward(vertices: np.ndarray, faces: list[np.ndarray], centre: np.ndarray) -> list[np.ndarray]:
    """Reverse faces whose winding points their normal towards ``centre`` (closed convex solids)."""
    mesh = Mesh(vertices, tuple(faces), np.zeros((len(faces), 3)), np.zeros(len(faces), bool))
    out_dir = mesh.centres - centre
    flip = np.sum(mesh.normals * out_dir, axis=1) < 0
    return [f[::-1].copy() if fl else f for f, fl in zip(faces, flip)]


def box_mesh(centre, size, colour: Colour) -> Mesh:
    """An axis-aligned box of ``size`` (dx, dy, dz) metres around ``centre``: 6 quads."""
    c, h = np.asarray(centre, float), np.asarray(size, float) / 2
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    vertices = c + signs * h
    quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    faces = _outward(vertices, [np.array(q) for q in quads], c)
    return Mesh(vertices, tuple(faces), np.tile(np.asarray(colour, float), (6, 1)), np.zeros(6, bool))


def ellipsoid_mesh(centre, semi_axes, colour: Colour, segments: tuple[int, int] = (24, 12)) -> Mesh:
    """An ellipsoid around ``centre`` with semi-axes (a, b, c) along x, y, z, as a latitude-longitude mesh.

    ``segments`` = (around the x axis, along the x axis); the long axis is x (a hull's roll axis).
    The vertices lie on the surface, so the faces are slightly inside it.
    """
    c, (a, b, cz) = np.asarray(centre, float), np.asarray(semi_axes, float)
    n_around, n_along = segments
    us = np.cos(np.linspace(np.pi, 0, n_along + 1))  # x / a from -1 to 1
    phis = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    vertices = [c + [-a, 0, 0]]
    for u in us[1:-1]:
        r = np.sqrt(1 - u * u)
        vertices += [c + [a * u, b * r * np.cos(p), cz * r * np.sin(p)] for p in phis]
    vertices.append(c + [a, 0, 0])
    vertices = np.array(vertices)
    rings = n_along - 1
    ring = lambda k, j: 1 + k * n_around + (j % n_around)  # noqa: E731
    faces = [np.array([0, ring(0, j + 1), ring(0, j)]) for j in range(n_around)]
    for k in range(rings - 1):
        faces += [np.array([ring(k, j), ring(k, j + 1), ring(k + 1, j + 1), ring(k + 1, j)]) for j in range(n_around)]
    last = len(vertices) - 1
    faces += [np.array([last, ring(rings - 1, j), ring(rings - 1, j + 1)]) for j in range(n_around)]
    faces = _outward(vertices, faces, c)
    return Mesh(vertices, tuple(faces), np.tile(np.asarray(colour, float), (len(faces), 1)),
                np.zeros(len(faces), bool))


def polygon_mesh(points, colour: Colour, two_sided: bool = True) -> Mesh:
    """One flat convex polygon (a fin, a panel), shape (K, 3) with K >= 3."""
    p = np.asarray(points, float)
    return Mesh(p, (np.arange(len(p)),), np.asarray(colour, float).reshape(1, 3), np.array([two_sided]))


def first_hits(origins: np.ndarray, targets: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Whether the segment from each origin to its target crosses any triangle before the target (see :func:`hits`)."""
    return hits(origins, targets, triangles).any(axis=1)


def hits(origins: np.ndarray, targets: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Which triangles the segment from each origin to its target crosses before the target.

    Möller–Trumbore, vectorised over segments x triangles.

    Parameters
    ----------
    origins : array, shape (N, 3) or (3,)
    targets : array, shape (N, 3)
    triangles : array, shape (T, 3, 3)

    Returns
    -------
    bool array, shape (N, T)
        True where the segment crosses the triangle at a fraction in (1e-6, 1 - 1e-6) of its length.
    """
    targets = np.asarray(targets, float).reshape(-1, 3)
    if len(triangles) == 0 or len(targets) == 0:
        return np.zeros((len(targets), len(triangles)), bool)
    o = np.broadcast_to(np.asarray(origins, float), targets.shape)
    d = (targets - o)[:, None, :]                       # (N, 1, 3)
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(d, e2[None])                           # (N, T, 3)
    det = np.einsum("ntk,tk->nt", p, e1)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o[:, None, :] - v0[None]
    u = np.einsum("ntk,ntk->nt", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("ntk,nk->nt", q, d[:, 0]) * inv
    t = np.einsum("ntk,tk->nt", q, e2) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6) & (t < 1 - 1e-6)
    return hit
