"""A :class:`~mrslam_core.sim.world.World` turned into pybullet bodies with textured meshes.

pybullet's box visual maps one texture onto a cube atlas, so each face shows a small, stretched
part of it. Here every piece is a mesh whose texture coordinates are laid out in metres
(the side faces unrolled around the perimeter, the top below them), so a texture of
``density`` texels per metre covers every face at that density, undistorted.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pybullet as p

from mrslam_core.sim.textures import plain_texture, repetitive_texture, unique_texture
from mrslam_core.sim.world import Solid, World


def box_mesh(hx: float, hy: float, hz: float, density: float):
    """Sides and top of a box centred at the origin, with texture coordinates in metres.

    Returns:
        vertices (20, 3) [m], normals (20, 3), uvs (20, 2) in [0, 1], indices (30,) (two
        counter-clockwise triangles per face seen from outside), texture size (rows, cols) [texels].
    """
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    normals2 = np.array([[0, -1], [1, 0], [0, 1], [-1, 0]], float)
    lengths = np.array([2 * hx, 2 * hy, 2 * hx, 2 * hy])
    u0 = np.concatenate([[0.0], np.cumsum(lengths)])
    verts, norms, uv = [], [], []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        n3 = [normals2[k, 0], normals2[k, 1], 0.0]
        verts += [[a[0], a[1], -hz], [b[0], b[1], -hz], [b[0], b[1], hz], [a[0], a[1], hz]]
        norms += [n3] * 4
        uv += [[u0[k], 2 * hz], [u0[k + 1], 2 * hz], [u0[k + 1], 0.0], [u0[k], 0.0]]
    verts += [[-hx, -hy, hz], [hx, -hy, hz], [hx, hy, hz], [-hx, hy, hz]]
    norms += [[0.0, 0.0, 1.0]] * 4
    uv += [[0.0, 2 * hz + 2 * hy], [2 * hx, 2 * hz + 2 * hy], [2 * hx, 2 * hz], [0.0, 2 * hz]]
    rows = int(np.ceil((2 * hz + 2 * hy) * density))
    cols = int(np.ceil(max(u0[-1], 2 * hx) * density))
    uvs = np.asarray(uv) * density / np.array([cols, rows])
    quads = np.arange(5)[:, None] * 4
    indices = (quads + np.array([0, 1, 2, 0, 2, 3])).ravel()
    return np.asarray(verts), np.asarray(norms), uvs, indices, (rows, cols)


def _texture_image(kind: str, shape: tuple[int, int], rng: np.random.Generator, density: float) -> np.ndarray:
    if kind == "repetitive":
        return repetitive_texture(shape[0], shape[1], density)
    if kind == "plain":
        return plain_texture(shape[0], shape[1], int(rng.integers(150, 230)))
    return unique_texture(shape[0], shape[1], rng, density)


def _load_texture(client: int, img: np.ndarray, folder: Path, name: str) -> int:
    path = folder / f"{name}.bmp"
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    return p.loadTexture(str(path), physicsClientId=client)


def _mesh_body(client: int, verts, norms, uvs, indices, position, yaw: float, half_extents=None) -> int:
    vis = p.createVisualShape(p.GEOM_MESH, vertices=verts.tolist(), normals=norms.tolist(), uvs=uvs.tolist(),
                              indices=indices.tolist(), rgbaColor=[1, 1, 1, 1], specularColor=[0, 0, 0],
                              physicsClientId=client)
    col = -1
    if half_extents is not None:
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half_extents), physicsClientId=client)
    return p.createMultiBody(0, col, vis, list(position), p.getQuaternionFromEuler([0, 0, yaw]),
                             physicsClientId=client)


def build_scene(client: int, world: World, seed: int, density: float, folder: Path) -> list[int]:
    """Create the floor and every solid of ``world`` (cut into ≤ 1.5 m pieces) in ``client``.

    Each piece is one static body with a box collision shape and a textured mesh. Textures come
    from ``np.random.default_rng([seed, kind, piece])``, so a world looks the same for a seed
    whatever else happens; BMP files go to ``folder`` (pybullet loads textures from files; an
    uncompressed file writes and loads in a third of a PNG's time, texel for texel the same).

    Returns:
        the body ids, floor first.
    """
    sx, sy = world.size
    floor_density = density
    rows, cols = int(np.ceil(sy * floor_density)), int(np.ceil(sx * floor_density))
    verts = np.array([[0, 0, 0], [sx, 0, 0], [sx, sy, 0], [0, sy, 0]], float)
    uvs = np.array([[0, 0], [sx, 0], [sx, sy], [0, sy]]) * floor_density / np.array([cols, rows])
    floor = _mesh_body(client, verts, np.tile([0.0, 0.0, 1.0], (4, 1)), uvs, np.array([0, 1, 2, 0, 2, 3]),
                       (0, 0, 0), 0.0)
    img = unique_texture(rows, cols, np.random.default_rng([seed, 0, 0]), floor_density)
    p.changeVisualShape(floor, -1, textureUniqueId=_load_texture(client, img, folder, "floor"), physicsClientId=client)
    bodies = [floor]
    piece: Solid
    for k, piece in enumerate(world.pieces()):
        hz = piece.height / 2
        v, n, uv, idx, shape = box_mesh(piece.half[0], piece.half[1], hz, density)
        body = _mesh_body(client, v, n, uv, idx, (piece.centre[0], piece.centre[1], hz), piece.yaw,
                          (piece.half[0], piece.half[1], hz))
        img = _texture_image(piece.texture, shape, np.random.default_rng([seed, 1, k]), density)
        p.changeVisualShape(body, -1, textureUniqueId=_load_texture(client, img, folder, f"piece{k}"),
                            physicsClientId=client)
        bodies.append(body)
    return bodies
