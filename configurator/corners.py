"""Room corners from a scan: floor and ceiling levels, traced room outline, clockwise corners.

Method (``docs/corners.md`` explains it in full):

1. floor and ceiling levels are the lowest and highest strong peaks of the z histogram;
2. wall points are the points between them (a margin away from both); their dominant
   directions come from a rotation search that makes their projections sharpest;
3. in that wall-aligned frame, every point is binned into a 2D occupancy grid; closing,
   hole filling and opening leave the room's footprint (a second, coarser grid adds
   sparsely scanned parts), whose boundary is traced (crack following) into a polygon;
   this works for L-, U- and T-shaped rooms, where angle ordering and convex hulls fail;
4. the polygon is simplified (Douglas-Peucker, then walls shorter than ``min_edge`` are
   merged into their neighbours, the 1D analogue of clustering corner candidates with
   an eps);
5. each wall line is refitted to the wall points near it (a histogram peak, then a
   total-least-squares fit), snapped to the dominant directions when within
   ``snap_angle``, and consecutive lines are intersected into the corners.

Wall points are points of vertical columns that reach up (``wall_reach``): furniture against
a wall does not, so its faces never become walls. A scan without a ceiling (an open-top mesh)
gets walls of ``default_wall_height``. An outline that walls back too little of is built on
the scan's wall planes instead (:mod:`configurator.wall_evidence`, a partial outline).
:func:`room_outline` never gives up on a real room:
when the outline cannot be traced it returns an approximate floor (the footprint's outline or
its oriented bounding rectangle) marked ``approximate_floor`` in the quality figures.
"""
from __future__ import annotations
import math
import os
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from configurator.lattice_outline import trace_boundary
from synthdet.contracts import CORNERS_FORMAT
from synthdet.geometry import (distance_to_polygon, first_self_crossing, points_in_polygon,
                               rotation2d, signed_area)
from synthdet.prepare import PreparedScan, prepare_scan
from synthdet.scan_io import load_scan


class CornerDetectionError(ValueError):
    """The scan does not show a room: no points, non-finite values, or no walls."""


@dataclass(frozen=True)
class CornerParams:
    """Tuning of :func:`detect_corners`; lengths in metres, angles in radians."""

    level_bin: float = 0.01  # z histogram bin for the floor and ceiling levels
    min_room_height: float = 1.0  # a smaller vertical extent has no walls
    wall_margin: float = 0.12  # wall points stay this far from the floor and ceiling
    angle_cell: float = 0.02  # wall-point grid cell of the rotation search
    points_per_cell: float = 8.0  # footprint cell size targets this many points per cell
    min_cell: float = 0.04
    max_cell: float = 0.2
    min_island_cells: int = 6  # smaller groups of occupied cells are outliers
    coarse_cell: float = 0.2  # second footprint scale, for sparsely scanned parts of a room
    min_sparse_area: float = 1.0  # smaller sparsely scanned regions are not added (m^2)
    min_edge: float = 0.25  # shorter walls are merged into their neighbours
    min_turn: float = math.radians(12)  # smaller direction changes are not corners
    snap_angle: float = math.radians(5)  # walls this close to a dominant direction snap to it
    inlier_width: float = 0.03  # half width of the slab of points that belong to a wall plane
    on_polygon_tol: float = 0.05  # quality: wall points this close to the outline are on it
    min_wall_support: float = 0.4  # fraction of the outline that must be backed by wall points
    min_line_support: float = 0.15  # edges with less of their length backed are no walls
    max_fit_points: int = 300_000  # wall points used for the fits (every k-th point)
    max_quality_points: int = 50_000  # wall points used for the quality figures
    cluster_gap: float = 2.0  # points beyond an empty gap this wide (x or y) are far outliers
    min_floor_prominence: float = 3.0  # the floor level is this many times denser than walls
    min_level_peak: float = 0.05  # a floor peak holds this share of the biggest lower peak
    floor_cell: float = 0.5  # plan grid on which the floor level must span the scan
    min_floor_cover: float = 0.3  # share of the scan's occupied plan cells the floor spans
    min_inner_cover: float = 0.5  # a level spanning this share of the inner plan cells is a
    # floor (or ceiling) however sparse: reconstructed meshes sampled per vertex
    wall_reach: float = 1.6  # wall columns reach this high above the floor (or 60 % of the
    # room height if lower); furniture does not
    wall_column: float = 0.2  # plan cell of the wall-column test
    default_wall_height: float = 2.5  # walls of a scan without a ceiling are at least this tall
    min_seen_walls: float = 0.75  # an outline backed less than this by walls is partial
    max_approximate_corners: int = 16  # a rougher approximate footprint becomes a rectangle
    min_approximate_share: float = 0.97  # ... so does one holding a smaller share of the points


