"""The parts the laser scanner, tablet and depth-frame sensor models share: the room as they see
it (floor polygon, height, cells, object bounds), clearances, the cast of a grid of rays and its
depth edges, the dropouts of dark and shiny triangles, and the labelled result of a scan.

A depth edge lies between two neighbouring beams of a grid whose ranges differ by more than a
jump, on different parts, one of them an object (not room structure): the laser scanner
(:mod:`generator.tls`) mixes returns there, the depth frame (:mod:`generator.depth_frame`) loses
them.
"""
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numba
import numpy as np

from generator.scanner import (NO_STRAY, ScanResult, Scanner, TriangleScene, label_returns,
                               part_bounds, triangles_of_colors)
from synthdet.geometry import grid_cells

# the room's structure; every other part is an object (kept clear of, edges for mixed pixels)
ROOM_STRUCTURE = ('floor', 'ceiling', 'wall', 'door', 'window')


@dataclass
class RoomGeometry:
    """What the sensors need of a room: its floor polygon, height, cells and obstacles."""

    polygon: np.ndarray  # (K, 2) clockwise
    height: float
    bays: list[np.ndarray]  # rectangles (4, 2) of a hall's bays; empty for a room
    obstacles: np.ndarray  # (M, 2, 2) xy bounds [low, high] of every object
    object_parts: np.ndarray  # (P,) bool per part of the scene: an object, not room structure

    @property
    def cells(self) -> list[np.ndarray]:
        """The bays of a hall, else the grid cells of the room (one for a box room)."""
        return self.bays or grid_cells(self.polygon)


def room_geometry(polygon: np.ndarray, height: float, bays: list[np.ndarray], scene: TriangleScene,
                  classes: Sequence[str]) -> RoomGeometry:
    """The :class:`RoomGeometry` of a scene whose parts have ``classes``."""
    object_parts = np.array([cls not in ROOM_STRUCTURE for cls in classes], dtype=bool)
    low, high = part_bounds(scene, np.flatnonzero(object_parts))
    meshed = np.isfinite(low[:, 0])  # parts without triangles have no bounds
    obstacles = np.stack([low[meshed, :2], high[meshed, :2]], axis=1)
    return RoomGeometry(polygon, height, bays, obstacles, object_parts)


