"""The laser scanner export's spacing filter: one return per cube across the stations.

:class:`SpacingFilter` keeps its cubes in an open-addressing hash set that numba functions
fill station by station, one pass in beam order.
"""
import threading

import numba
import numpy as np

from generator.counter_random import ITEM_COUNTERS, word
from generator.tls_grid import grid_points, next_beam
from synthdet.voxels import hash_slot, packed_key


@numba.njit(cache=True, nogil=True)
def beam_priority(seed: np.uint64, beam: int) -> np.uint64:
    """The spacing filter's priority of ``beam``: the first word of the beam's counters in the
    station's stream ``seed`` (its range error draws from the next ones)."""
    return word(seed, np.uint64(beam) * ITEM_COUNTERS)


@numba.njit(cache=True, nogil=True)
def beam_priorities(seed: np.uint64, beams: np.ndarray) -> np.ndarray:
    """The spacing filter's priority (uint64) of each of ``beams``."""
    priority = np.empty(len(beams), dtype=np.uint64)
    for k in range(len(beams)):
        priority[k] = beam_priority(seed, beams[k])
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
        points :func:`grid_points` computes) kept in cubes not seen before, the priorities
        from the stream ``seed``."""
        kept, far, self.table, self.count = _thin_station(station, *angles, ranges, seed,
                                                          self.side, self.origin_key,
                                                          self.table, self.count,
                                                          *_filter_buffers(len(ranges)))
        if len(far):  # points kilometres away: rare, kept exact, by priority
            far = far[np.argsort(beam_priorities(seed, far), kind='stable')]
            fresh = []
            points = grid_points(station, *angles, far, ranges[far])
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


# the memory of the last released spacing filter's hash set and the filter's work space, per
# thread
_spare = threading.local()


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
    :func:`grid_points` computes it, as :func:`synthdet.voxels.packed_key` packs it: -1 for
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
        row, column = next_beam(row, column, columns)


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
        priority = beam_priority(seed, beam)
        if key == last_key:  # neighbouring beams mostly hit the same cube: no lookup
            if table[2 * last_slot + 1] >= 0 and priority < last_priority:
                table[2 * last_slot + 1], last_priority = beam, priority
            continue
        slot = _slot_of(table, bits, key)
        if table[2 * slot] == key:
            choice = table[2 * slot + 1]
            if choice >= 0:  # a cube of this station: the smaller priority stays
                last_priority = beam_priority(seed, choice)
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