@dataclass
class RoomOutline:
    """Result of :func:`detect_corners`: the room polygon and its levels."""

    corners: np.ndarray  # (K, 2) metres, clockwise seen from above, scan frame
    floor_z: float
    ceiling_z: float
    wall_angle: float  # dominant wall direction in [0, pi/2), radians
    quality: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)  # warnings: approximate floor, no ceiling

    @property
    def approximate(self) -> bool:
        """Whether the floor is a fallback (footprint or rectangle), not a traced outline."""
        return bool(self.quality.get('approximate_floor', 0.0))


@dataclass
class _WallLine:
    point: np.ndarray  # a point on the line
    direction: np.ndarray  # unit vector along the polygon's clockwise traversal
    inliers: int = 0
    support: float = 0.0  # fraction of the edge length backed by inlier points


# --------------------------------------------------------------------------- public API


def detect_corners(points: np.ndarray, params: CornerParams | None = None) -> RoomOutline:
    """Find the room outline of a scan given as an ``(N, >=3)`` array of ``x y z ...``."""
    params = params or CornerParams()
    xyz = _checked_xyz(points)
    # far outliers cost nothing: every grid below spans only the room's own cluster of points,
    # in float64 relative to a local origin (georeferenced coordinates keep their precision)
    xyz, origin, far_points = _room_cluster(xyz, params)
    levels = room_levels(xyz, params)
    floor_z, ceiling_z = levels.floor_z, levels.ceiling_z
    wall_xy = wall_points(xyz, levels, params)
    if len(wall_xy) < 100:
        raise CornerDetectionError(f'no walls found: only {len(wall_xy)} points lie between '
                                   f'the floor (z={floor_z:.2f}) and ceiling (z={ceiling_z:.2f})')

    angle = dominant_wall_angle(wall_xy, params.angle_cell)
    to_frame = rotation2d(-angle)  # wall-aligned frame: dominant walls along the axes
    frame_xy = xyz[:, :2] @ to_frame.T
    frame_walls = wall_xy @ to_frame.T

    outline, cell, outline_error = _traced_outline(frame_xy, params)
    outline = simplify_outline(
        outline, tolerance=1.5 * cell, min_edge=params.min_edge, min_turn=params.min_turn)
    if len(outline) < 3:
        raise CornerDetectionError('no walls found: the footprint of the points has no area')
    lines = _fit_wall_lines(outline, frame_walls, outline_error + 0.05, params)
    supported = sum(line.support * _edge_length(outline, i) for i, line in enumerate(lines))
    perimeter = sum(_edge_length(outline, i) for i in range(len(outline)))
    seen = supported / perimeter
    failure = None
    if seen < params.min_wall_support:
        failure = (f'no walls found: wall points back only {seen:.0%} of the room outline '
                   f'(need {params.min_wall_support:.0%})')
    else:
        lines = _drop_wall_less_bumps(lines, params)
        lines = _snap_directions(lines, params.snap_angle)
        corners = _intersect_lines(lines, params.min_edge, params.min_turn)
        failure = _outline_failure(corners)
    walled = None
    if failure or seen < params.min_seen_walls:  # the footprint follows occlusions: walls first
        from configurator.wall_evidence import walls_first_outline  # it imports this module
        walled = walls_first_outline(xyz, levels, to_frame, failure, params)
    if walled is not None and (failure or walled.seen > seen):  # else the traced one is better
        corners, seen, lines = walled.corners, walled.seen, []
    else:
        walled = None

    corners = corners @ rotation2d(angle).T
    corners = _canonical_order(corners)
    quality = _quality(corners, xyz, floor_z, ceiling_z, lines, params)
    quality['walls_seen'] = seen
    if walled is not None:
        quality['min_wall_support'] = float(walled.supports.min())
    _check_floor(xyz, levels, quality, far_points, params)
    notes = list(levels.notes)
    if seen < params.min_seen_walls:
        notes.append(f'partial outline: walls back only {seen:.0%} of it (a view of one side '
                     'of the room?); the rest follows the extent of the points')
    return RoomOutline(
        corners=corners + origin,
        floor_z=floor_z,
        ceiling_z=ceiling_z,
        wall_angle=float(angle % (math.pi / 2)),
        quality=quality,
        notes=notes)


