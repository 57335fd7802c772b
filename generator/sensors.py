"""Sensor models on the Embree caster: the paper's crossing path, a terrestrial laser scanner
(TLS) and a handheld tablet LiDAR, chosen per room.

Every model builds ray batches (origins, directions) and casts them through
:meth:`generator.scanner.Scanner.cast`, the one place rays are cast. The paper model is
:meth:`Scanner.scan` on :func:`generator.scanner.sensor_path` (object-ratio phase, uniform or
aimed directions). The TLS and the tablet have no object-ratio phase: the share of object points
is what the geometry gives.

- TLS: stations on a tripod (one or more per grid cell or hall bay, away from objects), beams on a
  regular azimuth x elevation grid of ``angular_step_deg`` (chosen from the point budget when not
  set), the merged returns thinned to one per ``point_spacing`` cube (the export's spacing
  filter), a range window, range noise of std ``a + b * d`` and mixed pixels at depth edges (where
  a neighbouring beam's hit lies more than ``edge_jump`` off the plane of a beam's hit, a share
  of the returns lands between the foreground and the background). Those mixed returns lie in
  the air, on no surface: they are marked ``stray`` and annotated as a clutter instance of their
  own (:func:`label_stray_returns`), as an annotator would not give them to the object, whose
  box they would stretch towards the background.
- Tablet: a smooth walk around every cell at hand height that steps around objects, the device
  facing the walls for most of the walk and the room's inside or the way ahead for the rest
  (swaying left and right, tilting up and down), returns only between ``min_range`` and
  ``max_range``, range noise, fewer returns far away and dropouts on dark triangles (luminance of
  the color below ``dark_luminance``) and shiny ones (colors of the metal palette).
- Depth frame: one frame of an RGB-D camera (Kinect-like, as a SUN RGB-D view): one pose near a
  wall or in a corner, clear of objects, looking into the room and pitched down, a pinhole
  pixel grid of the field of view, returns only between ``min_range`` and ``max_range``, depth
  noise of std ``a + b * depth**2``, returns lost at depth edges and on dark and shiny
  triangles; objects left with fewer than ``min_object_points`` returns lose them.
"""
import math
import warnings
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numba
import numpy as np

from generator.scanner import (ScanResult, Scanner, TriangleScene, part_bounds, row_norms,
                               sensor_path, triangles_of_colors)
from synthdet.contracts import SENSOR_MODELS
from synthdet.geometry import distance_to_polygon, grid_cells, points_in_polygon

# an empty index array
_NONE = np.zeros(0, dtype=np.int64)
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


def choose_sensor(probabilities: Mapping[str, float], rng: np.random.Generator) -> str:
    """Draw one sensor model from ``probabilities`` (model -> probability, summing to 1)."""
    weights = np.array([float(probabilities.get(m, 0.0)) for m in SENSOR_MODELS])
    return SENSOR_MODELS[int(rng.choice(len(SENSOR_MODELS), p=weights / weights.sum()))]


def scan_room(
    scanner: Scanner,
    room: RoomGeometry,
    model: str,
    n_points: int,
    object_ratio: float,
    rng: np.random.Generator,
    scanner_config: Mapping[str, Any],
    shiny_colors: Sequence[Sequence[int]] = ()
) -> tuple[ScanResult, dict[str, Any]]:
    """Scan ``room`` with sensor ``model``; return the points and the sensor's meta.json record.

    ``object_ratio`` applies to the paper model only; ``shiny_colors`` (RGB triples) mark the
    triangles the tablet loses returns on as shiny.
    """
    if model == 'paper':
        cfg = scanner_config
        # a hall gets a cross per bay, with as many sensor positions per bay as a room
        path, segments = sensor_path(room.polygon, room.height, rng, cfg['path_coverage'],
                                     cfg['sensor_height'],
                                     cfg['path_steps'] * max(1, len(room.bays)), room.cells)
        scan = scanner.scan(path, n_points, object_ratio, rng, cfg)
        return scan, {
            'model': 'paper',
            'path': np.round(segments, 6).tolist(),
            'height': round(cfg['sensor_height'] * room.height, 6),
            **{
                k: cfg[k]
                for k in ('aim_at_objects', 'range_noise', 'angular_jitter', 'dropout')
            }
        }
    if model == 'tls':
        cfg = scanner_config['tls']
        stations = tls_stations(room, rng, cfg)
        scan, step = scan_tls(scanner, stations, n_points, rng, cfg, scanner_config['batch_rays'],
                              room.object_parts[scanner.scene.part])
        return scan, {
            'model': 'tls',
            'stations': np.round(stations, 6).tolist(),
            'angular_step_deg': step,
            **{
                k: cfg[k]
                for k in ('min_elevation_deg', 'min_range', 'max_range', 'range_noise',
                          'mixed_pixels', 'edge_jump', 'oversample', 'point_spacing')
            }
        }
    if model == 'tablet':
        cfg = scanner_config['tablet']
        positions, look = tablet_trajectory(room, rng, cfg)
        scan, _ = cast_tablet(scanner, positions, look, n_points, rng, cfg,
                              scanner_config['batch_rays'], shiny_colors)
        return scan, {
            'model': 'tablet',
            'trajectory': np.round(positions, 3).tolist(),
            **{
                k: cfg[k]
                for k in ('wall_look', 'fov_deg', 'min_range', 'max_range', 'range_noise',
                          'far_keep', 'dark_luminance', 'dark_dropout', 'shiny_dropout')
            }
        }
    if model == 'depth_frame':
        cfg = scanner_config['depth_frame']
        camera = depth_frame_camera(room, rng, cfg)
        scan, record = cast_depth_frame(scanner, camera, n_points, rng, cfg,
                                        scanner_config['batch_rays'], room.object_parts,
                                        shiny_colors)
        return scan, {
            'model': 'depth_frame',
            **record,
            **{
                k: cfg[k]
                for k in ('min_range', 'depth_noise', 'edge_jump', 'edge_dropout',
                          'dark_luminance', 'dark_dropout', 'shiny_dropout',
                          'min_object_points')
            }
        }
    raise ValueError(f'unknown sensor model {model!r} (known: {", ".join(SENSOR_MODELS)})')


