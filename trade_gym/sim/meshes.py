"""Triangle meshes with world-scale UVs for pybullet visual shapes, and the texture files they use.

Owns `Mesh`, the builders (terrain grid, boxes, buildings, rocks, road strips, flat polygons) and texture paths.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade_gym.assets import ASSETS_DIR
from trade_gym.sim.bullet_lists import bullet_list
from trade_gym.sim.mesh_files import mesh_visual_shape

FloatArray = npt.NDArray[np.float64]

TEXTURE_DIR = ASSETS_DIR / "textures"
# World size of one texture repeat [m] (make_assets.py sizes the texture features from these).
TEXTURE_PERIOD_M = {
    "desert_ground": 32.0, "city_ground": 40.0, "mountain_ground": 40.0, "roof": 16.0, "facade": 6.0,
    "dirt_road": 8.0, "rock": 2.5,
}
ROCK_SUBDIVISIONS = 1
ROCK_PROTOTYPES = 6
ROCK_RADIAL_NOISE = 0.12  # relative radial perturbation of the rock prototypes
ROCK_ASPECT_XY, ROCK_ASPECT_Z = (0.8, 1.3), (0.55, 0.85)  # prototype semi-axes relative to the size class
ROCK_SIZE_CLASSES_M = (0.45, 0.7, 1.0, 1.4, 1.9)  # boulder radius per size class [m]
ROCK_PROTOTYPE_SEED = 20240611  # fixed: rock shapes are assets, not per-episode randomness


def texture_path(name: str) -> Path:
    """TEXTURE_DIR/<name>.png (the repo's assets/textures); FileNotFoundError says how to generate it."""
    path = TEXTURE_DIR / f"{name}.png"
    if not path.is_file():
        raise FileNotFoundError(f"missing texture {path}; run `python scripts/make_assets.py`")
    return path


@dataclass(frozen=True, eq=False)
class Mesh:
    """Indexed triangle mesh: CCW triangles seen from outside."""

    vertices: FloatArray  # (N, 3) [m]
    uvs: FloatArray  # (N, 2) texture coordinates (repeat)
    normals: FloatArray  # (N, 3) unit
    indices: npt.NDArray[np.int64]  # (3M,) vertex indices

    def create_visual_shape(self, client_id: int, rgba: tuple[float, float, float, float] | None = None) -> int:
        """Textured visual shape; with `rgba`, a uniformly coloured one without UVs."""
        return mesh_visual_shape(client_id, self.vertices, self.indices, self.uvs, self.normals, rgba)

    def create_collision_shape(self, client_id: int) -> int:
        """Concave triangle-mesh collision shape (BVH; static bodies only), exactly the drawn surface."""
        return p.createCollisionShape(p.GEOM_MESH, vertices=bullet_list("vertices", self.vertices),
                                      indices=bullet_list("indices", self.indices), physicsClientId=client_id)


def merge_meshes(meshes: list[Mesh]) -> Mesh:
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return Mesh(np.concatenate([m.vertices for m in meshes]), np.concatenate([m.uvs for m in meshes]),
                np.concatenate([m.normals for m in meshes]),
                np.concatenate([m.indices + o for m, o in zip(meshes, offsets)]))


def placed_meshes(meshes: list[Mesh], yaw_rad: npt.ArrayLike, centres_m: npt.ArrayLike) -> Mesh:
    """One world-frame mesh of meshes turned by yaw (N,) about z and moved to centres (N, 3) [m]:
    v' = Rz(yaw) v + c, n' = Rz(yaw) n, UVs unchanged (textured as the separate meshes would be)."""
    placed = []
    for mesh, yaw, centre in zip(meshes, np.asarray(yaw_rad, dtype=np.float64), np.asarray(centres_m, np.float64)):
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        placed.append(Mesh(mesh.vertices @ R.T + centre, mesh.uvs, mesh.normals @ R.T, mesh.indices))
    return merge_meshes(placed)


def vertex_normals(vertices: FloatArray, triangles: npt.NDArray[np.int64]) -> FloatArray:
    """(N, 3) unit normals: area-weighted sum of the adjacent faces' normals."""
    tri = vertices[triangles]  # (M, 3, 3)
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, triangles[:, k], face)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def box_mesh(centre_m: FloatArray, half_m: FloatArray, uv_top: tuple, uv_side: tuple) -> Mesh:
    """Axis-aligned box with one flat UV (palette cell) for the top face and one for the others."""
    verts, uvs, normals = [], [], []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3  # e_b x e_c = e_a
        for sign in (1.0, -1.0):
            quad = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
            for sb, sc in quad if sign > 0 else quad[::-1]:
                v = np.array(centre_m, dtype=np.float64)
                v[a] += sign * half_m[a]
                v[b] += sb * half_m[b]
                v[c] += sc * half_m[c]
                verts.append(v)
                normals.append(sign * np.eye(3)[a])
                uvs.append(uv_top if (a == 2 and sign > 0) else uv_side)
    quads = np.arange(6)[:, None] * 4 + np.array([0, 1, 2, 0, 2, 3])[None, :]
    return Mesh(np.array(verts), np.array(uvs, dtype=np.float64), np.array(normals), quads.ravel())


