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
import threading
import warnings
from dataclasses import dataclass
from typing import Any, Mapping

import numba
import numpy as np

from generator.counter_random import (DRAW_CHUNK, ITEM_COUNTERS, normals, stream_seed,
                                     uniform, word)
from generator.scanner import ScanResult, Scanner
from generator.sensor_common import (RoomGeometry, _cast_grid, _clearance, _depth_edges, _inset,
                                     _result, _rows_of)
from synthdet.voxels import hash_slot, packed_key

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
    row, column = start // columns, start % columns  # then counted on, without divisions
    for k in range(len(directions)):
        directions[k, 0] = cos_elevation[row] * cos_azimuth[column]
        directions[k, 1] = cos_elevation[row] * sin_azimuth[column]
        directions[k, 2] = sin_elevation[row]
        column += 1
        if column == columns:
            row, column = row + 1, 0


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
def _grid_points(station: np.ndarray, cos_elevation: np.ndarray, sin_elevation: np.ndarray,
                 cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, beams: np.ndarray,
                 measured: np.ndarray) -> np.ndarray:
    """Points (N, 3) of ``beams`` (grid indices) at their ``measured`` ranges (N,)."""
    columns = len(cos_azimuth)
    xyz = np.empty((len(beams), 3))
    row, first = 0, 0  # the row of the last beam and its first beam
    for k in range(len(beams)):
        beam = beams[k]
        # the row from a division only when it changes (ascending beams mostly stay in it)
        if beam < first or beam >= first + columns:
            row = beam // columns
            first = row * columns
        column = beam - first
        xyz[k, 0] = station[0] + cos_elevation[row] * cos_azimuth[column] * measured[k]
        xyz[k, 1] = station[1] + cos_elevation[row] * sin_azimuth[column] * measured[k]
        xyz[k, 2] = station[2] + sin_elevation[row] * measured[k]
    return xyz


@numba.njit(cache=True, nogil=True)
def _add_range_noise(ranges: np.ndarray, seed: np.uint64, a: float, b: float) -> None:
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


@numba.njit(cache=True, nogil=True)
def _priority(seed: np.uint64, beam: int) -> np.uint64:
    """The spacing filter's priority of ``beam``: the first word of the beam's counters in the
    station's stream ``seed`` (its range error draws from the next ones)."""
    return word(seed, np.uint64(beam) * ITEM_COUNTERS)


@numba.njit(cache=True, nogil=True)
def _priorities(seed: np.uint64, beams: np.ndarray) -> np.ndarray:
    """The spacing filter's priority (uint64) of each of ``beams``."""
    priority = np.empty(len(beams), dtype=np.uint64)
    for k in range(len(beams)):
        priority[k] = _priority(seed, beams[k])
    return priority


class SpacingFilter:
    """The laser scanner export's spacing filter: one return per cube of ``side`` metres across
    the stations, one station after the other. A cube keeps a return of the first station that
    hits it, drawn uniformly at random among that station's returns in the cube: the one of
    smallest priority, a random word per beam of the station's stream (the same distribution as
    the first return of the cube in a uniformly random order of the station's returns).

    A station's returns go in one pass in beam order through an open-addressing hash set of the
    cubes (memory grows with the kept cubes, not with the beams), each cube holding the beam of
    the station's current choice until the station is done. The keys are those of
    :class:`synthdet.voxels.VoxelFilter` (cube coordinates relative to ``origin``'s cube, 21
    bits each); returns too far for them (2**20 cubes away) are kept by their exact cube
    coordinates, the same way.
    """

    def __init__(self, side: float, origin: np.ndarray):
        self.side = float(side)
        self.origin_key = np.floor(origin / side)
        # slot k: table[2k] a cube's key (-1: free), table[2k + 1] the beam its station keeps
        # so far (-1 once the station is done); the memory of the thread's previous filter
        # when there is one, emptied (a process generating rooms scans one after the other:
        # fresh pages for every room's hash set would cost more than emptying it)
        self.table = _spare.__dict__.pop('table', None)
        if self.table is None:
            self.table = np.full(2 << 16, -1, dtype=np.int64)
        else:
            self.table.fill(-1)
        self.count = 0
        self.wide: set[tuple[int, int, int]] = set()  # cubes beyond the packed key range

    def new_returns(self, station: np.ndarray, angles: tuple[np.ndarray, ...],
                    ranges: np.ndarray, seed: np.uint64) -> np.ndarray:
        """Grid indices (ascending) of the returns (the finite ``ranges`` of the grid, at the
        points :func:`_grid_points` computes) kept in cubes not seen before, the priorities
        from the stream ``seed``."""
        kept, far, self.table, self.count = _thin_station(station, *angles, ranges, seed,
                                                          self.side, self.origin_key,
                                                          self.table, self.count,
                                                          *_filter_buffers(len(ranges)))
        if len(far):  # points kilometres away: rare, kept exact, by priority
            far = far[np.argsort(_priorities(seed, far), kind='stable')]
            fresh = []
            points = _grid_points(station, *angles, far, ranges[far])
            for beam, point in zip(far.tolist(), points):
                key = tuple(int(v) for v in (np.floor(point / self.side) - self.origin_key))
                if key not in self.wide:
                    self.wide.add(key)
                    fresh.append(beam)
            kept = np.union1d(kept, np.array(fresh, dtype=np.int64))
        return kept

    def release(self) -> None:
        """Leave the hash set's memory to the thread's next filter (this one is done)."""
        _spare.table, self.table = self.table, None