def obstacle_clearance(xy: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
    """Distance (N,) from each point to the nearest obstacle box (inf without obstacles)."""
    if len(obstacles) == 0:
        return np.full(len(xy), np.inf)
    below = obstacles[None, :, 0, :] - xy[:, None, :]
    above = xy[:, None, :] - obstacles[None, :, 1, :]
    gap = np.maximum(np.maximum(below, above), 0.0)
    return np.sqrt((gap**2).sum(axis=2)).min(axis=1)


def inset_cell(cell: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Low and high corners of ``cell`` moved ``margin`` inwards (at most 30 % of a side)."""
    low, high = cell.min(axis=0), cell.max(axis=0)
    margin = np.minimum(margin, 0.3 * (high - low))
    return low + margin, high - margin


def cast_grid(scanner: Scanner,
              rays: Callable[[int, int], tuple[np.ndarray, np.ndarray]],
              size: int,
              batch: int,
              rng: np.random.Generator,
              min_range: float,
              max_range: float,
              out: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """First hits of ``size`` rays in batches, ``rays(start, stop)`` giving the origins and
    directions of rays start to stop: ranges (float64; inf for a miss and outside
    [min_range, max_range]) and triangle index (int32, half the memory of int64; 0 for a miss,
    so that per-triangle lookups of a whole grid stay in bounds; the range tells), written into
    ``out`` (two arrays of ``size`` or more) when given."""
    if out is None:
        ranges, triangle = np.empty(size), np.empty(size, np.int32)
    else:
        ranges, triangle = out[0][:size], out[1][:size]
    for start in range(0, size, batch):
        stop = min(start + batch, size)
        t_hit, primitive = scanner.cast(scanner.full_scene, *rays(start, stop), rng)
        _store_hits(t_hit, primitive, min_range, max_range, ranges[start:stop],
                    triangle[start:stop])
    return ranges, triangle


@numba.njit(cache=True, nogil=True)
def _store_hits(t_hit: np.ndarray, primitive: np.ndarray, min_range: float, max_range: float,
                ranges: np.ndarray, triangle: np.ndarray) -> None:
    """Write a batch's hit distances (float32) into ``ranges`` as float64, inf outside
    [min_range, max_range], and its triangles into ``triangle`` (0 for a miss)."""
    for ray in range(len(t_hit)):
        value = np.float64(t_hit[ray])
        ranges[ray] = np.inf if value < min_range or value > max_range else value
        triangle[ray] = primitive[ray] if np.isfinite(t_hit[ray]) else 0


@numba.njit(cache=True, nogil=True, inline='always')
def _steep(mine: float, theirs: float, jump: float) -> bool:
    """Whether two finite neighbouring ranges differ by more than ``jump``."""
    gap = abs(theirs - mine)
    return gap > jump and gap < np.inf


@numba.njit(cache=True, nogil=True)
def depth_edges(ranges: np.ndarray, triangle: np.ndarray, columns: int, on_object: np.ndarray,
                part: np.ndarray,
                jump: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The beams (ascending) of a grid (flattened, ``columns`` azimuths per row) at an object
    edge, with the range and triangle of the neighbour across the largest range step. The
    neighbours in this order: azimuth - 1 and + 1 (wrapping around), elevation - 1 and + 1; a
    later one replaces an earlier one only with a larger step.

    Row by row: first, without branches, the beams with a range step over ``jump`` to some
    neighbour (a small share of a grid); then the triangles of those only."""
    size = len(ranges)
    rows = size // columns
    edges = np.empty(size, dtype=np.int64)
    other = np.empty(size)
    other_tri = np.empty(size, dtype=triangle.dtype)
    steep = np.empty(columns, dtype=np.bool_)
    count = 0
    for row in range(rows):
        first = row * columns
        # the rows above and below (the row itself at the grid's border: no step)
        below = first - columns if row > 0 else first
        above = first + columns if row < rows - 1 else first
        for column in range(columns):
            mine = ranges[first + column]
            left = ranges[first + (column - 1 if column > 0 else columns - 1)]
            right = ranges[first + (column + 1 if column < columns - 1 else 0)]
            steep[column] = (_steep(mine, left, jump) | _steep(mine, right, jump)
                             | _steep(mine, ranges[below + column], jump)
                             | _steep(mine, ranges[above + column], jump))
        for column in range(columns):
            if not steep[column]:
                continue
            beam = first + column
            mine = ranges[beam]
            mine_on_object = on_object[triangle[beam]]
            largest = 0.0
            for side in range(4):
                if side == 0:
                    neighbour = beam - 1 if column > 0 else beam + columns - 1
                elif side == 1:
                    neighbour = beam + 1 if column < columns - 1 else beam - columns + 1
                elif side == 2:
                    if row == 0:
                        continue
                    neighbour = beam - columns
                else:
                    if row == rows - 1:
                        continue
                    neighbour = beam + columns
                theirs = ranges[neighbour]
                gap = abs(theirs - mine)
                if not (gap > jump and gap > largest and gap < np.inf):
                    continue
                their_tri = triangle[neighbour]
                if not (mine_on_object or on_object[their_tri]):
                    continue
                if part[their_tri] == part[triangle[beam]]:
                    continue
                largest, other[count], other_tri[count] = gap, theirs, their_tri
            if largest > 0:
                edges[count] = beam
                count += 1
    return edges[:count].copy(), other[:count].copy(), other_tri[:count].copy()


@numba.njit(cache=True, nogil=True)
def rows_of(table: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Row ``index[k]`` of ``table`` (M, 3) for every k (where each return was seen from): one
    pass, faster than ``np.take`` along an axis."""
    rows = np.empty((len(index), 3), dtype=table.dtype)
    for k in range(len(index)):
        for axis in range(3):
            rows[k, axis] = table[index[k], axis]
    return rows


def surface_loss(scanner: Scanner, cfg: Mapping[str, Any],
                 shiny_colors: Sequence[Sequence[int]]) -> np.ndarray:
    """Per triangle: the probability that a return on it is lost, ``dark_dropout`` when its
    color's luminance is below ``dark_luminance``, at least ``shiny_dropout`` when its color is
    one of ``shiny_colors``, else 0."""
    colors = scanner.scene.colors.astype(np.float64)
    luminance = colors @ np.array([0.2126, 0.7152, 0.0722])
    loss = np.where(luminance < cfg['dark_luminance'], cfg['dark_dropout'], 0.0)
    shiny = triangles_of_colors(scanner.scene, shiny_colors)
    return np.where(shiny, np.maximum(loss, cfg['shiny_dropout']), loss)


def labelled_result(scanner: Scanner,
                    xyz: np.ndarray,
                    triangle: np.ndarray,
                    origin: np.ndarray,
                    rays: int,
                    stray: np.ndarray | None = None) -> ScanResult:
    """Label the returns by their triangles; ``origin`` (N, 3): where each was seen from;
    ``stray`` (N,): returns between two surfaces, which count as no object's points."""
    scene = scanner.scene
    rgb = np.empty((len(triangle), 3), dtype=np.uint8)
    part = np.empty(len(triangle), dtype=np.int32)
    triangles = np.empty(len(triangle), dtype=np.int64)
    object_points = label_returns(triangle, scene.colors, scene.part, scanner.movable_tri,
                                  NO_STRAY if stray is None else stray, rgb, part,
                                  triangles)
    return ScanResult(
        xyz=xyz.astype(np.float64, copy=False),
        rgb=rgb,
        part=part,
        triangle=triangles,
        origin=origin.astype(np.float32, copy=False),
        rays_cast=int(rays),
        object_points=object_points,
        stray=stray)