@lru_cache(maxsize=8)
def grid_triangles(ny: int, nx: int) -> npt.NDArray[np.int64]:
    """(2 (ny-1)(nx-1), 3) triangles of a row-major grid split along the (i+1, j)-(i, j+1)
    diagonal like Bullet's heightfield: (00, 10, 01) and (11, 01, 10), CCW from above."""
    idx = np.arange(ny * nx).reshape(ny, nx)
    v00, v10, v01, v11 = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tris = np.concatenate([np.stack([v00, v10, v01], -1).reshape(-1, 3), np.stack([v11, v01, v10], -1).reshape(-1, 3)])
    tris.setflags(write=False)
    return tris


@lru_cache(maxsize=8)
def grid_uvs(ny: int, nx: int, x0_m: float, y0_m: float, spacing_m: float, period_m: float) -> FloatArray:
    """(ny, nx, 2) seed-independent UVs of a grid (world x, y / period), cached per process (read-only)."""
    gx, gy = np.meshgrid(x0_m + spacing_m * np.arange(nx), y0_m + spacing_m * np.arange(ny))
    uv = np.stack([gx, gy], axis=-1) / period_m
    uv.setflags(write=False)
    return uv


def create_terrain_visual(client_id: int, vertices_m: FloatArray, uvs: FloatArray, normals: FloatArray,
                          drop_vertex: npt.NDArray[np.bool_] | None = None) -> int:
    """Visual shape of a (sub-)grid of the heightfield: `vertices_m` (ny, nx, 3) in the body frame, `uvs`
    (ny, nx, 2), `normals` (ny, nx, 3); triangles whose three vertices are all flagged in `drop_vertex` (ny, nx)
    are left out (under a lake). The triangulation is Bullet's (see `grid_triangles`), so the picture matches
    the collision surface."""
    ny, nx = vertices_m.shape[:2]
    tris = grid_triangles(ny, nx)
    if drop_vertex is not None:  # kept triangles first, then degenerate (0, 0, 0) ones: a fixed length, so pooled
        kept = tris[~np.all(drop_vertex.ravel()[tris], axis=1)]
        tris = np.zeros_like(tris)
        tris[: len(kept)] = kept
    return mesh_visual_shape(client_id, vertices_m.reshape(-1, 3), tris.ravel(), uvs.reshape(-1, 2),
                             normals.reshape(-1, 3))


def building_meshes(boxes_lo: FloatArray, boxes_hi: FloatArray, facade_period_m: float,
                    roof_period_m: float) -> tuple[Mesh, Mesh]:
    """Walls (UV: along-wall distance and height / period) and roofs (UV: world x, y / period)
    of axis-aligned boxes given by (B, 3) min and max corners."""
    lo, hi = np.asarray(boxes_lo, dtype=np.float64), np.asarray(boxes_hi, dtype=np.float64)
    # wall corner pairs (counter-clockwise seen from above) -> outward normals on the right of travel
    xs = np.stack([lo[:, 0], hi[:, 0], hi[:, 0], lo[:, 0]], 1)
    ys = np.stack([lo[:, 1], lo[:, 1], hi[:, 1], hi[:, 1]], 1)
    a = np.stack([xs, ys], -1)  # (B, 4, 2)
    b = np.roll(a, -1, axis=1)
    length = np.linalg.norm(b - a, axis=-1)  # (B, 4)
    z0, z1 = np.repeat(lo[:, None, 2], 4, 1), np.repeat(hi[:, None, 2], 4, 1)
    wall_v = np.stack([np.dstack([a, z0]), np.dstack([b, z0]), np.dstack([b, z1]), np.dstack([a, z1])], 2)
    wall_uv = np.stack([np.stack([np.zeros_like(length), z0], -1), np.stack([length, z0], -1),
                        np.stack([length, z1], -1), np.stack([np.zeros_like(length), z1], -1)], 2) / facade_period_m
    d = (b - a) / length[..., None]
    wall_n = np.repeat(np.dstack([d[..., 1], -d[..., 0], np.zeros_like(length)])[:, :, None, :], 4, 2)
    roof_v = np.stack([np.stack([xs, ys, np.repeat(hi[:, None, 2], 4, 1)], -1)], 1)  # (B, 1, 4, 3)
    quad = np.array([0, 1, 2, 0, 2, 3])
    walls = Mesh(wall_v.reshape(-1, 3), wall_uv.reshape(-1, 2), wall_n.reshape(-1, 3),
                 (np.arange(wall_v.shape[0] * 4)[:, None] * 4 + quad).ravel())
    roofs = Mesh(roof_v.reshape(-1, 3), roof_v.reshape(-1, 3)[:, :2] / roof_period_m,
                 np.tile([0.0, 0.0, 1.0], (len(lo) * 4, 1)), (np.arange(len(lo))[:, None] * 4 + quad).ravel())
    return walls, roofs