def _outline_failure(corners: np.ndarray) -> str | None:
    """Why fitted corners are no room outline (too few, crossing), or None."""
    if len(corners) < 3:
        return 'no walls found: fewer than 3 wall lines were fitted'
    crossing = first_self_crossing(corners)
    if crossing is not None:
        return (f'the fitted outline crosses itself (walls {crossing[0]} and {crossing[1]}); '
                'the scan is too sparse or not one room')
    return None


def _checked_xyz(points: np.ndarray) -> np.ndarray:
    """The ``(N, 3)`` float64 coordinates of ``(N, >=3)`` points; raises for no points, a
    wrong shape or non-finite values."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] < 3:
        raise CornerDetectionError(f'points must be an (N, 3+) array, got shape {points.shape}')
    if len(points) == 0:
        raise CornerDetectionError('the scan holds no points')
    xyz = points[:, :3].astype(np.float64, copy=False)
    bad = ~np.isfinite(xyz.sum(axis=1))  # NaN and inf propagate through the sum
    if bad.any():
        raise CornerDetectionError(f'the scan has {int(bad.sum())} points with non-finite '
                                   f'coordinates (first at row {int(np.flatnonzero(bad)[0])})')
    return xyz


def _room_cluster(xyz: np.ndarray, params: CornerParams) -> tuple[np.ndarray, np.ndarray, float]:
    """The room's own cluster of points relative to a local origin (far outliers out), the
    origin and the number of points left out."""
    keep = main_cluster(xyz[:, :2], params.cluster_gap)
    origin = np.floor(xyz[keep, :2].min(axis=0))
    return xyz[keep] - np.array([origin[0], origin[1], 0.0]), origin, float(len(xyz) - len(keep))


def _check_floor(xyz: np.ndarray, levels: Levels, quality: dict[str, float],
                 far_points: float, params: CornerParams) -> None:
    """Add the level figures to ``quality``; raise if the lowest level is no floor: neither
    ``min_floor_prominence`` times as dense as the walls nor spanning ``min_inner_cover`` of
    the room's inner plan cells and a quarter of them more than a slab of the walls does."""
    quality['far_points'] = far_points
    quality['floor_prominence'] = floor_prominence(xyz[:, 2], levels.floor_z, levels.ceiling_z,
                                                   params)
    quality['floor_cover'] = levels.floor_cover
    quality['ceiling_found'] = float(levels.ceiling_found)
    quality['approximate_floor'] = 0.0
    spans = levels.floor_cover >= max(params.min_inner_cover, levels.wall_cover + 0.25)
    if quality['floor_prominence'] < params.min_floor_prominence and not spans:
        raise CornerDetectionError(
            f'no floor found: the lowest level (z={levels.floor_z + 0.0:.2f}) is only '
            f'{quality["floor_prominence"]:.1f} times as dense as the walls (a floor is at least '
            f'{params.min_floor_prominence:g} times) and spans {levels.floor_cover:.0%} of the '
            f"room's inside (a floor at least {params.min_inner_cover:.0%} and a quarter more "
            'than the walls); the scan has no floor, so its levels are unknown')


def room_outline(points: np.ndarray, params: CornerParams | None = None) -> RoomOutline:
    """:func:`detect_corners`, or when the outline cannot be traced (no floor, too few walls,
    a self-crossing fit) :func:`approximate_outline`, with the reason in its notes.

    Raises :class:`CornerDetectionError` only when there is no room at all: no points,
    non-finite values, a scan under ``min_room_height`` tall."""
    try:
        return detect_corners(points, params)
    except CornerDetectionError as error:
        reason = str(error)
    return approximate_outline(points, params, reason)


