"""Visual shapes from triangle arrays, as in-memory meshes (TinyRenderer) or as OBJ files (the EGL renderer).

Owns `mesh_visual_shape` and the clients that draw through OBJ files. pybullet 3.2.7's EGL plugin converts no
in-memory mesh (createVisualShape(vertices=...)): it warns "issue extracting mesh" and the next createMultiBody
segfaults (measured). So a client with the plugin loaded (`Camera` registers it) gets each mesh written to an OBJ
file named by its content's hash, in one temporary directory per process (removed at exit), read when its bodies
are created and deleted by `remove_mesh_files` once the world is built. A file name always means the same mesh:
the plugin keeps every OBJ file it loaded in a cache by name, for the life of the process (its own copy of Bullet's
cache: `enableFileCaching=0` does not reach it), so the same mesh again costs nothing and a new one ~its size
(measured: +4 MB RSS per desert world never built before, +0.1 MB per reset of one world; `Camera`).
"""

from __future__ import annotations

import atexit
import hashlib
import io
import shutil
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade_gym.sim.bullet_lists import bullet_list

_OBJ_CLIENTS: set[int] = set()
_OBJ_DIR: list[Path] = []  # the process's directory, made on first use
_WRITTEN: dict[int, set[Path]] = {}  # per client, the files its bodies may still need


def draw_meshes_from_files(client_id: int, enabled: bool) -> None:
    """From now on, build `client_id`'s mesh visual shapes from OBJ files (enabled) or from memory."""
    (_OBJ_CLIENTS.add if enabled else _OBJ_CLIENTS.discard)(int(client_id))
    if not enabled:
        remove_mesh_files(client_id)


def remove_mesh_files(client_id: int) -> None:
    """Delete the OBJ files written for `client_id` (call once its bodies are created: they are read then)."""
    for path in _WRITTEN.pop(int(client_id), set()):
        path.unlink(missing_ok=True)


def mesh_visual_shape(client_id: int, vertices_m: npt.ArrayLike, indices: npt.ArrayLike, uvs: npt.ArrayLike,
                      normals: npt.ArrayLike, rgba: tuple[float, float, float, float] | None = None) -> int:
    """Visual shape of triangles `indices` (3M,) over `vertices_m` (N, 3) [m] with `uvs` (N, 2) and unit `normals`
    (N, 3); with `rgba` a uniform colour (in memory the UVs are then left out, as TinyRenderer had them)."""
    colour = {} if rgba is None else {"rgbaColor": list(rgba)}
    if int(client_id) in _OBJ_CLIENTS:
        path = _obj_file(vertices_m, indices, uvs, normals)
        _WRITTEN.setdefault(int(client_id), set()).add(path)
        return p.createVisualShape(p.GEOM_MESH, fileName=str(path), physicsClientId=client_id, **colour)
    uv = {} if rgba is not None else {"uvs": bullet_list("uvs", np.asarray(uvs).reshape(-1, 2))}
    return p.createVisualShape(p.GEOM_MESH, vertices=bullet_list("vertices", np.asarray(vertices_m).reshape(-1, 3)),
                               indices=bullet_list("indices", np.asarray(indices).ravel()),
                               normals=bullet_list("normals", np.asarray(normals).reshape(-1, 3)),
                               physicsClientId=client_id, **uv, **colour)


def obj_text(vertices_m: npt.ArrayLike, indices: npt.ArrayLike, uvs: npt.ArrayLike, normals: npt.ArrayLike) -> str:
    """Wavefront OBJ of the mesh: vertex i has position, UV and normal i (1-based `f i/i/i` faces)."""
    out = io.StringIO()
    np.savetxt(out, np.asarray(vertices_m, dtype=np.float64).reshape(-1, 3), fmt="v %.9g %.9g %.9g")
    np.savetxt(out, np.asarray(uvs, dtype=np.float64).reshape(-1, 2), fmt="vt %.9g %.9g")
    np.savetxt(out, np.asarray(normals, dtype=np.float64).reshape(-1, 3), fmt="vn %.9g %.9g %.9g")
    faces = np.repeat(np.asarray(indices, dtype=np.int64).reshape(-1, 3) + 1, 3, axis=1)
    np.savetxt(out, faces, fmt="f %d/%d/%d %d/%d/%d %d/%d/%d")
    return out.getvalue()


def _obj_file(vertices_m, indices, uvs, normals) -> Path:
    text = obj_text(vertices_m, indices, uvs, normals).encode()
    if not _OBJ_DIR:
        _OBJ_DIR.append(Path(tempfile.mkdtemp(prefix="trade_gym_meshes_")))
        atexit.register(shutil.rmtree, _OBJ_DIR[0], ignore_errors=True)
    path = _OBJ_DIR[0] / f"{hashlib.sha1(text).hexdigest()}.obj"
    if not path.exists():
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(text)
        tmp.replace(path)
    return path
