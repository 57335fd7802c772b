"""The terrestrial laser scanner (TLS) sensor model.

Stations on a tripod (one or more per grid cell or hall bay, away from objects), beams on a
regular azimuth x elevation grid of ``angular_step_deg`` (chosen from the point budget when not
set; the grid is :mod:`generator.tls_grid`), the merged returns thinned to one per
``point_spacing`` cube (the export's spacing filter, :mod:`generator.spacing_filter`), a range
window, range noise of std ``a + b * d`` and mixed pixels at depth edges (where a grid
neighbour's range differs by more than ``edge_jump``, on another part, one of the two an object,
a share of the returns lands between the foreground and the background). Those mixed returns lie in the air, on no surface: they are marked ``stray`` and
annotated as a clutter instance of their own (:func:`generator.sensors.label_stray_returns`), as
an annotator would not give them to the object, whose box they would stretch towards the
background. There is no object-ratio phase: the share of object points is what the geometry
gives.
"""
import math
import threading
import warnings
from dataclasses import dataclass
from typing import Any, Mapping

import numba
import numpy as np

from generator.counter_random import DRAW_CHUNK, normals, stream_seed, uniform
from generator.scanner import ScanResult, Scanner
from generator.sensor_common import (RoomGeometry, cast_grid, depth_edges, inset_cell,
                                     labelled_result, obstacle_clearance, rows_of)
from generator.spacing_filter import SpacingFilter
from generator.tls_grid import angle_tables, grid_directions, grid_points, tls_grid


def tls_stations(room: RoomGeometry, rng: np.random.Generator,
                 cfg: Mapping[str, Any]) -> np.ndarray:
    """Tripod positions (S, 3): ``stations_per_cell`` per cell, ``object_clearance`` from objects
    when possible (else the clearest of the candidates), ``wall_clearance`` from the cell's
    sides, at a height drawn from ``height``."""
    stations = []
    for cell in room.cells:
        low, high = inset_cell(cell, cfg['wall_clearance'])
        for _ in range(
                int(rng.integers(cfg['stations_per_cell'][0], cfg['stations_per_cell'][1] + 1))):
            candidates = low + rng.random((64, 2)) * (high - low)
            clearance = obstacle_clearance(candidates, room.obstacles)
            free = np.flatnonzero(clearance >= cfg['object_clearance'])
            xy = candidates[free[0] if len(free) else int(np.argmax(clearance))]
            stations.append([xy[0], xy[1], rng.uniform(*cfg['height'])])
    return np.array(stations, dtype=np.float64)


