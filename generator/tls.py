"""The terrestrial laser scanner (TLS) sensor model.

Stations on a tripod (one or more per grid cell or hall bay, away from objects), beams on a
regular azimuth x elevation grid of ``angular_step_deg`` (chosen from the point budget when not
set), the merged returns thinned to one per ``point_spacing`` cube (the export's spacing filter,
:class:`SpacingFilter`), a range window, range noise of std ``a + b * d`` and mixed pixels at
depth edges (where a grid neighbour's range differs by more than ``edge_jump``, on another part,
one of the two an object, a share of the returns lands between the foreground and the
background). Those mixed returns lie in the air, on no surface: they are marked ``stray`` and
annotated as a clutter instance of their own (:func:`generator.sensors.label_stray_returns`), as
an annotator would not give them to the object, whose box they would stretch towards the
background. There is no object-ratio phase: the share of object points is what the geometry
gives.
"""
import math
import warnings
from typing import Any, Mapping

import numba
import numpy as np

from generator.scanner import ScanResult, Scanner
from generator.sensor_common import (RoomGeometry, _cast_grid, _clearance, _depth_edges, _inset,
                                     _result)
from synthdet.voxels import hash_slot, packed_key

# an empty index array
_NONE = np.zeros(0, dtype=np.int64)


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
                     cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, start: int,
                     directions: np.ndarray) -> None:
    """Write the unit directions of the grid's beams ``start`` on (elevation-major) into
    ``directions`` (N, 3), as the float32 rays Embree casts.

    Each component is the float64 product of an elevation's and an azimuth's cosine or sine
    (:func:`_grid_points` recomputes the same products for the returns), rounded to float32."""
    columns = len(cos_azimuth)
    for k in range(len(directions)):
        row, column = (start + k) // columns, (start + k) % columns
        directions[k, 0] = cos_elevation[row] * cos_azimuth[column]
        directions[k, 1] = cos_elevation[row] * sin_azimuth[column]
        directions[k, 2] = sin_elevation[row]


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


# returns whose keys and slots the spacing filter reads ahead of inserting them
_FILTER_BLOCK = 32


@numba.njit(cache=True, nogil=True)
def _add_cube(table: np.ndarray, bits: int, key: np.int64) -> bool:
    """Put ``key`` (>= 0) into the hash set ``table`` (-1: a free slot); whether it was new."""
    mask = (1 << bits) - 1
    slot = hash_slot(key, bits)
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
    :func:`_grid_points` computes it, as :func:`synthdet.voxels.packed_key` packs it: -1 for
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
        keys[index] = packed_key(point, side, origin_key)
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
                first_held[j] = table[hash_slot(block_keys[j], bits)]
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


def _finite_rows(ranges: np.ndarray, dtype: type) -> np.ndarray:
    """Indices (ascending, of ``dtype``) of the finite ``ranges``: ``np.flatnonzero`` of
    ``np.isfinite``, without its temporaries, in half the memory with int32."""
    rows = np.empty(_count_finite(ranges), dtype=dtype)
    _write_finite_rows(ranges, rows)
    return rows


@numba.njit(cache=True, nogil=True)
def _count_finite(values: np.ndarray) -> int:
    """How many of ``values`` are finite."""
    count = 0
    for value in values:
        count += np.isfinite(value)
    return count


@numba.njit(cache=True, nogil=True)
def _write_finite_rows(values: np.ndarray, rows: np.ndarray) -> None:
    """Write the indices of the finite ``values`` into ``rows``, in ascending order."""
    count = 0
    for index in range(len(values)):
        if np.isfinite(values[index]):
            rows[count] = index
            count += 1


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
    a, b = cfg['range_noise']
    spacing = cfg['point_spacing']
    cubes = SpacingFilter(spacing, stations[0]) if spacing else None
    points, triangles, owner, strays = [], [], [], []
    # one batch's directions, written batch by batch: no array of the whole grid's rays
    directions = np.empty((min(batch, grid[0] * grid[1]), 3), dtype=np.float32)
    for index, station in enumerate(stations):
        # the station as the float32 rays Embree casts, without a copy per beam
        origins = np.broadcast_to(station.astype(np.float32), directions.shape)

        def rays(start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
            _grid_directions(*angles, start, directions[:stop - start])
            return origins[:stop - start], directions[:stop - start]

        ranges, triangle = _cast_grid(scanner, rays, grid[0] * grid[1], batch, rng,
                                      cfg['min_range'], cfg['max_range'])
        if cfg['mixed_pixels'] > 0:
            ranges, triangle, stray = _mixed_pixels(
                rng, ranges.reshape(grid), triangle.reshape(grid), on_object, scanner.scene.part,
                cfg['mixed_pixels'], cfg['edge_jump'])
        else:
            stray = np.zeros(ranges.size, dtype=bool)
        rows = _finite_rows(ranges, np.int32 if ranges.size < 2**31 else np.int64)
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
        owner.append(np.full(len(rows), index, dtype=np.int32))
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
        # the drawn returns (distinct) in ascending order, without sorting them
        chosen = np.zeros(len(xyz), dtype=bool)
        chosen[rng.choice(len(xyz), n_points, replace=False)] = True
        keep = np.flatnonzero(chosen)
        xyz, triangle, owner, stray = xyz[keep], triangle[keep], owner[keep], stray[keep]
    elif len(xyz) < n_points:
        warnings.warn(f'TLS: only {len(xyz)} of {n_points} points at an angular step of '
                      f'{step:.4g} deg')
    return _result(scanner, xyz, triangle, stations.astype(np.float32)[owner], rays, stray), step
