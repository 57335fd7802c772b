"""Tuning, result and error of the corner detection (:mod:`configurator.corners`)."""
from __future__ import annotations
import math
from dataclasses import dataclass, field

import numpy as np


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