def approximate_outline(points: np.ndarray,
                        params: CornerParams | None = None,
                        reason: str = '') -> RoomOutline:
    """An approximate floor polygon: the outline of the points' footprint (simplified), or its
    oriented bounding rectangle (0.5th to 99.5th percentiles along the walls) when that
    outline is rough, crosses itself or leaves out more than 3 % of the points (objects seen
    apart from the floor), on the floor level found (the lowest dense level). Marked
    ``approximate_floor`` = 1 in the quality."""
    params = params or CornerParams()
    xyz, origin, far_points = _room_cluster(_checked_xyz(points), params)
    levels = room_levels(xyz, params)
    walls = wall_points(xyz, levels, params)
    angle = dominant_wall_angle(walls, params.angle_cell) if len(walls) >= 100 else \
        dominant_wall_angle(xyz[:, :2], params.angle_cell)
    frame_xy = xyz[:, :2] @ rotation2d(-angle).T
    outline, cell, _ = _traced_outline(frame_xy, params)
    shape = 'footprint outline'
    if len(outline) >= 3:
        outline = simplify_outline(
            outline, tolerance=max(3 * cell, 0.1), min_edge=max(params.min_edge, 0.5),
            min_turn=params.min_turn)
    if len(outline) < 3 or len(outline) > params.max_approximate_corners or \
            first_self_crossing(outline) is not None or \
            points_in_polygon(_subsample(frame_xy, params.max_quality_points),
                              outline).mean() < params.min_approximate_share:
        low, high = np.percentile(frame_xy, [0.5, 99.5], axis=0)
        outline = np.array([[low[0], low[1]], [low[0], high[1]], [high[0], high[1]],
                            [high[0], low[1]]])
        shape = 'oriented bounding rectangle'
    corners = _canonical_order(outline @ rotation2d(angle).T)
    quality = _quality(corners, xyz, levels.floor_z, levels.ceiling_z, [], params)
    quality['walls_seen'] = 0.0
    try:
        _check_floor(xyz, levels, quality, far_points, params)
        floor_note = ''
    except CornerDetectionError:
        floor_note = ' on the lowest dense level (no floor plane found)'
    quality['approximate_floor'] = 1.0
    reason = f' ({reason})' if reason else ''
    notes = [f'approximate floor: the {shape} of the points{floor_note}; the room outline '
             f'could not be traced{reason}', *levels.notes]
    return RoomOutline(
        corners=corners + origin,
        floor_z=levels.floor_z,
        ceiling_z=levels.ceiling_z,
        wall_angle=float(angle % (math.pi / 2)),
        quality=quality,
        notes=notes)


SCAN_VOXEL = 0.02  # metres: scans are read keeping one point per voxel of this size


def corners_for_scan(scan_path: str | os.PathLike,
                     params: CornerParams | None = None,
                     *,
                     voxel: float | None = SCAN_VOXEL,
                     columns: str | None = None,
                     approximate: bool = True) -> dict:
    """Read and prepare a scan file and return its ``synthdet.corners/1`` dictionary, in the
    scan's own coordinates; by default an approximate floor (``quality.approximate_floor``
    = 1) when the outline cannot be traced, so that a real scan always gives a document."""
    outline, _ = scan_outline(
        scan_path, params, voxel=voxel, columns=columns, approximate=approximate)
    return outline_to_dict(outline, str(scan_path))


def scan_outline(scan_path: str | os.PathLike,
                 params: CornerParams | None = None,
                 *,
                 voxel: float | None = SCAN_VOXEL,
                 columns: str | None = None,
                 approximate: bool = False) -> tuple[RoomOutline, PreparedScan]:
    """Stream a scan (``synthdet.scan_io.load_scan``), prepare it (``synthdet.prepare``: no
    outliers, z up, floor level, walls along the axes), find its outline there and return
    the outline in the scan's own coordinates with the prepared scan. ``approximate``: an
    approximate floor (:func:`room_outline`) rather than an error when none can be traced."""
    prepared = prepare_scan(load_scan(scan_path, voxel=voxel, columns=columns))
    find = room_outline if approximate else detect_corners
    return outline_in_scan(find(prepared.points, params), prepared), prepared


def outline_in_scan(outline: RoomOutline, prepared: PreparedScan) -> RoomOutline:
    """An outline found in the prepared frame, in the scan's coordinates: corners on the
    floor, floor and ceiling heights at the room's centre (exact for a level scan)."""
    corners = _canonical_order(prepared.points_to_scan(outline.corners))
    centre = outline.corners.mean(axis=0)
    levels = prepared.points_to_scan(
        np.array([[centre[0], centre[1], outline.floor_z],
                  [centre[0], centre[1], outline.ceiling_z]]))
    angle = (outline.wall_angle + prepared.yaw) % (math.pi / 2)
    return RoomOutline(
        corners=corners,
        floor_z=float(levels[0, 2]),
        ceiling_z=float(levels[1, 2]),
        wall_angle=float(angle),
        quality=dict(outline.quality),
        notes=list(outline.notes))


