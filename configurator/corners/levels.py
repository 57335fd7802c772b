"""Floor and ceiling levels of a scan, its wall points and their dominant direction."""
from __future__ import annotations
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from configurator.corners.params import CornerDetectionError, CornerParams


@dataclass
class Levels:
    """Floor and ceiling of a scan (:func:`room_levels`)."""

    floor_z: float
    ceiling_z: float  # floor_z + the default wall height or more when no ceiling was found
    ceiling_found: bool
    floor_cover: float  # share of the inner plan cells the floor level spans
    wall_cover: float  # ... and the median share a 4 cm slab of the walls spans
    notes: list[str] = field(default_factory=list)


def find_levels(xyz: np.ndarray, params: CornerParams | None = None) -> tuple[float, float]:
    """Floor and ceiling heights of (N, 3) points (:func:`room_levels`)."""
    levels = room_levels(xyz, params)
    return levels.floor_z, levels.ceiling_z


def room_levels(xyz: np.ndarray, params: CornerParams | None = None) -> Levels:
    """Floor and ceiling of (N, 3) points from the peaks of their z histogram.

    The floor is the lowest peak of the lower half that holds ``min_level_peak`` of its
    biggest peak and whose points (within 2 bins) span ``min_floor_cover`` of the plan cells
    the scan occupies: chair seats or a table top can be denser than a floor that clutter
    hides, but they never span the room. Without such a peak, the lowest peak holding a
    quarter of the biggest. The ceiling is the highest peak of the upper half holding a
    quarter of its biggest and spanning ``min_floor_cover`` of the inner plan cells (cells
    not on the rim of the occupied plan: the tops of the walls of an open-top scan are a rim),
    and a quarter of them more than a slab of the walls does (walls of a small room reach
    into its inner cells);
    without one the scan is open-top and the ceiling is put ``default_wall_height`` above the
    floor, or at the highest points (99.9th z percentile) when they are higher.
    """
    params = params or CornerParams()
    xyz = xyz[::max(1, len(xyz) // params.max_fit_points)]  # levels need no more points
    z = xyz[:, 2]
    low, high = np.percentile(z, [0.1, 99.9])
    if high - low < params.min_room_height:
        raise CornerDetectionError(f'no walls found: the scan is only {high - low:.2f} m tall')
    edges = np.arange(low - 2 * params.level_bin, high + 3 * params.level_bin, params.level_bin)
    hist = np.convolve(np.histogram(z, edges)[0], [1, 2, 1], mode='same').astype(np.float64)
    centres = (edges[:-1] + edges[1:]) / 2
    is_peak = (hist >= np.roll(hist, 1)) & (hist >= np.roll(hist, -1)) & (hist > 0)
    lower = centres < (low + high) / 2

    strongest = hist[lower].max()
    cells = _plan_cells(xyz, params.floor_cell)
    least_cover = params.min_floor_cover * len(np.unique(cells))
    floor_peak = next(
        (peak
         for peak in np.flatnonzero(is_peak & lower & (hist >= params.min_level_peak * strongest))
         if len(np.unique(cells[np.abs(z - centres[peak]) < 2 * params.level_bin])) >=
         least_cover), None)
    if floor_peak is None:  # no level spans the scan: the lowest strong peak
        floor_peak = np.flatnonzero(is_peak & lower & (hist >= 0.25 * strongest))[0]
    floor_z = _level_at(z, centres[floor_peak], params.level_bin)
    inner = _inner_cells(xyz, params.floor_cell)
    floor_cover = _cover(cells, inner, np.abs(z - floor_z) < 2 * params.level_bin)
    # walls alone cover part of the inner cells of a small room: a floor or ceiling covers more
    slabs = np.linspace(floor_z + 0.3, high - 0.3, 8)
    wall_cover = float(np.median([
        _cover(cells, inner, np.abs(z - height) < 2 * params.level_bin) for height in slabs
    ]))
    upper = ~lower
    ceiling_z = None
    if hist[upper].max() >= 0.2 * hist[floor_peak]:
        least = max(params.min_floor_cover, wall_cover + 0.25)
        candidates = np.flatnonzero(is_peak & upper & (hist >= 0.25 * hist[upper].max()))
        for peak in candidates[::-1]:
            level = _level_at(z, centres[peak], params.level_bin)
            if _cover(cells, inner, np.abs(z - level) < 2 * params.level_bin) >= least:
                ceiling_z = level
                break
    if ceiling_z is not None:
        return Levels(floor_z, ceiling_z, True, floor_cover, wall_cover)
    height = max(params.default_wall_height, float(high) - floor_z)
    return Levels(
        floor_z,
        floor_z + height,
        False,
        floor_cover,
        wall_cover,
        notes=[f'no ceiling found (an open-top scan): walls get {height:.2f} m, the default '
               f'{params.default_wall_height:g} m or the highest points if higher'])


def _inner_cells(xyz: np.ndarray, cell: float) -> np.ndarray:
    """Keys (as :func:`_plan_cells`) of the occupied plan cells whose 8 neighbours are all
    occupied; all occupied cells when none is."""
    squares = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    shape = squares.max(axis=0) + 1
    grid = np.zeros(shape, dtype=bool)
    grid[squares[:, 0], squares[:, 1]] = True
    inner = ndimage.binary_erosion(grid, np.ones((3, 3), dtype=bool))
    ix, iy = np.nonzero(inner if inner.any() else grid)
    return ix * shape[1] + iy


def _cover(cells: np.ndarray, inner: np.ndarray, selected: np.ndarray) -> float:
    """Share of the ``inner`` cells holding at least one ``selected`` point."""
    return float(np.isin(inner, cells[selected]).mean()) if len(inner) else 0.0


def wall_points(xyz: np.ndarray, levels: Levels, params: CornerParams | None = None) -> np.ndarray:
    """Plan positions ``(M, 2)`` of the wall points: the points between the floor and the
    ceiling (``wall_margin`` away from both) in ``wall_column`` plan cells whose points reach
    ``wall_reach`` above the floor (or 60 % of the room height if lower). Walls are vertical
    surfaces that reach up; a sofa, a bed or a table against a wall does not, so its faces
    never pull a wall line into the room. At most about ``max_fit_points`` are returned."""
    params = params or CornerParams()
    z = xyz[:, 2]
    band = xyz[(z > levels.floor_z + params.wall_margin) &
               (z < levels.ceiling_z - params.wall_margin)]
    if len(band) == 0:
        return np.zeros((0, 2))
    reach = levels.floor_z + min(params.wall_reach, 0.6 * (levels.ceiling_z - levels.floor_z))
    columns = _plan_cells(band, params.wall_column)
    reaching = columns[band[:, 2] >= reach]
    if columns.max() < 2**24:  # a table of the columns (64 MB at most), else a sorted lookup
        keep = (np.bincount(reaching, minlength=int(columns.max()) + 1) > 0)[columns]
    else:
        keep = np.isin(columns, reaching)
    return subsample(band[keep, :2], params.max_fit_points)


def _plan_cells(xyz: np.ndarray, cell: float) -> np.ndarray:
    """One integer key per point: its ``cell`` x ``cell`` square of the plan."""
    squares = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    return squares[:, 0] * (int(squares[:, 1].max()) + 1) + squares[:, 1]


def main_cluster(xy: np.ndarray, gap: float) -> np.ndarray:
    """Indices of the points of the biggest cluster, split at empty gaps wider than ``gap``.

    The x and then the y coordinates of the kept points are sorted; a gap wider than ``gap``
    between consecutive values splits them, and the part with most points is kept; repeated
    until nothing changes. Time O(N log N) and memory O(N), whatever the coordinates' range.
    """
    keep = np.arange(len(xy))
    changed = True
    while changed:
        changed = False
        for axis in (0, 1):
            order = np.argsort(xy[keep, axis], kind='stable')
            values = xy[keep[order], axis]
            cuts = np.flatnonzero(np.diff(values) > gap) + 1
            if len(cuts):
                bounds = np.concatenate([[0], cuts, [len(values)]])
                biggest = int(np.argmax(np.diff(bounds)))
                keep = np.sort(keep[order[bounds[biggest]:bounds[biggest + 1]]])
                changed = True
    return keep


def floor_prominence(z: np.ndarray, floor_z: float, ceiling_z: float,
                     params: CornerParams) -> float:
    """How many times denser the floor level is than the walls: points within 2 cm of
    ``floor_z`` over the mean count of a 4 cm slab between floor and ceiling (margins off).
    """
    slab = 2 * params.level_bin
    at_floor = int(np.count_nonzero(np.abs(z - floor_z) < slab))
    low, high = floor_z + params.wall_margin, ceiling_z - params.wall_margin
    between = int(np.count_nonzero((z > low) & (z < high)))
    per_slab = between * 2 * slab / max(high - low, 2 * slab)
    return at_floor / max(per_slab, 1.0)


def _level_at(z: np.ndarray, peak: float, level_bin: float) -> float:
    near = z[np.abs(z - peak) < 4 * level_bin]
    return float(np.median(near))


def dominant_wall_angle(wall_xy: np.ndarray, cell: float = 0.02) -> float:
    """Direction in [0, pi/2) of the dominant (Manhattan) walls of 2D wall points.

    The points are binned into ``cell`` squares; for each candidate angle the occupied
    cells are projected onto the two rotated axes, and the angle whose 1D histograms are
    sharpest (largest sum of squared bin counts) wins: a coarse 1 degree sweep, then a
    0.05 degree refinement.
    """
    keys = np.floor((wall_xy - wall_xy.min(axis=0)) / cell).astype(np.int64)
    width = int(keys[:, 1].max()) + 1
    counts = np.bincount(keys[:, 0] * width + keys[:, 1])
    occupied = np.flatnonzero(counts)
    weights = counts[occupied].astype(np.float64)
    centres = np.stack([occupied // width, occupied % width], axis=1) * cell

    def sharpness(theta: float) -> float:
        c, s = math.cos(theta), math.sin(theta)
        score = 0.0
        for axis in (centres @ [c, s], centres @ [-s, c]):
            bins = np.floor((axis - axis.min()) / cell).astype(np.int64)
            score += float(np.square(np.bincount(bins, weights)).sum())
        return score

    coarse = np.radians(np.arange(0.0, 90.0, 1.0))
    best = coarse[int(np.argmax([sharpness(t) for t in coarse]))]
    fine = best + np.radians(np.arange(-1.0, 1.0001, 0.05))
    best = fine[int(np.argmax([sharpness(t) for t in fine]))]
    return float(best % (math.pi / 2))


def subsample(points: np.ndarray, limit: int) -> np.ndarray:
    """At most about ``limit`` of the points: every k-th one (deterministic, no copy)."""
    return points[::max(1, math.ceil(len(points) / limit))]
