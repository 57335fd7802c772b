"""Triangle meshes of the room structure: floor, ceiling, walls, doors and windows.

Pure numpy. Each structural part is one annotated element in the S3DIS output (``floor_1``,
``ceiling_1``, ``wall_<i>`` for polygon edge i, ``door_<k>``, ``window_<k>``). Openings are cut
out of their wall and filled by a panel in the wall plane, so the room stays closed for the
scanner.
"""
from dataclasses import dataclass

import numpy as np

from generator.layout import RoomLayout, partition_names
from synthdet.geometry import grid_cells


@dataclass
class PartMesh:
    """Triangles of one annotated element of the structure, in world coordinates."""

    instance: str
    cls: str
    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int32
    colors: np.ndarray  # (T, 3) uint8


def _quads_to_mesh(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quads (Q, 4, 3), corners in order -> vertices (4Q, 3) and triangles (2Q, 3)."""
    q = len(corners)
    vertices = corners.reshape(-1, 3)
    base = np.arange(q, dtype=np.int32)[:, None] * 4
    triangles = np.concatenate(
        [base + np.array([0, 1, 2], np.int32), base + np.array([0, 2, 3], np.int32)], axis=0)
    return vertices, triangles


def _horizontal(polygon: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray]:
    bounds = [(*cell.min(axis=0), *cell.max(axis=0)) for cell in grid_cells(polygon)]
    corners = np.array([[[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]
                        for x0, y0, x1, y1 in bounds],
                       dtype=float)
    return _quads_to_mesh(corners)


def _wall_cells(length: float, height: float, openings) -> tuple[list, list]:
    """Grid cells (u0, z0, u1, z1) of a wall: plain ones and, per opening index, the cut ones."""
    us = sorted({0.0, length, *[v for o in openings for v in (o.u0, o.u1)]})
    zs = sorted({0.0, height, *[v for o in openings for v in (o.z0, o.z1)]})
    plain, cut = [], []
    for u0, u1 in zip(us[:-1], us[1:]):
        for z0, z1 in zip(zs[:-1], zs[1:]):
            uc, zc = (u0 + u1) / 2, (z0 + z1) / 2
            owner = next(
                (k for k, o in enumerate(openings) if o.u0 < uc < o.u1 and o.z0 < zc < o.z1), None)
            (plain if owner is None else cut).append((u0, z0, u1, z1, owner))
    return plain, cut


def opening_names(layout: RoomLayout) -> list[str]:
    """Annotation names of the openings, numbered per kind in layout order (door_1, ...)."""
    counters: dict[str, int] = {}
    names = []
    for opening in layout.openings:
        counters[opening.kind] = counters.get(opening.kind, 0) + 1
        names.append(f'{opening.kind}_{counters[opening.kind]}')
    return names


def structure_parts(layout: RoomLayout, rng: np.random.Generator) -> list[PartMesh]:
    """Floor, ceiling, one part per wall, and one panel per door/window, with plain colors."""
    polygon, height = layout.polygon, layout.height
    grey = int(rng.integers(90, 150))
    floor_rgb = np.array([grey, grey - int(rng.integers(0, 10)), grey - int(rng.integers(0, 20))])
    wall_rgb = rng.integers(185, 235, size=3)
    ceiling_rgb = rng.integers(215, 250, size=3)
    parts = []
    for name, z, rgb in (('floor_1', 0.0, floor_rgb), ('ceiling_1', height, ceiling_rgb)):
        vertices, triangles = _horizontal(polygon, z)
        colors = np.tile(rgb.astype(np.uint8), (len(triangles), 1))
        parts.append(PartMesh(name, name.split('_')[0], vertices, triangles, colors))
    names = opening_names(layout)
    for wall in range(len(polygon)):
        p0, p1 = polygon[wall], polygon[(wall + 1) % len(polygon)]
        length = float(np.linalg.norm(p1 - p0))
        direction = (p1 - p0) / length
        openings = [(name, o) for name, o in zip(names, layout.openings) if o.wall == wall]
        plain, cut = _wall_cells(length, height, [o for _, o in openings])

        def corners(cells):
            out = []
            for u0, z0, u1, z1, _ in cells:
                a, b = p0 + direction * u0, p0 + direction * u1
                out.append([[a[0], a[1], z0], [b[0], b[1], z0], [b[0], b[1], z1], [a[0], a[1],
                                                                                   z1]])
            return np.array(out, dtype=float)

        vertices, triangles = _quads_to_mesh(corners(plain))
        parts.append(
            PartMesh(f'wall_{wall + 1}', 'wall', vertices, triangles,
                     np.tile(wall_rgb.astype(np.uint8), (len(triangles), 1))))
        for k, (name, opening) in enumerate(openings):
            rgb = (
                rng.integers(60, 140, size=3) if opening.kind == 'door' else
                np.array([150, 190, 215]) + rng.integers(-15, 15, size=3))
            vertices, triangles = _quads_to_mesh(corners([c for c in cut if c[4] == k]))
            parts.append(
                PartMesh(name, opening.kind, vertices, triangles,
                         np.tile(rgb.astype(np.uint8), (len(triangles), 1))))
    for name, partition in zip(partition_names(layout), layout.partitions):
        vertices, triangles = _partition_mesh(partition, height)
        parts.append(
            PartMesh(name, 'wall', vertices, triangles,
                     np.tile(wall_rgb.astype(np.uint8), (len(triangles), 1))))
    return parts


def _partition_mesh(partition, height: float) -> tuple[np.ndarray, np.ndarray]:
    """The two full-height pieces of a hall's partition wall, either side of its passage."""
    length = float(np.linalg.norm(partition.end - partition.start))
    direction = (partition.end - partition.start) / length
    quads = []
    for u0, u1 in ((0.0, partition.u0), (partition.u1, length)):
        a, b = partition.start + direction * u0, partition.start + direction * u1
        quads.append([[a[0], a[1], 0.0], [b[0], b[1], 0.0], [b[0], b[1], height],
                      [a[0], a[1], height]])
    return _quads_to_mesh(np.array(quads, dtype=float))
