"""One point per cube (voxel): the voxel filter of scan reading (``synthdet.scan_io``) and of the
generator's laser-scanner export, and the voxel grid of the training pipeline
(``VoxelGridSample``)."""
import numba
import numpy as np


def cube_keys(xyz: np.ndarray, side: float) -> np.ndarray:
    """One int64 key per point of ``xyz`` (N >= 1, 3): equal keys share a cube of ``side``
    metres (cubes on a grid through the origin)."""
    index = np.floor(xyz / side).astype(np.int64)
    index -= index.min(axis=0)
    extent = index.max(axis=0) + 1
    return (index[:, 0] * extent[1] + index[:, 1]) * extent[2] + index[:, 2]


def one_point_per_cube(xyz: np.ndarray, side: float, rng) -> np.ndarray:
    """Ascending indices of one point of ``xyz`` (N, 3) per occupied cube of ``side`` metres,
    the point drawn at random by ``rng`` (a ``np.random.Generator``, or ``np.random`` itself)."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=np.int64)
    # shuffled first, so the point a cube keeps is whichever of its points the sort puts first
    # (benchmarks/bench_structure_thinning.py times this against np.unique)
    order = rng.permutation(len(xyz))
    keys = cube_keys(xyz, side)[order]
    by_key = np.argsort(keys)
    sorted_keys = keys[by_key]
    first = by_key[np.concatenate(([True], sorted_keys[1:] != sorted_keys[:-1]))]
    return np.sort(order[first])


class VoxelFilter:
    """Keeps the first point of every voxel, across chunks (a scan read in pieces, a laser
    scanner's stations one after the other): a sorted array of the kept voxels' keys grows by
    each chunk's new voxels, so memory grows with the occupied voxels only."""

    def __init__(self, voxel: float, origin: np.ndarray):
        self.voxel = voxel
        self.origin_key = np.floor(origin / voxel)
        self.seen = np.zeros(0, dtype=np.int64)
        self.wide: set[tuple[float, float, float]] = set()  # voxels beyond the packed range

    def new_points(self, xyz: np.ndarray) -> np.ndarray:
        """Indices (ascending) of the points of ``xyz`` (scan coordinates) in voxels not seen
        before, one per voxel: its first point."""
        packed = _packed_keys(np.ascontiguousarray(xyz, dtype=np.float64), self.voxel,
                              self.origin_key)
        first = _first_of_each(packed)
        first = first[packed[first] >= 0]
        fresh = first[~_sorted_contains(self.seen, packed[first])]
        # the fresh keys are new and distinct: the sorted union is the sorted concatenation
        self.seen = np.sort(np.concatenate([self.seen, packed[fresh]]))
        far = []
        for index in np.flatnonzero(packed < 0):  # points kilometres away: rare, kept exact
            key = tuple(float(value) for value in self._keys(xyz[index]))
            if key not in self.wide:
                self.wide.add(key)
                far.append(index)
        return np.sort(np.concatenate([fresh, np.array(far, dtype=np.int64)]))

    def _keys(self, point: np.ndarray) -> np.ndarray:
        """The whole-number voxel coordinates (3,) of one point, relative to the origin's
        voxel, in float64 (a point at 1e300 m has no int64 voxel number)."""
        return np.floor(point / self.voxel) - self.origin_key


@numba.njit(cache=True, nogil=True)
def packed_key(point: np.ndarray, voxel: float, origin_key: np.ndarray) -> np.int64:
    """The int64 key of one point (3,): its voxel's integer coordinates relative to
    ``origin_key``, 21 bits each, packed; -1 for a point 2**20 voxels or more away."""
    key = np.int64(0)
    for axis in range(3):
        offset = np.floor(point[axis] / voxel) - origin_key[axis]
        if not abs(offset) < 2**20:  # checked before the cast: 1e300 has no int64
            return np.int64(-1)
        key = (key << 21) | (np.int64(offset) + 2**20)
    return key


@numba.njit(cache=True, nogil=True)
def _packed_keys(xyz: np.ndarray, voxel: float, origin_key: np.ndarray) -> np.ndarray:
    """:func:`packed_key` of every point (N, 3)."""
    packed = np.empty(len(xyz), dtype=np.int64)
    for i in range(len(xyz)):
        packed[i] = packed_key(xyz[i], voxel, origin_key)
    return packed


@numba.njit(cache=True, nogil=True)
def hash_slot(key: np.int64, bits: int) -> int:
    """A key's first slot in a hash table of 2**bits slots (Fibonacci hashing: the top bits of
    the key times 2**64 / golden ratio)."""
    return np.int64((np.uint64(key) * np.uint64(11400714819323198485)) >> np.uint64(64 - bits))


@numba.njit(cache=True, nogil=True)
def _first_of_each(keys: np.ndarray) -> np.ndarray:
    """Ascending indices of the first occurrence of every distinct value of ``keys`` (int64),
    in one pass through an open-addressing hash table (the same indices as ``np.unique``'s
    ``return_index``, sorted, without sorting the keys)."""
    bits = 1
    while (1 << bits) < 2 * len(keys):
        bits += 1
    slot_of = np.full(1 << bits, -1, dtype=np.int64)  # index of the key held by each slot
    mask = (1 << bits) - 1
    first = np.empty(len(keys), dtype=np.int64)
    count = 0
    for i in range(len(keys)):
        slot = hash_slot(keys[i], bits)
        while True:
            held = slot_of[slot]
            if held < 0:
                slot_of[slot] = i
                first[count] = i
                count += 1
                break
            if keys[held] == keys[i]:
                break
            slot = (slot + 1) & mask
    return first[:count]


def _sorted_contains(sorted_keys: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Whether each of ``keys`` is in the sorted array ``sorted_keys``."""
    if len(sorted_keys) == 0:
        return np.zeros(len(keys), dtype=bool)
    # searched in ascending order: each search starts from the last one's place
    order = np.argsort(keys)
    wanted = keys[order]
    position = np.minimum(np.searchsorted(sorted_keys, wanted), len(sorted_keys) - 1)
    found = np.empty(len(keys), dtype=bool)
    found[order] = sorted_keys[position] == wanted
    return found