def outline_to_dict(outline: RoomOutline, scan: str) -> dict:
    """The ``synthdet.corners/1`` dictionary of an outline found in the scan ``scan``."""
    return {
        'format':
        CORNERS_FORMAT,
        'scan':
        scan,
        'corners': [
            [round(float(x), 4) + 0.0, round(float(y), 4) + 0.0]  # + 0.0: no '-0.0'
            for x, y in outline.corners
        ],
        'floor_z':
        round(float(outline.floor_z), 4),
        'ceiling_z':
        round(float(outline.ceiling_z), 4),
        'quality': {
            key: round(float(value), 4)
            for key, value in outline.quality.items()
        },
    }


# --------------------------------------------------------------------------- levels and angle


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
    return _subsample(band[keep, :2], params.max_fit_points)


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


# --------------------------------------------------------------------------- footprint tracing


def _traced_outline(frame_xy: np.ndarray, params: CornerParams) -> tuple[np.ndarray, float, float]:
    """Trace the boundary of the points' footprint.

    Returns the clockwise polygon, the grid cell and the largest boundary error to expect
    (metres). The footprint is found at two scales: the fine grid gives accurate edges
    where the scan is dense, a grid ``coarse_factor`` times coarser adds the regions the
    fine grid sees as empty because they were scanned sparsely (such as the far arm of a
    U-shaped room); a thin rim of the coarse footprint around the fine one is dropped.
    """
    low = frame_xy.min(axis=0)
    extent = frame_xy.max(axis=0) - low
    area = max(float(extent[0] * extent[1]), 1e-6)
    cell = float(
        np.clip(
            math.sqrt(params.points_per_cell * area / len(frame_xy)), params.min_cell,
            params.max_cell))
    factor = max(2, math.ceil(params.coarse_cell / cell))
    pad = 2 * factor
    shape = np.floor(extent / cell).astype(int) + 1 + 2 * pad
    shape = -(-shape // factor) * factor  # whole coarse cells
    keys = np.floor((frame_xy - low) / cell).astype(np.int64) + pad
    counts = np.bincount(
        keys[:, 0] * shape[1] + keys[:, 1], minlength=shape[0] * shape[1]).reshape(shape)
    fine = _solid_footprint(counts > 0, params.min_island_cells, iterations=2)
    coarse_counts = counts.reshape(shape[0] // factor, factor, shape[1] // factor,
                                   factor).sum(axis=(1, 3))
    coarse = _solid_footprint(coarse_counts >= 2, params.min_island_cells, iterations=1)
    coarse = np.repeat(np.repeat(coarse, factor, axis=0), factor, axis=1)
    square = np.ones((3, 3), dtype=bool)
    sparse = ndimage.binary_opening(coarse & ~fine, square, iterations=factor)
    labels, _ = ndimage.label(sparse)
    sizes = np.bincount(labels.ravel()) * cell**2
    sparse &= sizes[labels] >= params.min_sparse_area  # whole room parts, not outlier bumps
    footprint = ndimage.binary_fill_holes(ndimage.binary_closing(fine | sparse, square))
    labels, count = ndimage.label(footprint)
    if count == 0:
        return np.zeros((0, 2)), cell, cell
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    footprint = labels == int(np.argmax(sizes))
    loop = trace_boundary(footprint)
    origin = low - pad * cell
    error = factor * cell if (sparse & footprint).any() else 2 * cell
    return origin + loop * cell, cell, error


def _solid_footprint(occupied: np.ndarray, min_island: int, iterations: int) -> np.ndarray:
    """Occupied cells without small islands, closed, hole-filled and opened."""
    square = np.ones((3, 3), dtype=bool)
    # small islands (outliers) go before closing could join them into loops around empty cells
    labels, _ = ndimage.label(occupied, square)
    sizes = np.bincount(labels.ravel())
    occupied = occupied & (sizes[labels] >= min_island)
    occupied = ndimage.binary_closing(occupied, square, iterations=iterations)
    occupied = ndimage.binary_fill_holes(occupied)
    return ndimage.binary_opening(occupied, square, iterations=iterations)


# --------------------------------------------------------------------------- simplification


def simplify_outline(polygon: np.ndarray, tolerance: float, min_edge: float,
                     min_turn: float) -> np.ndarray:
    """Simplify a closed clockwise polygon: Douglas-Peucker, then merge short walls.

    A wall shorter than ``min_edge`` disappears: if its neighbours are (anti)parallel (a
    jog or a spike) both its ends are dropped, otherwise its ends are replaced by the
    intersection of the neighbouring walls. Vertices turning less than ``min_turn`` go.
    """
    polygon = _douglas_peucker_closed(np.asarray(polygon, dtype=np.float64), tolerance)
    while len(polygon) >= 3:
        polygon = _drop_small_turns(polygon, min_turn)
        if len(polygon) < 3:
            break
        lengths = np.linalg.norm(np.roll(polygon, -1, axis=0) - polygon, axis=1)
        shortest = int(np.argmin(lengths))
        if lengths[shortest] >= min_edge:
            break
        polygon = _remove_edge(polygon, shortest)
    return polygon


def _douglas_peucker_closed(polygon: np.ndarray, tolerance: float) -> np.ndarray:
    if len(polygon) <= 3:
        return polygon
    first = 0
    far = int(np.argmax(np.linalg.norm(polygon - polygon[first], axis=1)))
    keep = np.zeros(len(polygon), dtype=bool)
    keep[[first, far]] = True
    closed = np.vstack([polygon, polygon[:1]])
    for start, end in ((first, far), (far, len(polygon))):
        stack = [(start, end)]
        while stack:
            i, j = stack.pop()
            if j - i < 2:
                continue
            a, b = closed[i], closed[j]
            segment = closed[i + 1:j]
            direction = b - a
            norm = np.linalg.norm(direction)
            if norm < 1e-12:
                distance = np.linalg.norm(segment - a, axis=1)
            else:
                distance = np.abs(direction[0] * (segment[:, 1] - a[1]) - direction[1] *
                                  (segment[:, 0] - a[0])) / norm
            k = int(np.argmax(distance))
            if distance[k] > tolerance:
                keep[i + 1 + k] = True
                stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return polygon[keep]


def _drop_small_turns(polygon: np.ndarray, min_turn: float) -> np.ndarray:
    while len(polygon) >= 3:
        incoming = polygon - np.roll(polygon, 1, axis=0)
        outgoing = np.roll(polygon, -1, axis=0) - polygon
        turn = np.abs(
            np.arctan2(incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0],
                       (incoming * outgoing).sum(axis=1)))
        weakest = int(np.argmin(turn))
        if turn[weakest] >= min_turn:
            break
        polygon = np.delete(polygon, weakest, axis=0)
    return polygon


