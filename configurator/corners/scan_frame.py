"""Corners of a scan file in the scan's own coordinates, and their ``synthdet.corners/1`` form."""
from __future__ import annotations
import math
import os

import numpy as np

from configurator.corners.detect import canonical_order, detect_corners, room_outline
from configurator.corners.params import CornerParams, RoomOutline
from synthdet.contracts import CORNERS_FORMAT
from synthdet.prepare import PreparedScan, prepare_scan
from synthdet.scan_io import load_scan


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
    corners = canonical_order(prepared.points_to_scan(outline.corners))
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