def _clearance(xy: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
    """Distance (N,) from each point to the nearest obstacle box (inf without obstacles)."""
    if len(obstacles) == 0:
        return np.full(len(xy), np.inf)
    below = obstacles[None, :, 0, :] - xy[:, None, :]
    above = xy[:, None, :] - obstacles[None, :, 1, :]
    gap = np.maximum(np.maximum(below, above), 0.0)
    return np.sqrt((gap**2).sum(axis=2)).min(axis=1)


def _inset(cell: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Low and high corners of ``cell`` moved ``margin`` inwards (at most 30 % of a side)."""
    low, high = cell.min(axis=0), cell.max(axis=0)
    margin = np.minimum(margin, 0.3 * (high - low))
    return low + margin, high - margin


def tls_stations(room: RoomGeometry, rng: np.random.Generator,
                 cfg: Mapping[str, Any]) -> np.ndarray:
    """Tripod positions (S, 3): ``stations_per_cell`` per cell, ``object_clearance`` from objects
    when possible (else the clearest of the candidates), ``wall_clearance`` from the cell's
    sides, at a height drawn from ``height``."""
    stations = []
    for cell in room.cells:
        low, high = _inset(cell, cfg['wall_clearance'])
        for _ in range(
                int(rng.integers(cfg['stations_per_cell'][0], cfg['stations_per_cell'][1] + 1))):
            candidates = low + rng.random((64, 2)) * (high - low)
            clearance = _clearance(candidates, room.obstacles)
            free = np.flatnonzero(clearance >= cfg['object_clearance'])
            xy = candidates[free[0] if len(free) else int(np.argmax(clearance))]
            stations.append([xy[0], xy[1], rng.uniform(*cfg['height'])])
    return np.array(stations, dtype=np.float64)


def tls_grid(step_deg: float, min_elevation_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths and elevations (radians) of the beam grid: multiples of the step, elevations from
    ``min_elevation_deg`` up to below the zenith."""
    n_azimuth = int(round(360.0 / step_deg))
    azimuth = np.arange(n_azimuth) * step_deg
    first, last = math.ceil(min_elevation_deg / step_deg - 1e-9), math.ceil(90.0 / step_deg) - 1
    elevation = np.arange(first, last + 1) * step_deg
    return np.radians(azimuth), np.radians(elevation)


def _angle_tables(azimuth: np.ndarray,
                  elevation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cosines and sines of the grid's elevations and azimuths (numpy's, computed once)."""
    return np.cos(elevation), np.sin(elevation), np.cos(azimuth), np.sin(azimuth)


@numba.njit(cache=True, nogil=True)
def _grid_directions(cos_elevation: np.ndarray, sin_elevation: np.ndarray,
                     cos_azimuth: np.ndarray, sin_azimuth: np.ndarray) -> np.ndarray:
    """Unit directions (E * A, 3) of the grid, elevation-major, as the float32 rays Embree casts.

    Each component is the float64 product of an elevation's and an azimuth's cosine or sine
    (:func:`_grid_points` recomputes the same products for the returns), rounded to float32."""
    columns = len(cos_azimuth)
    directions = np.empty((len(cos_elevation) * columns, 3), dtype=np.float32)
    for row in range(len(cos_elevation)):
        for column in range(columns):
            beam = row * columns + column
            directions[beam, 0] = cos_elevation[row] * cos_azimuth[column]
            directions[beam, 1] = cos_elevation[row] * sin_azimuth[column]
            directions[beam, 2] = sin_elevation[row]
    return directions


def _cast_grid(scanner: Scanner, origins: np.ndarray, directions: np.ndarray, batch: int,
               rng: np.random.Generator, min_range: float,
               max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """First hits of many rays in batches: ranges (float64; inf for a miss and outside
    [min_range, max_range]) and triangle index (int32, half the memory of int64; 0 for a miss,
    so that per-triangle lookups of a whole grid stay in bounds; the range tells)."""
    ranges = np.empty(len(origins))
    triangle = np.empty(len(origins), np.int32)
    for start in range(0, len(origins), batch):
        stop = start + batch
        t_hit, primitive = scanner.cast(scanner.full_scene, origins[start:stop],
                                        directions[start:stop], rng)
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


@numba.njit(cache=True, nogil=True)
def _depth_edges(ranges: np.ndarray, triangle: np.ndarray, columns: int, on_object: np.ndarray,
                 part: np.ndarray,
                 jump: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The beams (ascending) of a grid (flattened, ``columns`` azimuths per row) at an object
    edge, with the range and triangle of the neighbour across the largest range step. The
    neighbours in this order: azimuth - 1 and + 1 (wrapping around), elevation - 1 and + 1; a
    later one replaces an earlier one only with a larger step."""
    size = len(ranges)
    rows = size // columns
    edges = np.empty(size, dtype=np.int64)
    other = np.empty(size)
    other_tri = np.empty(size, dtype=triangle.dtype)
    count = 0
    for beam in range(size):
        mine = ranges[beam]
        if not np.isfinite(mine):  # a step from a lost beam is no edge
            continue
        row = beam // columns
        column = beam - row * columns
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


# uniform draws made at once by _uniform_at: a buffer that stays in the cache
_DRAW_CHUNK = 1 << 16


def _uniform_at(rng: np.random.Generator, size: int, index: np.ndarray) -> np.ndarray:
    """The values at ``index`` (ascending) of ``rng.random(size)``: the same numbers, and
    ``rng`` left in the same state, drawn in chunks into one small buffer instead of an array
    of ``size`` (a grid of millions of beams needs only the draws of its few edge beams)."""
    values = np.empty(len(index))
    buffer = np.empty(min(size, _DRAW_CHUNK))
    for start in range(0, size, _DRAW_CHUNK):
        count = min(_DRAW_CHUNK, size - start)
        rng.random(out=buffer[:count])
        low, high = np.searchsorted(index, (start, start + count))
        values[low:high] = buffer[index[low:high] - start]
    return values


def _mixed_pixels(rng: np.random.Generator, ranges: np.ndarray, triangle: np.ndarray,
                  on_object: np.ndarray, part: np.ndarray, share: float,
                  jump: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ranges, triangles and the mixed (stray) beams of one station's grid (E, A) after mixing
    at depth edges, each flattened (``ranges`` and ``triangle`` are changed in place).

    Two grid neighbours (azimuth wraps around) straddle a depth edge when their ranges differ by
    more than ``jump``, they hit different parts and one of them is an object (``on_object`` per
    triangle, ``part`` per triangle): the room's floor, walls and ceiling meet only in concave
    corners, and a surface seen at a grazing angle (a floor, a table top) has large range steps
    without an edge; edges of an object in front of itself are not modelled. A beam at an edge,
    with probability ``share``, returns a range a uniform fraction of the way to the neighbour's
    across the largest step, with the neighbour's triangle past half way.
    """
    columns = ranges.shape[1]
    ranges, triangle = ranges.reshape(-1), triangle.reshape(-1)
    edges, other, other_tri = _depth_edges(ranges, triangle, columns, on_object, part, jump)
    chosen = _uniform_at(rng, ranges.size, edges) < share
    mixed, other, other_tri = edges[chosen], other[chosen], other_tri[chosen]
    fraction = rng.random(len(mixed))
    ranges[mixed] += fraction * (other - ranges[mixed])
    far = fraction > 0.5
    triangle[mixed[far]] = other_tri[far]
    stray = np.zeros(ranges.size, dtype=bool)
    stray[mixed] = True
    return ranges, triangle, stray


@numba.njit(cache=True, nogil=True)
def _grid_points(station: np.ndarray, cos_elevation: np.ndarray, sin_elevation: np.ndarray,
                 cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, ranges: np.ndarray,
                 beams: np.ndarray, ordered: bool, order: np.ndarray) -> np.ndarray:
    """Points (N, 3) of ``beams`` (grid indices), ``ordered``: those of ``order`` (indices into
    ``beams``) in its order, else all in theirs, at their ranges."""
    columns = len(cos_azimuth)
    count = len(order) if ordered else len(beams)
    xyz = np.empty((count, 3))
    for k in range(count):
        index = order[k] if ordered else k
        beam = beams[index]
        measured = ranges[beam]
        row = beam // columns
        column = beam - row * columns
        xyz[k, 0] = station[0] + cos_elevation[row] * cos_azimuth[column] * measured
        xyz[k, 1] = station[1] + cos_elevation[row] * sin_azimuth[column] * measured
        xyz[k, 2] = station[2] + sin_elevation[row] * measured
    return xyz


def _add_range_noise(rng: np.random.Generator, ranges: np.ndarray, rows: np.ndarray, a: float,
                     b: float) -> None:
    """Move the range of each of ``rows`` by a standard normal draw x (a + b x range), in place:
    the draws of ``rng.standard_normal(len(rows))``, made in chunks into one small buffer."""
    buffer = np.empty(min(len(rows), _DRAW_CHUNK))
    for start in range(0, len(rows), _DRAW_CHUNK):
        count = min(_DRAW_CHUNK, len(rows) - start)
        rng.standard_normal(out=buffer[:count])
        _noisy_ranges(ranges, rows[start:start + count], buffer[:count], a, b)


@numba.njit(cache=True, nogil=True)
def _noisy_ranges(ranges: np.ndarray, rows: np.ndarray, noise: np.ndarray, a: float,
                  b: float) -> None:
    """``ranges[rows]`` += ``noise`` x (a + b x range), in place."""
    for k in range(len(rows)):
        measured = ranges[rows[k]]
        ranges[rows[k]] = measured + noise[k] * (a + b * measured)


class SpacingFilter:
    """The laser scanner export's spacing filter: keeps the first return of every cube of
    ``side`` metres across the stations, one station's returns after the other.

    The kept cubes' keys live in an open-addressing hash set that grows with them (memory grows
    with the kept cubes, not with the beams). A station's returns are keyed in beam order (the
    reads go forwards), then looked up in the station's random order, without an array of its
    points. The keys are those of
    :class:`synthdet.voxels.VoxelFilter` (cube coordinates relative to ``origin``'s cube, 21
    bits each), and returns too far for them (2**20 cubes away) are kept by their exact cube
    coordinates, so the two filters keep the same returns.
    """

    def __init__(self, side: float, origin: np.ndarray):
        self.side = float(side)
        self.origin_key = np.floor(origin / side)
        self.table = np.full(1 << 16, -1, dtype=np.int64)
        self.count = 0
        self.wide: set[tuple[int, int, int]] = set()  # cubes beyond the packed key range

    def new_returns(self, station: np.ndarray, angles: tuple[np.ndarray, ...],
                    ranges: np.ndarray, beams: np.ndarray, order: np.ndarray) -> np.ndarray:
        """Indices (ascending, into ``beams``) of the returns in cubes not seen before, the
        first in ``order`` of each (at the points :func:`_grid_points` computes)."""
        keys = _cube_keys(station, *angles, ranges, beams, self.side, self.origin_key)
        kept, far, self.table, self.count = _first_in_new_cubes(keys, order, self.table,
                                                                self.count)
        if len(far):  # points kilometres away: rare, kept exact
            points = _grid_points(station, *angles, ranges, beams, True, far)
            for index, point in zip(far.tolist(), points):
                key = tuple(int(v) for v in (np.floor(point / self.side) - self.origin_key))
                if key not in self.wide:
                    self.wide.add(key)
                    kept[index] = True
        return np.flatnonzero(kept)


@numba.njit(cache=True, nogil=True)
def _cube_slot(key: np.int64, bits: int) -> int:
    """A key's first slot in a hash table of 2**bits slots (Fibonacci hashing: the top bits of
    the key times 2**64 / golden ratio)."""
    return np.int64((np.uint64(key) * np.uint64(11400714819323198485)) >> np.uint64(64 - bits))


# returns whose keys and slots the spacing filter reads ahead of inserting them
_FILTER_BLOCK = 32


@numba.njit(cache=True, nogil=True)
def _add_cube(table: np.ndarray, bits: int, key: np.int64) -> bool:
    """Put ``key`` (>= 0) into the hash set ``table`` (-1: a free slot); whether it was new."""
    mask = (1 << bits) - 1
    slot = _cube_slot(key, bits)
    while True:
        held = table[slot]
        if held < 0:
            table[slot] = key
            return True
        if held == key:
            return False
        slot = (slot + 1) & mask


@numba.njit(cache=True, nogil=True)
def _cube_keys(station: np.ndarray, cos_elevation: np.ndarray, sin_elevation: np.ndarray,
               cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, ranges: np.ndarray,
               beams: np.ndarray, side: float, origin_key: np.ndarray) -> np.ndarray:
    """The packed cube key (N,) of each return of ``beams``, at its point as
    :func:`_grid_points` computes it, as :func:`synthdet.voxels._packed_keys` packs it: -1 for
    a point 2**20 cubes or more away. In the returns' order, so the reads go forwards."""
    columns = len(cos_azimuth)
    keys = np.empty(len(beams), dtype=np.int64)
    point = np.empty(3)
    for index in range(len(beams)):
        beam = beams[index]
        measured = ranges[beam]
        row = beam // columns
        column = beam - row * columns
        point[0] = station[0] + cos_elevation[row] * cos_azimuth[column] * measured
        point[1] = station[1] + cos_elevation[row] * sin_azimuth[column] * measured
        point[2] = station[2] + sin_elevation[row] * measured
        key = np.int64(0)
        for axis in range(3):
            cube = np.int64(np.floor(point[axis] / side) - origin_key[axis])
            if abs(cube) >= 2**20:
                key = np.int64(-1)
                break
            key = (key << 21) | (cube + 2**20)
        keys[index] = key
    return keys