def _remove_edge(polygon: np.ndarray, k: int) -> np.ndarray:
    """Remove edge k (from vertex k to k+1) of a closed polygon."""
    n = len(polygon)
    before, start, end, after = (polygon[(k + i) % n] for i in (-1, 0, 1, 2))
    crossing = _line_intersection(before, start - before, end, after - end, min_sine=0.5)
    kept = [i for i in range(n) if i not in (k, (k + 1) % n)]
    if crossing is None or n <= 4:
        return polygon[kept]
    result = polygon.copy()
    result[k] = crossing
    return np.delete(result, (k + 1) % n, axis=0)


def _line_intersection(p: np.ndarray, d: np.ndarray, q: np.ndarray, e: np.ndarray,
                       min_sine: float) -> np.ndarray | None:
    """Intersection of lines p + s d and q + t e, or None if they are nearly parallel."""
    cross = d[0] * e[1] - d[1] * e[0]
    if abs(cross) <= min_sine * np.linalg.norm(d) * np.linalg.norm(e):
        return None
    s = ((q[0] - p[0]) * e[1] - (q[1] - p[1]) * e[0]) / cross
    return p + s * d


def _edge_length(polygon: np.ndarray, i: int) -> float:
    return float(np.linalg.norm(polygon[(i + 1) % len(polygon)] - polygon[i]))


# --------------------------------------------------------------------------- wall line fits


