"""The room outline of a scan's points: traced and fitted, or approximate."""
from __future__ import annotations
import math

import numpy as np

from configurator.corners.footprint import traced_outline
from configurator.corners.levels import (Levels, dominant_wall_angle, floor_prominence,
                                         main_cluster, room_levels, subsample, wall_points)
from configurator.corners.params import CornerDetectionError, CornerParams, RoomOutline
from configurator.corners.simplify import edge_length, simplify_outline
from configurator.corners.wall_lines import (WallLine, drop_wall_less_bumps, fit_wall_lines,
                                             intersect_lines, snap_directions)
from synthdet.geometry import (distance_to_polygon, first_self_crossing, points_in_polygon,
                               rotation2d, signed_area)


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

    outline, cell, outline_error = traced_outline(frame_xy, params)
    outline = simplify_outline(
        outline, tolerance=1.5 * cell, min_edge=params.min_edge, min_turn=params.min_turn)
    if len(outline) < 3:
        raise CornerDetectionError('no walls found: the footprint of the points has no area')
    lines = fit_wall_lines(outline, frame_walls, outline_error + 0.05, params)
    supported = sum(line.support * edge_length(outline, i) for i, line in enumerate(lines))
    perimeter = sum(edge_length(outline, i) for i in range(len(outline)))
    seen = supported / perimeter
    failure = None
    if seen < params.min_wall_support:
        failure = (f'no walls found: wall points back only {seen:.0%} of the room outline '
                   f'(need {params.min_wall_support:.0%})')
    else:
        lines = drop_wall_less_bumps(lines, params)
        lines = snap_directions(lines, params.snap_angle)
        corners = intersect_lines(lines, params.min_edge, params.min_turn)
        failure = _outline_failure(corners)
    walled = None
    if failure or seen < params.min_seen_walls:  # the footprint follows occlusions: walls first
        from configurator.wall_evidence import walls_first_outline  # it imports this package
        walled = walls_first_outline(xyz, levels, to_frame, failure, params)
    if walled is not None and (failure or walled.seen > seen):  # else the traced one is better
        corners, seen, lines = walled.corners, walled.seen, []
    else:
        walled = None

    corners = corners @ rotation2d(angle).T
    corners = canonical_order(corners)
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
    outline, cell, _ = traced_outline(frame_xy, params)
    shape = 'footprint outline'
    if len(outline) >= 3:
        outline = simplify_outline(
            outline, tolerance=max(3 * cell, 0.1), min_edge=max(params.min_edge, 0.5),
            min_turn=params.min_turn)
    if len(outline) < 3 or len(outline) > params.max_approximate_corners or \
            first_self_crossing(outline) is not None or \
            points_in_polygon(subsample(frame_xy, params.max_quality_points),
                              outline).mean() < params.min_approximate_share:
        low, high = np.percentile(frame_xy, [0.5, 99.5], axis=0)
        outline = np.array([[low[0], low[1]], [low[0], high[1]], [high[0], high[1]],
                            [high[0], low[1]]])
        shape = 'oriented bounding rectangle'
    corners = canonical_order(outline @ rotation2d(angle).T)
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


def canonical_order(corners: np.ndarray) -> np.ndarray:
    """Clockwise order starting at the corner nearest the bounding box's (min x, min y)."""
    if signed_area(corners) > 0:
        corners = corners[::-1]
    start = int(np.argmin(np.linalg.norm(corners - corners.min(axis=0), axis=1)))
    return np.roll(corners, -start, axis=0)


def _quality(corners: np.ndarray, xyz: np.ndarray, floor_z: float, ceiling_z: float,
             lines: list[WallLine], params: CornerParams) -> dict[str, float]:
    """Quality figures of an outline (``docs/corners.md`` defines them)."""
    xyz = subsample(xyz, params.max_quality_points)
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