def mix_at_depth_edges(rng: np.random.Generator, ranges: np.ndarray, triangle: np.ndarray,
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
    edges, other, other_tri = depth_edges(ranges, triangle, columns, on_object, part, jump)
    chosen = rng.random(len(edges)) < share
    mixed, other, other_tri = edges[chosen], other[chosen], other_tri[chosen]
    fraction = rng.random(len(mixed))
    ranges[mixed] += fraction * (other - ranges[mixed])
    far = fraction > 0.5
    triangle[mixed[far]] = other_tri[far]
    stray = np.zeros(ranges.size, dtype=bool)
    stray[mixed] = True
    return ranges, triangle, stray


@numba.njit(cache=True, nogil=True)
def add_range_noise(ranges: np.ndarray, seed: np.uint64, a: float, b: float) -> None:
    """Move every finite range by a standard normal draw x (a + b x range), in place: beam k's
    draw from its counters after the first in the stream ``seed``
    (:data:`generator.counter_random.ITEM_COUNTERS`), chunk by chunk
    (:func:`generator.counter_random.normals`)."""
    draws = np.empty(DRAW_CHUNK)
    for start in range(0, len(ranges), DRAW_CHUNK):
        stop = min(start + DRAW_CHUNK, len(ranges))
        normals(seed, start, stop, 1, draws)
        for beam in range(start, stop):
            measured = ranges[beam]
            if np.isfinite(measured):
                ranges[beam] = measured + draws[beam - start] * (a + b * measured)


# the last grid's ranges and triangles, per thread
_spare = threading.local()


def _grid_buffers(size: int) -> tuple[np.ndarray, np.ndarray]:
    """The thread's buffers for a grid's ranges (float64) and triangles (int32), of ``size``
    or more: a station's grid is done with them before the next one is cast, and a process
    generating rooms casts grid after grid (fresh pages for every grid would cost more)."""
    buffers = getattr(_spare, 'grid', None)
    if buffers is None or len(buffers[0]) < size:
        buffers = _spare.grid = (np.empty(size), np.empty(size, np.int32))
    return buffers


@numba.njit(cache=True, nogil=True)
def uniform_subset(total: int, wanted: int, seed: np.uint64) -> np.ndarray:
    """Ascending indices of ``wanted`` of ``total`` items, every such subset equally likely:
    selection sampling (Knuth's algorithm S), item k taken with probability (still wanted) /
    (items left) by the uniform draw k of the stream ``seed``."""
    # one slot more: each item is written to the next slot, which it keeps when taken (no
    # branch on a draw)
    chosen = np.empty(wanted + 1, dtype=np.int64)
    count = 0
    for item in range(total):
        if count == wanted:
            break
        chosen[count] = item
        count += uniform(seed, np.uint64(item)) * (total - item) < wanted - count
    return chosen[:wanted]


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


@dataclass
class StationReturns:
    """The returns one station keeps: grid indices (ascending), measured ranges, triangles and
    whether each is a mixed pixel between two surfaces."""

    station: np.ndarray  # (3,)
    beams: np.ndarray  # (N,) int
    ranges: np.ndarray  # (N,) float64
    triangle: np.ndarray  # (N,) int32
    stray: np.ndarray  # (N,) bool


def station_returns(scanner: Scanner, stations: np.ndarray, step_deg: float,
                    rng: np.random.Generator, cfg: Mapping[str, Any], batch: int,
                    on_object: np.ndarray) -> list[StationReturns]:
    """The returns each station's grid keeps (see :func:`cast_tls`), without their points."""
    azimuth, elevation = tls_grid(step_deg, cfg['min_elevation_deg'])
    grid = (len(elevation), len(azimuth))
    angles = angle_tables(azimuth, elevation)
    a, b = cfg['range_noise']
    spacing = cfg['point_spacing']
    cubes = SpacingFilter(spacing, stations[0]) if spacing else None
    kept = []
    # the grid is cast in slices (Scanner.slice_size); one slice's directions, written slice
    # by slice: no array of the whole grid's rays
    batch = scanner.slice_size(batch)
    directions = np.empty((min(batch, grid[0] * grid[1]), 3), dtype=np.float32)
    for station in stations:
        # the station as the float32 rays Embree casts, without a copy per beam
        origins = np.broadcast_to(station.astype(np.float32), directions.shape)

        def rays(start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
            grid_directions(*angles, start, directions[:stop - start])
            return origins[:stop - start], directions[:stop - start]

        ranges, triangle = cast_grid(scanner, rays, grid[0] * grid[1], batch, rng,
                                     cfg['min_range'], cfg['max_range'],
                                     _grid_buffers(grid[0] * grid[1]))
        if cfg['mixed_pixels'] > 0:
            ranges, triangle, stray = mix_at_depth_edges(
                rng, ranges.reshape(grid), triangle.reshape(grid), on_object, scanner.scene.part,
                cfg['mixed_pixels'], cfg['edge_jump'])
        else:
            stray = np.zeros(ranges.size, dtype=bool)
        seed = stream_seed(rng)  # the station's range errors and filter priorities
        if a > 0 or b > 0:
            add_range_noise(ranges, seed, a, b)
        if cubes is not None:
            beams = cubes.new_returns(station, angles, ranges, seed)
        else:
            beams = _finite_rows(ranges, np.int32 if ranges.size < 2**31 else np.int64)
        kept.append(StationReturns(station, beams, *_gathered(beams, ranges, triangle, stray)))
    if cubes is not None:
        cubes.release()
    return kept


def returns_points(returns: list[StationReturns], step_deg: float, min_elevation_deg: float,
                   chosen: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points (N, 3), triangles (N,), station index (N,) and mixed pixels (N,) of the stations'
    ``returns`` in order, ``chosen`` (ascending indices into them; None: all) only."""
    angles = angle_tables(*tls_grid(step_deg, min_elevation_deg))
    points, triangles, owner, strays = [], [], [], []
    first = 0
    for index, kept in enumerate(returns):
        if chosen is None:
            points.append(grid_points(kept.station, *angles, kept.beams, kept.ranges))
            triangles.append(kept.triangle)
            strays.append(kept.stray)
        else:  # the chosen indices within this station's returns
            low, high = np.searchsorted(chosen, (first, first + len(kept.beams)))
            mine = chosen[low:high] - first
            ranges, triangle, stray = _gathered(mine, kept.ranges, kept.triangle, kept.stray)
            points.append(grid_points(kept.station, *angles, np.take(kept.beams, mine), ranges))
            triangles.append(triangle)
            strays.append(stray)
        first += len(kept.beams)
        owner.append(np.full(len(points[-1]), index, dtype=np.int32))
    if len(returns) == 1:  # no copies of one station's returns
        return points[0], triangles[0], owner[0], strays[0]
    return (np.concatenate(points), np.concatenate(triangles), np.concatenate(owner),
            np.concatenate(strays))


@numba.njit(cache=True, nogil=True)
def _gathered(rows: np.ndarray, ranges: np.ndarray, triangle: np.ndarray,
              stray: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``rows`` of a station's ranges, triangles and mixed pixels, in one pass (numpy
    gathers each array in a pass of its own)."""
    chosen_ranges = np.empty(len(rows))
    chosen_triangle = np.empty(len(rows), dtype=triangle.dtype)
    chosen_stray = np.empty(len(rows), dtype=np.bool_)
    for k in range(len(rows)):
        row = rows[k]
        chosen_ranges[k], chosen_triangle[k], chosen_stray[k] = (ranges[row], triangle[row],
                                                                 stray[row])
    return chosen_ranges, chosen_triangle, chosen_stray


def cast_tls(scanner: Scanner, stations: np.ndarray, step_deg: float, rng: np.random.Generator,
             cfg: Mapping[str, Any], batch: int,
             on_object: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """All returns of the stations' grids: points (N, 3), triangles (N,), station index (N,)
    and whether each is a mixed pixel between two surfaces (N,).

    ``on_object`` (T,) marks the triangles of objects, where depth edges can be. The returns
    get range errors (``range_noise``), then with a ``point_spacing`` the export's spacing
    filter (:class:`SpacingFilter`) keeps one return per cube of that side, station by station
    (memory grows with the kept cubes, not with the beams).
    """
    returns = station_returns(scanner, stations, step_deg, rng, cfg, batch, on_object)
    return returns_points(returns, step_deg, cfg['min_elevation_deg'])


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
        returns = station_returns(scanner, stations, step, rng, cfg, batch, on_object)
        found = sum(len(kept.beams) for kept in returns)
        azimuth, elevation = tls_grid(step, cfg['min_elevation_deg'])
        rays += len(stations) * len(azimuth) * len(elevation)
        if fixed or found >= n_points or step <= finest * (1 + 1e-9):
            break
        finer = math.ceil(360.0 / step * math.sqrt(n_points / max(found, 1)) * 1.02)
        step = max(finest, 360.0 / max(finer, int(round(360.0 / step)) + 1))
    chosen = None
    if found > n_points:
        # a uniform random subset of exactly n_points, in the returns' order
        chosen = uniform_subset(found, n_points, stream_seed(rng))
    elif found < n_points:
        warnings.warn(f'TLS: only {found} of {n_points} points at an angular step of '
                      f'{step:.4g} deg')
    xyz, triangle, owner, stray = returns_points(returns, step, cfg['min_elevation_deg'], chosen)
    origin = rows_of(stations.astype(np.float32), owner)
    return labelled_result(scanner, xyz, triangle, origin, rays, stray), step