def _fit_wall_lines(outline: np.ndarray, walls: np.ndarray, band: float,
                    params: CornerParams) -> list[_WallLine]:
    """Refit every outline edge to the wall points within ``band`` of it (wall frame)."""
    index = _BucketIndex(walls, bucket=0.5)
    lines = []
    for i in range(len(outline)):
        a, b = outline[i], outline[(i + 1) % len(outline)]
        length = float(np.linalg.norm(b - a))
        direction = (b - a) / length
        normal = np.array([-direction[1], direction[0]])  # outward for clockwise polygons
        margin = min(0.2, 0.3 * length)
        near = index.in_box(np.minimum(a, b) - band, np.maximum(a, b) + band)
        offset = (near - a) @ normal
        along = (near - a) @ direction
        near = near[(np.abs(offset) < band) & (along > margin) & (along < length - margin)]
        line = _WallLine(point=a.copy(), direction=direction)
        if len(near) >= 10:
            offset = (near - a) @ normal
            bins = np.arange(-band, band + 0.005, 0.005)
            hist = np.convolve(np.histogram(offset, bins)[0], np.ones(5), mode='same')
            peak = bins[int(np.argmax(hist))] + 0.0025
            inliers = near[np.abs(offset - peak) < params.inlier_width]
            for _ in range(2):  # total least squares, then refit on the fitted line's slab
                if len(inliers) < 10:
                    break
                centre = inliers.mean(axis=0)
                _, vectors = np.linalg.eigh(np.cov((inliers - centre).T))
                fitted = vectors[:, 1] * np.sign(vectors[:, 1] @ direction)
                line = _WallLine(point=centre, direction=fitted, inliers=len(inliers))
                residual = (near - centre) @ np.array([-fitted[1], fitted[0]])
                inliers = near[np.abs(residual) < params.inlier_width]
            if line.inliers:
                usable = max(length - 2 * margin, 1e-6)
                along = (inliers - a) @ direction
                covered = np.unique(np.floor((along - margin) / 0.1).astype(int))
                line.support = float(min(1.0, len(covered) * 0.1 / usable))
        lines.append(line)
    return lines


def _drop_wall_less_bumps(lines: list[_WallLine], params: CornerParams) -> list[_WallLine]:
    """Drop runs of edges without wall points that bulge out of one straight wall.

    Such a bump is floor or clutter seen through a door. It is recognised by its neighbours,
    which are the two halves of one wall (parallel and within 10 cm). An unsupported run
    between different walls, such as a sparsely scanned arm, is kept.
    """
    weak = [line.support < params.min_line_support for line in lines]
    if all(weak) or not any(weak):
        return lines
    count = len(lines)
    drop = np.zeros(count, dtype=bool)
    start = next(i for i in range(count) if not weak[i])  # begin the walk at a supported line
    i = start
    for _ in range(count):
        j = (i + 1) % count
        if not weak[i] and weak[j]:
            end = j
            while weak[end]:
                end = (end + 1) % count
            before, after = lines[i], lines[end]
            sine = abs(before.direction[0] * after.direction[1] -
                       before.direction[1] * after.direction[0])
            normal = np.array([-before.direction[1], before.direction[0]])
            offset = abs(float((after.point - before.point) @ normal))
            if sine < math.sin(params.min_turn) and offset < 0.1 and \
                    before.direction @ after.direction > 0:
                k = j
                while k != end:
                    drop[k] = True
                    k = (k + 1) % count
        i = j
    return [line for line, dropped in zip(lines, drop) if not dropped]