def _icosphere(subdivisions: int) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    t = (1.0 + 5.0**0.5) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
         (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
         (8, 6, 7), (9, 8, 1)]
    verts = [np.array(x, dtype=np.float64) / np.linalg.norm(x) for x in v]
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(i: int, j: int) -> int:
            key = (min(i, j), max(i, j))
            if key not in cache:
                m = verts[i] + verts[j]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        f = [g for a, b, c in f for g in ((a, mid(a, b), mid(a, c)), (b, mid(b, c), mid(a, b)),
                                          (c, mid(a, c), mid(b, c)), (mid(a, b), mid(b, c), mid(a, c)))]
    return np.array(verts), np.array(f, dtype=np.int64)


@lru_cache(maxsize=None)
def rock_prototype(index: int) -> tuple[FloatArray, npt.NDArray[np.int64], FloatArray]:
    """Lumpy unit sphere `index` (seed-independent): (N, 3) vertices, (M, 3) triangles, (3,) aspect."""
    verts, tris = _icosphere(ROCK_SUBDIVISIONS)
    rng = np.random.default_rng(ROCK_PROTOTYPE_SEED + index)
    verts = verts * (1.0 + ROCK_RADIAL_NOISE * rng.uniform(-1.0, 1.0, size=(len(verts), 1)))
    aspect = np.array([*rng.uniform(*ROCK_ASPECT_XY, 2), rng.uniform(*ROCK_ASPECT_Z)])
    return verts, tris, aspect


def rock_radii_m(index: int, size_class: int) -> FloatArray:
    """(3,) ellipsoid semi-axes [m] of prototype `index` at size class `size_class`."""
    return ROCK_SIZE_CLASSES_M[size_class] * rock_prototype(index)[2]


@lru_cache(maxsize=None)
def rock_mesh(index: int, size_class: int) -> Mesh:
    """Prototype scaled to its size class (cached), UVs planar in x + z/2, y + z/2."""
    unit, tris, _ = rock_prototype(index)
    verts = unit * rock_radii_m(index, size_class)
    uv = (verts[:, :2] + 0.5 * verts[:, 2:3]) / TEXTURE_PERIOD_M["rock"]
    return Mesh(verts, uv, vertex_normals(verts, tris), tris.ravel())


def strip_mesh(centre_xy_m: FloatArray, normal_xy: FloatArray, s_m: FloatArray, half_width_m: float,
               z_m: FloatArray, period_m: float) -> Mesh:
    """Ribbon along a path: (K, 2) centres, (K, 2) left normals, (K,) arc lengths, (K, 2) left/right z."""
    left = centre_xy_m + half_width_m * normal_xy
    right = centre_xy_m - half_width_m * normal_xy
    verts = np.stack([np.column_stack([right, z_m[:, 1]]), np.column_stack([left, z_m[:, 0]])], 1).reshape(-1, 3)
    uv = np.stack([np.column_stack([np.zeros_like(s_m), s_m / period_m]),
                   np.column_stack([np.ones_like(s_m), s_m / period_m])], 1).reshape(-1, 2)
    k = np.arange(len(s_m) - 1)[:, None] * 2
    tris = np.concatenate([k + np.array([0, 2, 1]), k + np.array([1, 2, 3])], axis=1)
    return Mesh(verts, uv, np.tile([0.0, 0.0, 1.0], (len(verts), 1)), tris.ravel())


def polygon_mesh(outline_xy_m: FloatArray, z_m: float) -> Mesh:
    """Flat fan over a star-shaped (K, 2) CCW outline around its mean, normal up, UV 0."""
    centre = outline_xy_m.mean(axis=0)
    verts = np.vstack([np.append(centre, z_m), np.column_stack([outline_xy_m, np.full(len(outline_xy_m), z_m)])])
    k = np.arange(1, len(outline_xy_m) + 1)
    tris = np.stack([np.zeros_like(k), k, k % len(outline_xy_m) + 1], 1)
    return Mesh(verts, np.zeros((len(verts), 2)), np.tile([0.0, 0.0, 1.0], (len(verts), 1)), tris.ravel())