@numba.njit(cache=True, nogil=True)
def _first_in_new_cubes(keys: np.ndarray, order: np.ndarray, table: np.ndarray,
                        count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The spacing filter's pass over one station's returns in ``order``: whether each return
    (N,) is the first of a cube key not in the hash set ``table``, the returns (in ``order``)
    without a packed key (-1), and the hash set (grown at half full) and its size after."""
    kept = np.zeros(len(keys), dtype=np.bool_)
    far = np.empty(len(order), dtype=np.int64)
    far_count = 0
    bits = 0
    while (1 << bits) < len(table):
        bits += 1
    # the returns go in blocks: first their keys and the keys in their first slots are read,
    # each read independent of the others, so that the memory serves many at once; then the
    # inserts, which skip a key found in its first slot (a key stays in the set)
    block_keys = np.empty(_FILTER_BLOCK, dtype=np.int64)
    first_held = np.empty(_FILTER_BLOCK, dtype=np.int64)
    for start in range(0, len(order), _FILTER_BLOCK):
        size = min(_FILTER_BLOCK, len(order) - start)
        for j in range(size):
            block_keys[j] = keys[order[start + j]]
        for j in range(size):
            if block_keys[j] >= 0:
                first_held[j] = table[_cube_slot(block_keys[j], bits)]
        for j in range(size):
            index, key = order[start + j], block_keys[j]
            if key < 0:
                far[far_count] = index
                far_count += 1
                continue
            if first_held[j] == key:  # in the set already (it stays there)
                continue
            if 2 * (count + 1) > len(table):  # grow: rehash into four times the slots
                bits += 2
                grown = np.full(1 << bits, -1, dtype=np.int64)
                for held in table:
                    if held >= 0:
                        _add_cube(grown, bits, held)
                table = grown
            if _add_cube(table, bits, key):
                kept[index] = True
                count += 1
    return kept, far[:far_count].copy(), table, count


def cast_tls(scanner: Scanner, stations: np.ndarray, step_deg: float, rng: np.random.Generator,
             cfg: Mapping[str, Any], batch: int,
             on_object: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """All returns of the stations' grids: points (N, 3), triangles (N,), station index (N,)
    and whether each is a mixed pixel between two surfaces (N,).

    ``on_object`` (T,) marks the triangles of objects, where depth edges can be. With a
    ``point_spacing``, the export's spacing filter keeps one return per cube of that side: each
    station's returns in a random order, the first in a cube kept, station by station (memory
    grows with the kept cubes, not with the beams).
    """
    azimuth, elevation = tls_grid(step_deg, cfg['min_elevation_deg'])
    grid = (len(elevation), len(azimuth))
    angles = _angle_tables(azimuth, elevation)
    directions = _grid_directions(*angles)
    a, b = cfg['range_noise']
    spacing = cfg['point_spacing']
    cubes = SpacingFilter(spacing, stations[0]) if spacing else None
    points, triangles, owner, strays = [], [], [], []
    for index, station in enumerate(stations):
        origins = np.broadcast_to(station, directions.shape)
        ranges, triangle = _cast_grid(scanner, origins, directions, batch, rng,
                                      cfg['min_range'], cfg['max_range'])
        stray = np.zeros(ranges.size, dtype=bool)
        if cfg['mixed_pixels'] > 0:
            ranges, triangle, stray = _mixed_pixels(
                rng, ranges.reshape(grid), triangle.reshape(grid), on_object, scanner.scene.part,
                cfg['mixed_pixels'], cfg['edge_jump'])
        rows = np.flatnonzero(np.isfinite(ranges))
        if a > 0 or b > 0:
            _add_range_noise(rng, ranges, rows, a, b)
        kept = _NONE
        if cubes is not None:
            # the returns in a random order; the first in a cube is kept
            shuffled = rng.permutation(len(rows))
            kept = cubes.new_returns(station, angles, ranges, rows, shuffled)
        xyz = _grid_points(station, *angles, ranges, rows, cubes is not None, kept)
        if cubes is not None:
            rows = rows[kept]
        points.append(xyz)
        triangles.append(triangle[rows])
        owner.append(np.full(len(rows), index))
        strays.append(stray[rows])
    if len(stations) == 1:  # no copies of one station's returns
        return points[0], triangles[0], owner[0], strays[0]
    return (np.concatenate(points), np.concatenate(triangles), np.concatenate(owner),
            np.concatenate(strays))


def scan_tls(scanner: Scanner, stations: np.ndarray, n_points: int,
             rng: np.random.Generator, cfg: Mapping[str, Any], batch: int,
             on_object: np.ndarray) -> tuple[ScanResult, float]:
    """A TLS scan of ``n_points`` and its angular step (degrees).

    A laser scanner records far more returns than a room's file keeps, and its export thins them
    with a spacing filter: the stations' returns keep one per cube of ``point_spacing`` metres
    (:func:`cast_tls`; ``null``: every return), then a uniform random subset meets the count
    exactly. Without the filter a room's points crowd the floor and walls next to the tripods
    and its far objects keep a few dozen; with it, every surface the beams sample finer than the
    spacing gets the same density. Without a configured ``angular_step_deg`` the step is the
    one whose grids (over all stations) give about ``oversample`` x ``n_points`` beams, not
    finer than ``min_angular_step_deg``, refined (smaller, down to that limit) until the kept
    returns reach ``n_points``. A configured step is used as is. Fewer returns than requested
    are written with a warning.
    """
    fixed = cfg['angular_step_deg']
    finest = 360.0 / math.floor(360.0 / cfg['min_angular_step_deg'] + 1e-9)
    span = 90.0 - cfg['min_elevation_deg']
    # a closed room returns nearly every beam; refined below
    beams = 1.05 * cfg['oversample'] * n_points
    step = fixed or max(
        finest, 360.0 / math.ceil(360.0 / math.sqrt(360.0 * span * len(stations) / beams)))
    rays = 0
    for _ in range(8):
        xyz, triangle, owner, stray = cast_tls(scanner, stations, step, rng, cfg, batch,
                                               on_object)
        azimuth, elevation = tls_grid(step, cfg['min_elevation_deg'])
        rays += len(stations) * len(azimuth) * len(elevation)
        if fixed or len(xyz) >= n_points or step <= finest * (1 + 1e-9):
            break
        finer = math.ceil(360.0 / step * math.sqrt(n_points / max(len(xyz), 1)) * 1.02)
        step = max(finest, 360.0 / max(finer, int(round(360.0 / step)) + 1))
    if len(xyz) > n_points:
        keep = np.sort(rng.choice(len(xyz), n_points, replace=False))
        xyz, triangle, owner, stray = xyz[keep], triangle[keep], owner[keep], stray[keep]
    elif len(xyz) < n_points:
        warnings.warn(f'TLS: only {len(xyz)} of {n_points} points at an angular step of '
                      f'{step:.4g} deg')
    return _result(scanner, xyz, triangle, stations.astype(np.float32)[owner], rays, stray), step


def _push_clear(xy: np.ndarray, centre: np.ndarray, obstacles: np.ndarray, clearance: float,
                polygon: np.ndarray) -> np.ndarray:
    """``xy`` (N, 2) moved out of every obstacle box grown by ``clearance``, straight to the
    side of the grown box nearest to the point's ``centre`` (N, 2) among those in ``polygon``:
    the walker passes an object on the room's side, not between it and a wall (a few passes,
    for boxes that touch); a point with no such side stays."""
    xy = xy.copy()
    for _ in range(4):
        moved = False
        for low, high in obstacles:
            low, high = low - clearance, high + clearance
            inside = np.flatnonzero(np.all((xy > low) & (xy < high), axis=1))
            if not len(inside):
                continue
            exits = np.repeat(xy[inside][:, None, :], 4, axis=1)  # (n, side, xy): -x +x -y +y
            exits[:, 0, 0], exits[:, 1, 0] = low[0], high[0]
            exits[:, 2, 1], exits[:, 3, 1] = low[1], high[1]
            distance = np.linalg.norm(exits - centre[inside][:, None, :], axis=2)
            in_room = points_in_polygon(exits.reshape(-1, 2), polygon).reshape(-1, 4)
            distance[~in_room] = np.inf
            side = np.argmin(distance, axis=1)
            free = np.isfinite(distance[np.arange(len(inside)), side])
            xy[inside[free]] = exits[np.flatnonzero(free), side[free]]
            moved |= bool(free.any())
        if not moved:
            break
    return xy


def tablet_trajectory(room: RoomGeometry, rng: np.random.Generator,
                      cfg: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Poses of a walk through the room: positions (P, 3) and view directions (P, 3).

    The walker goes once around every cell, ``wall_distance`` from its sides (starting corner and
    sense random), the loops joined in cell order; the polyline is resampled to ``poses`` points
    (per bay in a hall) and smoothed (rounded corners). Poses within 0.3 m of an object's bounds
    are pushed out to 0.3 m on the side towards the cell's centre (the walker steps around, on
    the room's side); poses then outside the room or still that near an object are dropped.
    The device is held at a height drawn from ``height``. Of every 2 m of walk, a share
    ``wall_look`` faces the nearest side of the cell (outwards, across the walk) and the rest
    the cell's centre or along the walk (drawn per 2 m). The view sways ``sway_deg`` left and
    right of that direction and tilts through ``pitch_deg``.
    """
    waypoints, centres = [], []
    for cell in room.cells:
        low, high = _inset(cell, cfg['wall_distance'])
        loop = np.array([[low[0], low[1]], [low[0], high[1]], [high[0], high[1]],
                         [high[0], low[1]]])
        loop = np.roll(loop, int(rng.integers(4)), axis=0)
        if rng.random() < 0.5:
            loop = loop[::-1]
        waypoints += [*loop, loop[0]]
        centres += [(low + high) / 2] * 5
    waypoints, centres = np.array(waypoints), np.array(centres)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1))])
    s = np.linspace(0.0, along[-1], int(cfg['poses']) * max(1, len(room.bays)))
    xy = np.stack([np.interp(s, along, waypoints[:, i]) for i in range(2)], axis=1)
    # the cell each pose walks around: the one of the loop's waypoints
    centre = centres[np.minimum(np.searchsorted(along, s, side='right') - 1, len(centres) - 1)]
    window = max(1, int(round(0.6 / max(s[1] - s[0], 1e-6)))) if len(s) > 1 else 1
    kernel = np.ones(2 * window + 1) / (2 * window + 1)
    padded = np.pad(xy, ((window, window), (0, 0)), mode='edge')
    xy = np.stack([np.convolve(padded[:, i], kernel, mode='valid') for i in range(2)], axis=1)
    step = np.gradient(xy, axis=0)
    heading = np.arctan2(step[:, 1], step[:, 0])
    # across the walk, towards the side of the cell the walker is nearest to
    outward = heading + np.pi / 2
    away = xy - centre
    flip = np.cos(outward) * away[:, 0] + np.sin(outward) * away[:, 1] < 0
    outward[flip] -= np.pi
    inward = np.arctan2(-away[:, 1], -away[:, 0])
    # every 2 m of walk: a share wall_look facing the wall, the rest inwards or ahead
    offset = rng.uniform(0.0, 2.0)
    stretch = np.floor((s + offset) / 2.0).astype(int)
    to_wall = ((s + offset) / 2.0) % 1.0 < cfg['wall_look']
    to_centre = rng.random(int(stretch.max()) + 1) < 0.5
    base = np.where(to_wall, outward, np.where(to_centre[stretch], inward, heading))
    phase = rng.uniform(0, 2 * np.pi, 2)
    yaw = base + np.radians(cfg['sway_deg']) * np.sin(2 * np.pi * s / 4.0 + phase[0])
    low_pitch, high_pitch = np.radians(cfg['pitch_deg'])
    pitch = low_pitch + (high_pitch - low_pitch) * (0.5 +
                                                    0.5 * np.sin(2 * np.pi * s / 2.5 + phase[1]))
    look = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], 1)
    xy = _push_clear(xy, centre, room.obstacles, 0.3, room.polygon)
    positions = np.column_stack([xy, np.full(len(xy), rng.uniform(*cfg['height']))])
    keep = points_in_polygon(xy, room.polygon) & (_clearance(xy, room.obstacles) > 0.3 - 1e-6)
    if not keep.any():
        raise ValueError('tablet: every pose of the walk is inside an object or outside the room')
    return positions[keep], look[keep]


