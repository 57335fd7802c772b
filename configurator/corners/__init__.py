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

The modules: ``levels`` (steps 1 and 2), ``footprint`` (3), ``simplify`` (4), ``wall_lines``
(5), ``detect`` (the whole detection and the approximate floor), ``scan_frame`` (a scan file's
corners in its own coordinates and their ``synthdet.corners/1`` form) and ``params`` (tuning,
result and error). This package file exports the public interface.
"""
from configurator.corners.detect import approximate_outline, detect_corners, room_outline
from configurator.corners.params import CornerDetectionError, CornerParams, RoomOutline
from configurator.corners.scan_frame import (SCAN_VOXEL, corners_for_scan, outline_in_scan,
                                             outline_to_dict, scan_outline)

__all__ = [
    'SCAN_VOXEL', 'CornerDetectionError', 'CornerParams', 'RoomOutline', 'approximate_outline',
    'corners_for_scan', 'detect_corners', 'outline_in_scan', 'outline_to_dict', 'room_outline',
    'scan_outline'
]