class _BucketIndex:
    """2D points sorted into square buckets, for fast bounding-box queries."""

    def __init__(self, points: np.ndarray, bucket: float):
        self.bucket = bucket
        self.origin = points.min(axis=0)
        keys = np.floor((points - self.origin) / bucket).astype(np.int64)
        self.rows = int(keys[:, 1].max()) + 1
        linear = keys[:, 0] * self.rows + keys[:, 1]
        order = np.argsort(linear, kind='stable')
        self.keys = linear[order]
        self.points = points[order]
        self.columns = int(keys[:, 0].max()) + 1

    def in_box(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """The points inside the axis-aligned box [low, high]."""
        first = np.maximum(np.floor((low - self.origin) / self.bucket).astype(int), 0)
        last = np.floor((high - self.origin) / self.bucket).astype(int)
        last = np.minimum(last, [self.columns - 1, self.rows - 1])
        chunks = []
        for column in range(first[0], last[0] + 1):
            start = np.searchsorted(self.keys, column * self.rows + first[1])
            stop = np.searchsorted(self.keys, column * self.rows + last[1], side='right')
            chunks.append(self.points[start:stop])
        if not chunks:
            return np.zeros((0, 2))
        near = np.concatenate(chunks)
        return near[((near >= low) & (near <= high)).all(axis=1)]


def _snap_directions(lines: list[_WallLine], snap_angle: float) -> list[_WallLine]:
    """Snap lines near the frame's axes to one common, refined Manhattan direction."""
    quarter = math.pi / 2
    deviations, weights = [], []
    for line in lines:
        theta = math.atan2(line.direction[1], line.direction[0])
        deviation = (theta + quarter / 2) % quarter - quarter / 2
        deviations.append(deviation)
        weights.append(line.inliers if abs(deviation) < snap_angle else 0)
    if sum(weights) == 0:
        return lines
    common = float(np.average(deviations, weights=weights))
    snapped = []
    for line, deviation in zip(lines, deviations):
        if abs(deviation) < snap_angle or line.inliers == 0:
            theta = math.atan2(line.direction[1], line.direction[0]) - deviation + common
            line = _WallLine(
                point=line.point,
                direction=np.array([math.cos(theta), math.sin(theta)]),
                inliers=line.inliers,
                support=line.support)
        snapped.append(line)
    return snapped


def _intersect_lines(lines: list[_WallLine], min_edge: float, min_turn: float) -> np.ndarray:
    """Corners between consecutive wall lines; degenerate walls are dropped and retried."""
    lines = list(lines)
    while len(lines) >= 3:
        n = len(lines)
        corners = []
        parallel = None
        for i in range(n):
            previous, current = lines[i - 1], lines[i]
            point = _line_intersection(
                previous.point,
                previous.direction,
                current.point,
                current.direction,
                min_sine=math.sin(min_turn))
            if point is None:
                parallel = i
                break
            corners.append(point)
        if parallel is not None:  # two consecutive (anti)parallel walls: keep the better one
            weaker = min((parallel - 1) % n, parallel, key=lambda j: lines[j].inliers)
            del lines[weaker]
            continue
        corners = np.array(corners)
        lengths = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
        edge_dirs = np.roll(corners, -1, axis=0) - corners
        agrees = np.einsum('ij,ij->i', edge_dirs, [line.direction for line in lines]) > 0
        bad = np.flatnonzero((lengths < min_edge / 2) | ~agrees)
        if len(bad) == 0:
            return corners
        del lines[int(min(bad, key=lambda j: lines[j].inliers))]
    return np.zeros((0, 2))


# --------------------------------------------------------------------------- output helpers


def _canonical_order(corners: np.ndarray) -> np.ndarray:
    """Clockwise order starting at the corner nearest the bounding box's (min x, min y)."""
    if signed_area(corners) > 0:
        corners = corners[::-1]
    start = int(np.argmin(np.linalg.norm(corners - corners.min(axis=0), axis=1)))
    return np.roll(corners, -start, axis=0)


def _subsample(points: np.ndarray, limit: int) -> np.ndarray:
    """At most about ``limit`` of the points: every k-th one (deterministic, no copy)."""
    return points[::max(1, math.ceil(len(points) / limit))]


def _quality(corners: np.ndarray, xyz: np.ndarray, floor_z: float, ceiling_z: float,
             lines: list[_WallLine], params: CornerParams) -> dict[str, float]:
    """Quality figures of an outline (``docs/corners.md`` defines them)."""
    xyz = _subsample(xyz, params.max_quality_points)
    upper = (xyz[:, 2] > floor_z + 0.6 * (ceiling_z - floor_z)) & \
        (xyz[:, 2] < ceiling_z - params.wall_margin)  # above most furniture
    distance = distance_to_polygon(xyz[upper, :2], corners)
    on = distance < params.on_polygon_tol
    outside = ~points_in_polygon(xyz[:, :2], corners) & \
        (distance_to_polygon(xyz[:, :2], corners) > params.on_polygon_tol)
    supports = [line.support for line in lines]
    return {
        'wall_points_on_polygon':
        float(on.mean()) if len(on) else 0.0,
        'wall_rms_residual_m':
        float(np.sqrt(np.mean(np.square(distance[on])))) if on.any() else params.on_polygon_tol,
        'points_outside_polygon':
        float(outside.mean()),
        'min_wall_support':
        float(min(supports)) if supports else 0.0,
    }