@numba.njit(cache=True, nogil=True)
def _tablet_rays(positions: np.ndarray, look: np.ndarray, right: np.ndarray, up: np.ndarray,
                 pose: np.ndarray, pixel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (N, 3) of rays through ``pixel`` (N, 2: right, up offsets on
    the image plane at distance 1) of each ray's ``pose``."""
    origins = np.empty((len(pose), 3))
    directions = np.empty((len(pose), 3))
    for ray in range(len(pose)):
        p = pose[ray]
        x = look[p, 0] + pixel[ray, 0] * right[p, 0] + pixel[ray, 1] * up[p, 0]
        y = look[p, 1] + pixel[ray, 0] * right[p, 1] + pixel[ray, 1] * up[p, 1]
        z = look[p, 2] + pixel[ray, 0] * right[p, 2] + pixel[ray, 1] * up[p, 2]
        norm = np.sqrt((x * x + y * y) + z * z)
        directions[ray, 0], directions[ray, 1], directions[ray, 2] = x / norm, y / norm, z / norm
        origins[ray] = positions[p]
    return origins, directions


@numba.njit(cache=True, nogil=True)
def _tablet_returns(t_hit: np.ndarray, primitive: np.ndarray, rows: np.ndarray,
                    noise: np.ndarray, loss: np.ndarray, range_noise: float, far_keep: float,
                    near: float, far: float, uniform: np.ndarray,
                    most: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``most`` of the hit ``rows`` the tablet keeps and their measured ranges: the
    distance plus ``noise`` x ``range_noise`` within [near, far], kept when ``uniform`` is below
    the keep probability (falling from 1 at ``near`` to ``far_keep`` at ``far``, times one minus
    the triangle's ``loss``)."""
    kept = np.empty(min(len(rows), max(most, 0)), dtype=np.int64)
    measured = np.empty(len(kept))
    count = 0
    for k in range(len(rows)):
        if count == len(kept):
            break
        ray = rows[k]
        distance = np.float64(t_hit[ray]) + noise[k] * range_noise
        keep = 1.0 - (1.0 - far_keep) * (distance - near) / (far - near)
        keep *= 1.0 - loss[primitive[ray]]
        if distance >= near and distance <= far and uniform[k] < keep:
            kept[count], measured[count] = ray, distance
            count += 1
    return kept[:count], measured[:count]


@numba.njit(cache=True, nogil=True)
def _tablet_points(origins: np.ndarray, directions: np.ndarray, rows: np.ndarray,
                   measured: np.ndarray, xyz: np.ndarray) -> None:
    """Write the points of ``rows`` at origin + direction x measured range into ``xyz``
    (N, 3)."""
    for k in range(len(rows)):
        for axis in range(3):
            xyz[k, axis] = origins[rows[k], axis] + directions[rows[k], axis] * measured[k]


def cast_tablet(
    scanner: Scanner,
    positions: np.ndarray,
    look: np.ndarray,
    n_points: int,
    rng: np.random.Generator,
    cfg: Mapping[str, Any],
    batch: int,
    shiny_colors: Sequence[Sequence[int]] = ()) -> tuple[ScanResult, np.ndarray]:
    """Up to ``n_points`` tablet returns and the pose index (N,) of each.

    Each ray takes a random pose and a uniform random pixel of the image plane (``fov_deg``
    horizontal x vertical). A return counts when its measured range (true range plus noise of
    std ``range_noise``) lies in [``min_range``, ``max_range``]; it is kept with a probability
    falling linearly from 1 at ``min_range`` to ``far_keep`` at ``max_range``, and lost with
    ``dark_dropout`` on dark and ``shiny_dropout`` on shiny triangles.
    """
    loss = _surface_loss(scanner, cfg, shiny_colors)
    right = np.stack([look[:, 1], -look[:, 0], np.zeros(len(look))], axis=1)
    right /= row_norms(right) + 1e-12
    up = np.cross(right, look)
    half = np.tan(np.radians(np.asarray(cfg['fov_deg'], dtype=np.float64)) / 2)
    near, far = cfg['min_range'], cfg['max_range']
    # the returns, written in place batch by batch
    xyz = np.empty((n_points, 3))
    triangle = np.empty(n_points, dtype=np.int64)
    pose_of = np.empty(n_points, dtype=np.int64)
    got = rays = 0
    max_batches = max(64, 16 * n_points // batch + 64)
    for _ in range(max_batches):
        if got >= n_points:
            break
        pose = rng.integers(len(positions), size=batch)
        pixel = (rng.random((batch, 2)) * 2 - 1) * half
        origins, directions = _tablet_rays(positions, look, right, up, pose, pixel)
        t_hit, prim = scanner.cast(scanner.full_scene, origins, directions, rng)
        rays += batch
        rows = np.flatnonzero(np.isfinite(t_hit))
        noise = rng.standard_normal(len(rows))
        rows, measured = _tablet_returns(t_hit, prim, rows, noise, loss, cfg['range_noise'],
                                         cfg['far_keep'], near, far, rng.random(len(rows)),
                                         n_points - got)
        _tablet_points(origins, directions, rows, measured, xyz[got:got + len(rows)])
        triangle[got:got + len(rows)] = prim[rows]
        pose_of[got:got + len(rows)] = pose[rows]
        got += len(rows)
    if got < n_points:
        warnings.warn(f'tablet: only {got} of {n_points} points after {rays} rays')
    pose = pose_of[:got]
    return _result(scanner, xyz[:got], triangle[:got], positions.astype(np.float32)[pose],
                   rays), pose


def _surface_loss(scanner: Scanner, cfg: Mapping[str, Any],
                  shiny_colors: Sequence[Sequence[int]]) -> np.ndarray:
    """Per triangle: the probability that a return on it is lost, ``dark_dropout`` when its
    color's luminance is below ``dark_luminance``, at least ``shiny_dropout`` when its color is
    one of ``shiny_colors``, else 0."""
    colors = scanner.scene.colors.astype(np.float64)
    luminance = colors @ np.array([0.2126, 0.7152, 0.0722])
    loss = np.where(luminance < cfg['dark_luminance'], cfg['dark_dropout'], 0.0)
    shiny = triangles_of_colors(scanner.scene, shiny_colors)
    return np.where(shiny, np.maximum(loss, cfg['shiny_dropout']), loss)


@dataclass
class DepthCamera:
    """One pose of a depth camera: position (3,), unit view direction (3,), unit right and up
    vectors of its image plane (3,), half tangents of its field of view (horizontal, vertical)
    and its range limit."""

    position: np.ndarray
    look: np.ndarray
    right: np.ndarray
    up: np.ndarray
    half_tan: np.ndarray
    max_range: float

    def record(self) -> dict[str, Any]:
        """The camera's entry of meta.json: pose, pitch, field of view and range limit."""
        return {
            'position': np.round(self.position, 6).tolist(),
            'look': np.round(self.look, 6).tolist(),
            'pitch_deg': round(math.degrees(math.asin(-self.look[2])), 4),
            'fov_deg': np.round(np.degrees(2 * np.arctan(self.half_tan)), 4).tolist(),
            'max_range': round(self.max_range, 6),
        }


def depth_frame_camera(room: RoomGeometry, rng: np.random.Generator,
                       cfg: Mapping[str, Any]) -> DepthCamera:
    """The pose of a depth frame: a person standing near a wall or in a corner with the camera.

    The position is drawn among random floor points of the room whose distance to the walls
    lies in ``wall_distance`` and that keep ``object_clearance`` from every object's bounds
    (else the clearest of them, else of any room point); the height is drawn from ``height``.
    The camera turns towards the centre of a random cell of the room or, with probability
    ``aim_at_objects``, towards a random object whose centre lies 1 m to ``max_range`` away and
    within 60 degrees of that way into the room (when there is one); it is pitched down by an
    angle drawn from ``pitch_deg``. The field of view (``horizontal_fov_deg``,
    ``vertical_fov_deg``) and ``max_range`` are drawn too.
    """
    low, high = room.polygon.min(axis=0), room.polygon.max(axis=0)
    xy = low + rng.random((512, 2)) * (high - low)
    xy = xy[points_in_polygon(xy, room.polygon)]
    wall = distance_to_polygon(xy, room.polygon)
    clearance = _clearance(xy, room.obstacles)
    near_wall = (wall >= cfg['wall_distance'][0]) & (wall <= cfg['wall_distance'][1])
    free = np.flatnonzero(near_wall & (clearance >= cfg['object_clearance']))
    if len(free):
        spot = xy[free[int(rng.integers(len(free)))]]
    else:
        pool = np.flatnonzero(near_wall) if near_wall.any() else np.arange(len(xy))
        spot = xy[pool[int(np.argmax(clearance[pool]))]]
    max_range = float(rng.uniform(*cfg['max_range']))
    cells = room.cells
    target = cells[int(rng.integers(len(cells)))].mean(axis=0)
    inward = (target - spot) / max(float(np.linalg.norm(target - spot)), 1e-9)
    offset = room.obstacles.mean(axis=1) - spot
    distance = np.linalg.norm(offset, axis=1)
    # objects in reach within 60 degrees of the way into the room (not along the wall)
    facing = offset @ inward >= 0.5 * distance
    reachable = np.flatnonzero((distance >= 1.0) & (distance <= max_range) & facing)
    if rng.random() < cfg['aim_at_objects'] and len(reachable):
        target = spot + offset[reachable[int(rng.integers(len(reachable)))]]
    yaw = math.atan2(target[1] - spot[1], target[0] - spot[0])
    pitch = -math.radians(rng.uniform(*cfg['pitch_deg']))
    look = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                     math.sin(pitch)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    fov = np.radians([rng.uniform(*cfg['horizontal_fov_deg']),
                      rng.uniform(*cfg['vertical_fov_deg'])])
    position = np.array([spot[0], spot[1], rng.uniform(*cfg['height'])])
    return DepthCamera(position, look, right, np.cross(right, look), np.tan(fov / 2), max_range)


def depth_frame_rays(camera: DepthCamera, columns: int, rows: int) -> np.ndarray:
    """Unit directions (rows * columns, 3) through the pixel centres of a pinhole image of
    ``columns`` x ``rows`` pixels, row-major from the top left."""
    u = ((np.arange(columns) + 0.5) / columns * 2 - 1) * camera.half_tan[0]
    v = (1 - (np.arange(rows) + 0.5) / rows * 2) * camera.half_tan[1]
    plane = (camera.look[None, None, :] + u[None, :, None] * camera.right
             + v[:, None, None] * camera.up)
    plane = plane.reshape(-1, 3)
    return plane / row_norms(plane)


def _depth_frame_returns(scanner: Scanner, camera: DepthCamera, columns: int, rows: int,
                         rng: np.random.Generator, cfg: Mapping[str, Any], batch: int,
                         on_object: np.ndarray,
                         loss: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The kept returns of one frame of ``columns`` x ``rows`` pixels: points (N, 3) and
    triangles (N,), in pixel order."""
    directions = depth_frame_rays(camera, columns, rows)
    origins = np.broadcast_to(camera.position, directions.shape)
    ranges, triangle = _cast_grid(scanner, origins, directions, batch, rng, cfg['min_range'],
                                  camera.max_range)
    # a lost column after each row: no depth edge across the image's left and right borders
    grid_ranges = np.full((rows, columns + 1), np.inf)
    grid_ranges[:, :columns] = ranges.reshape(rows, columns)
    grid_triangle = np.zeros((rows, columns + 1), triangle.dtype)
    grid_triangle[:, :columns] = triangle.reshape(rows, columns)
    edges, _, _ = _depth_edges(grid_ranges.reshape(-1), grid_triangle.reshape(-1), columns + 1,
                               on_object, scanner.scene.part, cfg['edge_jump'])
    edges = edges[rng.random(len(edges)) < cfg['edge_dropout']]
    ranges[edges // (columns + 1) * columns + edges % (columns + 1)] = np.inf
    hit = np.flatnonzero(np.isfinite(ranges))
    hit = hit[rng.random(len(hit)) >= loss[triangle[hit]]]
    # structured-light / time-of-flight depth noise: its std grows with the square of the depth
    a, b = cfg['depth_noise']
    depth = ranges[hit] * (directions[hit] @ camera.look)
    measured = ranges[hit] + rng.standard_normal(len(hit)) * (a + b * depth**2)
    inside = (measured >= cfg['min_range']) & (measured <= camera.max_range)
    hit, measured = hit[inside], measured[inside]
    return camera.position + directions[hit] * measured[:, None], triangle[hit].astype(np.int64)


def cast_depth_frame(scanner: Scanner,
                     camera: DepthCamera,
                     n_points: int,
                     rng: np.random.Generator,
                     cfg: Mapping[str, Any],
                     batch: int,
                     object_parts: np.ndarray,
                     shiny_colors: Sequence[Sequence[int]] = ()) -> tuple[ScanResult, dict]:
    """Up to ``n_points`` returns of one depth frame, and the frame's meta.json record.

    The pixel grid has the field of view's aspect and about ``n_points / 0.7`` pixels; when the
    kept returns fall short of ``n_points`` the frame is cast again with the grid refined by
    the shortfall (up to 4 times, at most ``16 * n_points`` pixels). A return counts within
    [``min_range``, the camera's ``max_range``] (true and measured range); a pixel at a depth
    edge (:func:`_depth_edges`: a range step over ``edge_jump`` to a neighbour on another part,
    one of them an object) is lost with probability ``edge_dropout``, one on a dark or shiny
    triangle with ``dark_dropout`` / ``shiny_dropout``. Beyond ``n_points`` a uniform random
    subset is kept; fewer returns than requested are written with a warning. Then an object
    (``object_parts`` per part) with fewer than ``min_object_points`` returns loses them (the
    record counts them): a few returns of an object at the frame's border or behind another
    would become the annotated box of a sliver.
    """
    on_object = object_parts[scanner.scene.part]
    loss = _surface_loss(scanner, cfg, shiny_colors)
    aspect = camera.half_tan[0] / camera.half_tan[1]
    pixels = n_points / 0.7
    rays = 0
    for _ in range(4):
        rows = max(2, int(round(math.sqrt(pixels / aspect))))
        columns = max(2, int(round(rows * aspect)))
        xyz, triangle = _depth_frame_returns(scanner, camera, columns, rows, rng, cfg, batch,
                                             on_object, loss)
        rays += rows * columns
        if len(xyz) >= n_points or pixels >= 16 * n_points:
            break
        pixels = min(16 * n_points, pixels * 1.05 * n_points / max(len(xyz), n_points / 16))
    if len(xyz) > n_points:
        keep = np.sort(rng.choice(len(xyz), n_points, replace=False))
        xyz, triangle = xyz[keep], triangle[keep]
    elif len(xyz) < n_points:
        warnings.warn(f'depth frame: only {len(xyz)} of {n_points} points from a '
                      f'{columns} x {rows} pixel grid')
    part = scanner.scene.part[triangle]
    counts = np.bincount(part[on_object[triangle]], minlength=len(object_parts))
    sparse = np.flatnonzero(object_parts & (counts > 0) & (counts < cfg['min_object_points']))
    dropped = np.isin(part, sparse)
    xyz, triangle = xyz[~dropped], triangle[~dropped]
    record = dict(camera.record(), pixels=[columns, rows], sparse_objects=len(sparse),
                  sparse_object_points=int(dropped.sum()))
    origin = np.broadcast_to(camera.position, xyz.shape)
    return _result(scanner, xyz, triangle, origin, rays), record


def _result(scanner: Scanner,
            xyz: np.ndarray,
            triangle: np.ndarray,
            origin: np.ndarray,
            rays: int,
            stray: np.ndarray | None = None) -> ScanResult:
    """Label the returns by their triangles; ``origin`` (N, 3): where each was seen from;
    ``stray`` (N,): returns between two surfaces, which count as no object's points."""
    scene = scanner.scene
    on_object = scanner.movable_tri[triangle]
    return ScanResult(
        xyz=xyz.astype(np.float64, copy=False),
        rgb=np.take(scene.colors, triangle, axis=0),
        part=scene.part[triangle].astype(np.int32, copy=False),
        triangle=triangle.astype(np.int64, copy=False),
        origin=origin.astype(np.float32, copy=False),
        rays_cast=int(rays),
        object_points=int((on_object if stray is None else on_object & ~stray).sum()),
        stray=stray)


def label_stray_returns(part: np.ndarray, names: Sequence[str],
                        stray: np.ndarray | None) -> tuple[np.ndarray, list[str], str | None]:
    """Annotation labels (``part`` indexes ``names``) with the stray returns as one new clutter
    instance, named after the room's other clutter (``clutter_<k>``); returns the labels, the
    names and the new instance's name (None and the inputs unchanged without stray returns)."""
    names = list(names)
    if stray is None or not stray.any():
        return part, names, None
    numbers = [int(n.rsplit('_', 1)[1]) for n in names if n.rsplit('_', 1)[0] == 'clutter']
    name = f'clutter_{max(numbers, default=0) + 1}'
    names.append(name)
    part = part.copy()
    part[stray] = len(names) - 1
    return part, names, name