# the memory of the last released spacing filter's hash set, the last grid's ranges and
# triangles and the filter's work space, per thread
_spare = threading.local()


def _grid_buffers(size: int) -> tuple[np.ndarray, np.ndarray]:
    """The thread's buffers for a grid's ranges (float64) and triangles (int32), of ``size``
    or more: a station's grid is done with them before the next one is cast, and a process
    generating rooms casts grid after grid (fresh pages for every grid would cost more)."""
    buffers = getattr(_spare, 'grid', None)
    if buffers is None or len(buffers[0]) < size:
        buffers = _spare.grid = (np.empty(size), np.empty(size, np.int32))
    return buffers


def _filter_buffers(size: int) -> tuple[np.ndarray, np.ndarray]:
    """The thread's work space of the spacing filter's pass over a grid of ``size`` beams (see
    :func:`_thin_station`), for the same reason."""
    buffers = getattr(_spare, 'filter', None)
    if buffers is None or len(buffers[0]) < size:
        buffers = _spare.filter = (np.empty(size, np.int64), np.zeros(size, np.bool_))
    return buffers


@numba.njit(cache=True, nogil=True)
def _slot_of(table: np.ndarray, bits: int, key: np.int64) -> int:
    """The slot of ``key`` in the hash set ``table`` (2**bits slots of two entries, the first
    the key), else the free slot where it goes."""
    mask = (1 << bits) - 1
    slot = hash_slot(key, bits)
    while table[2 * slot] >= 0 and table[2 * slot] != key:
        slot = (slot + 1) & mask
    return slot


# beams whose cube keys the spacing filter computes at a time (a buffer that stays in the
# cache), and beams whose first slots it reads ahead of its pass over them
_KEY_CHUNK = 1 << 16
_READ_AHEAD = 128


@numba.njit(cache=True, nogil=True)
def _cube_keys(station: np.ndarray, cos_elevation: np.ndarray, sin_elevation: np.ndarray,
               cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, ranges: np.ndarray,
               start: int, side: float, origin_key: np.ndarray, keys: np.ndarray) -> None:
    """Write the packed cube key of the beams ``start`` on into ``keys``, at each point as
    :func:`_grid_points` computes it, as :func:`synthdet.voxels.packed_key` packs it: -1 for
    a point 2**20 cubes or more away, -2 for a beam without a return."""
    columns = len(cos_azimuth)
    point = np.empty(3)
    row, column = start // columns, start % columns  # then counted on, without divisions
    for k in range(len(keys)):
        measured = ranges[start + k]
        if np.isfinite(measured):
            point[0] = station[0] + cos_elevation[row] * cos_azimuth[column] * measured
            point[1] = station[1] + cos_elevation[row] * sin_azimuth[column] * measured
            point[2] = station[2] + sin_elevation[row] * measured
            keys[k] = packed_key(point, side, origin_key)
        else:
            keys[k] = -2
        column += 1
        if column == columns:
            row, column = row + 1, 0


@numba.njit(cache=True, nogil=True)
def _thin_station(station: np.ndarray, cos_elevation: np.ndarray, sin_elevation: np.ndarray,
                  cos_azimuth: np.ndarray, sin_azimuth: np.ndarray, ranges: np.ndarray,
                  seed: np.uint64, side: float, origin_key: np.ndarray, table: np.ndarray,
                  count: int, fresh: np.ndarray,
                  chosen: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The spacing filter's pass over one station's grid (see :class:`SpacingFilter`): the
    kept beams (ascending), the beams 2**20 cubes or more away (ascending), and the hash set
    ``table`` (grown four times at half full) and its number of cubes after. ``fresh`` (int64)
    and ``chosen`` (bool, all False, left so) are work space of the grid's size or more."""
    returns = 0
    for measured in ranges:
        returns += np.isfinite(measured)
    # fresh: the slots of the cubes this station hit first; far: the beams without a packed key
    far = np.empty(16, dtype=np.int64)
    # a station's cubes are about a quarter of its returns or fewer: room for that many more
    # at the start spares most of the growing
    bits = _table_bits(table)
    while 2 * (count + returns // 4) > (1 << bits):
        bits += 1
    if bits > _table_bits(table):
        table = _grown(table, fresh[:0], bits)
    keys = np.empty(min(_KEY_CHUNK, len(ranges)), dtype=np.int64)
    # where the pass stands: next beam of the chunk, fresh and far counts, cubes (and the
    # pass's reads ahead)
    state = np.array([0, 0, 0, count, 0], dtype=np.int64)
    for start in range(0, len(ranges), _KEY_CHUNK):
        chunk = keys[:min(_KEY_CHUNK, len(ranges) - start)]
        _cube_keys(station, cos_elevation, sin_elevation, cos_azimuth, sin_azimuth, ranges,
                   start, side, origin_key, chunk)
        state[0] = 0
        while True:
            if state[2] + len(chunk) > len(far):  # room for every beam of the chunk
                far = np.concatenate((far[:state[2]], np.empty(len(far) + len(chunk),
                                                               dtype=np.int64)))
            _thin_pass(chunk, start, seed, table, fresh, far, state)
            if state[0] == len(chunk):
                break
            # half full: four times the slots
            table = _grown(table, fresh[:state[1]], _table_bits(table) + 2)
    # the station's choices, in beam order; their cubes are closed for the next stations
    for slot in fresh[:state[1]]:
        chosen[table[2 * slot + 1]] = True
        table[2 * slot + 1] = -1
    # each beam written to the next place, which it keeps when chosen (no branch per beam)
    kept = np.empty(state[1] + 1, dtype=np.int64)
    written = 0
    for beam in range(len(ranges)):
        kept[written] = beam
        written += chosen[beam]
        chosen[beam] = False
    return kept[:state[1]], far[:state[2]].copy(), table, state[3]


@numba.njit(cache=True, nogil=True)
def _grown(table: np.ndarray, fresh: np.ndarray, bits: int) -> np.ndarray:
    """The hash set ``table`` rehashed into 2**bits slots; ``fresh`` (slots) moved with their
    cubes, in place."""
    grown = np.full(2 << bits, -1, dtype=np.int64)
    for held in range(len(table) // 2):
        key = table[2 * held]
        if key >= 0:
            slot = _slot_of(grown, bits, key)
            grown[2 * slot], grown[2 * slot + 1] = key, table[2 * held + 1]
    for k in range(len(fresh)):
        fresh[k] = _slot_of(grown, bits, table[2 * fresh[k]])
    return grown


@numba.njit(cache=True, nogil=True)
def _table_bits(table: np.ndarray) -> int:
    """log2 of the number of slots of the hash set ``table``."""
    bits = 0
    while (2 << bits) < len(table):
        bits += 1
    return bits


@numba.njit(cache=True, nogil=True)
def _thin_pass(keys: np.ndarray, start: int, seed: np.uint64, table: np.ndarray,
               fresh: np.ndarray, far: np.ndarray, state: np.ndarray) -> None:
    """The spacing filter's pass over the cube ``keys`` of the beams ``start`` on, from key
    ``state[0]`` on, until their end or a new cube that would fill ``table`` to more than half
    (``state`` updated)."""
    bits = _table_bits(table)
    fresh_count, far_count, count = state[1], state[2], state[3]
    # the previous return's cube (none at the start or after the table grew): its slot and
    # the priority of the station's choice there
    last_key, last_slot, last_priority = np.int64(-3), 0, np.uint64(0)
    # read ahead: the first slots of the next keys, each read independent of the others, so
    # that the memory serves many at once before the pass needs them
    ahead = np.int64(0)
    for k in range(state[0], len(keys)):
        if (k - state[0]) % _READ_AHEAD == 0:
            for next_key in keys[k:k + _READ_AHEAD]:
                if next_key >= 0:
                    ahead ^= table[2 * hash_slot(next_key, bits)]
        key, beam = keys[k], start + k
        if key < 0:
            if key == -1:
                far[far_count] = beam
                far_count += 1
            continue
        priority = _priority(seed, beam)
        if key == last_key:  # neighbouring beams mostly hit the same cube: no lookup
            if table[2 * last_slot + 1] >= 0 and priority < last_priority:
                table[2 * last_slot + 1], last_priority = beam, priority
            continue
        slot = _slot_of(table, bits, key)
        if table[2 * slot] == key:
            choice = table[2 * slot + 1]
            if choice >= 0:  # a cube of this station: the smaller priority stays
                last_priority = _priority(seed, choice)
                if priority < last_priority:
                    table[2 * slot + 1], last_priority = beam, priority
        else:
            if 2 * (count + 1) > (1 << bits):  # the table must grow first
                state[0], state[1], state[2], state[3] = k, fresh_count, far_count, count
                return
            table[2 * slot], table[2 * slot + 1] = key, beam
            count += 1
            fresh[fresh_count] = slot
            fresh_count += 1
            last_priority = priority
        last_key, last_slot = key, slot
    state[0], state[1], state[2], state[3] = len(keys), fresh_count, far_count, count
    # the reads ahead are kept (a value no one uses would let them be left out)
    state[4] = ahead


@numba.njit(cache=True, nogil=True)
def _uniform_subset(total: int, wanted: int, seed: np.uint64) -> np.ndarray:
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
    angles = _angle_tables(azimuth, elevation)
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
            _grid_directions(*angles, start, directions[:stop - start])
            return origins[:stop - start], directions[:stop - start]

        ranges, triangle = _cast_grid(scanner, rays, grid[0] * grid[1], batch, rng,
                                      cfg['min_range'], cfg['max_range'],
                                      _grid_buffers(grid[0] * grid[1]))
        if cfg['mixed_pixels'] > 0:
            ranges, triangle, stray = _mixed_pixels(
                rng, ranges.reshape(grid), triangle.reshape(grid), on_object, scanner.scene.part,
                cfg['mixed_pixels'], cfg['edge_jump'])
        else:
            stray = np.zeros(ranges.size, dtype=bool)
        seed = stream_seed(rng)  # the station's range errors and filter priorities
        if a > 0 or b > 0:
            _add_range_noise(ranges, seed, a, b)
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
    angles = _angle_tables(*tls_grid(step_deg, min_elevation_deg))
    points, triangles, owner, strays = [], [], [], []
    first = 0
    for index, kept in enumerate(returns):
        if chosen is None:
            points.append(_grid_points(kept.station, *angles, kept.beams, kept.ranges))
            triangles.append(kept.triangle)
            strays.append(kept.stray)
        else:  # the chosen indices within this station's returns
            low, high = np.searchsorted(chosen, (first, first + len(kept.beams)))
            mine = chosen[low:high] - first
            ranges, triangle, stray = _gathered(mine, kept.ranges, kept.triangle, kept.stray)
            points.append(_grid_points(kept.station, *angles, np.take(kept.beams, mine), ranges))
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
        chosen = _uniform_subset(found, n_points, stream_seed(rng))
    elif found < n_points:
        warnings.warn(f'TLS: only {found} of {n_points} points at an angular step of '
                      f'{step:.4g} deg')
    xyz, triangle, owner, stray = returns_points(returns, step, cfg['min_elevation_deg'], chosen)
    origin = _rows_of(stations.astype(np.float32), owner)
    return _result(scanner, xyz, triangle, origin, rays, stray), step
