"""Scan preparation, the same for detection and corners: outliers out, z up, floor level at
z = 0, walls along the axes, density as in training; every step adds one line to the report.

The prepared frame is a rigid motion of the scan's own (``PreparedScan.to_scan``), so results
found in it are written back in the scan's coordinates exactly (float64 throughout):
``boxes_to_scan`` and ``points_to_scan``. ``docs/scans.md`` explains each step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from synthdet.geometry import (dominant_direction, projection_sharpness, rotation_between,
                               rotation_z)
from synthdet.scan_io import LoadedScan

OUTLIER_CELL = 0.2  # metres: cells of the density test
MIN_NEIGHBOURS = 4  # a point whose 3 x 3 x 3 cells hold fewer points is an outlier ...
MIN_NEIGHBOUR_SHARE = 0.01  # ... or fewer than this share of the median point's neighbours
LEVEL_CELL = 0.02  # metres: height bins of the tilt search and floor fit
MAX_TILT = math.radians(8.0)  # the floor levelling searches tilts up to this
FIT_POINTS = 200_000  # at most this many points estimate the up axis, tilt and yaw
TILT_POINTS = 50_000  # ... and this many the tilt search
FOOTPRINT_CELL = 0.25  # metres: floor cells of the density figure
FAR_DENSITY = 2.0  # a density this many times off the target is reported as a warning
UP_AXIS_MARGIN = 1.5  # another axis is up if its floor evidence beats z's by this factor
UP_AXIS_POINTS = 20_000  # at most this many points search each axis's tilt
CAMERA_HALF_FOV = math.radians(40.0)  # wider than a Kinect's or RealSense's half view
FURNITURE_MARGIN = 1.5  # the floor's end holds this many times the points of the other end
AXIS_NAMES = ('x', 'y', 'z')


@dataclass
class PreparedScan:
    """A scan in the prepared frame (z up, floor at z = 0, walls along the axes)."""

    points: np.ndarray  # (N, 6) float64 x y z r g b, prepared frame
    to_scan: np.ndarray  # (4, 4) float64: prepared frame -> the scan file's coordinates
    yaw: float  # radians: the rotation about z that was undone (the walls' direction)
    report: list[str] = field(default_factory=list)
    up_axis: str = '+z'  # the scan's up direction: '+z', or e.g. '+y' for a y-up tablet scan
    source: str = ''
    density: float = 0.0  # points per m^2 of floor footprint before resampling

    @property
    def up_rotation(self) -> np.ndarray:
        """3x3 rotation turning the scan's up axis onto z: the identity for z-up scans.

        Results are written in the scan's coordinates turned by it (``output frame``), so
        boxes and corners of a y-up scan are seen from above as the contracts require."""
        return _up_rotation(self.up_axis)

    def output_matrix(self) -> np.ndarray:
        """(4, 4): the prepared frame -> the output frame (the scan's coordinates turned by
        ``up_rotation``), in which predictions and corners are written."""
        matrix = np.eye(4)
        matrix[:3, :3] = self.up_rotation
        return matrix @ self.to_scan

    def points_to_scan(self, points: np.ndarray) -> np.ndarray:
        """Points ``(K, 3)`` of the prepared frame in the scan's coordinates; ``(K, 2)``
        points are taken on the floor (z = 0) and returned as ``(K, 2)`` x y."""
        points = np.asarray(points, dtype=np.float64)
        flat = points.shape[-1] == 2
        xyz = np.column_stack([points, np.zeros(len(points))]) if flat else points
        matrix = self.output_matrix()
        moved = xyz @ matrix[:3, :3].T + matrix[:3, 3]
        return moved[:, :2] if flat else moved

    def boxes_to_scan(self, centers: np.ndarray, sizes: np.ndarray,
                      yaws: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Oriented boxes of the prepared frame (centres ``(K, 3)``, sizes ``(K, 3)`` along
        the box axes, yaws ``(K,)`` about z) in the scan's coordinates: centres moved exactly,
        sizes kept, yaws turned by the scan's yaw (a levelled tilt only moves the centres)."""
        centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        yaws = np.asarray(yaws, dtype=np.float64).reshape(-1)
        rotation = self.output_matrix()[:3, :3]
        directions = np.column_stack([np.cos(yaws), np.sin(yaws), np.zeros(len(yaws))])
        turned = directions @ rotation.T
        new_yaws = np.arctan2(turned[:, 1], turned[:, 0])
        return (self.points_to_scan(centers), np.asarray(sizes, dtype=np.float64).copy(), new_yaws)


def prepare_scan(loaded: LoadedScan,
                 *,
                 target_density: float | None = None,
                 remove_outliers: bool = True,
                 level: bool = True,
                 align_yaw: bool = True,
                 seed: int = 0) -> PreparedScan:
    """Prepare a loaded scan for detection and corners; each step adds a report line.

    ``target_density`` is the training data's points per m^2 of floor footprint: a denser
    scan is resampled down to it (at random, ``seed``); one far from it is warned about.
    """
    aligned = align_scan(
        loaded, remove_outliers=remove_outliers, level=level, align_yaw=align_yaw)
    return resample_to_density(aligned, target_density, seed)


def resample_to_density(aligned: PreparedScan,
                        target_density: float | None,
                        seed: int = 0) -> PreparedScan:
    """The last step of :func:`prepare_scan` on an :func:`align_scan` result: thinned at random
    (``seed``) to ``target_density`` when denser, a warning when far from it, one report line."""
    points, line = _resampled(aligned.points, aligned.density, target_density, seed)
    return replace(aligned, points=points, report=[*aligned.report, line])


def align_scan(loaded: LoadedScan,
               *,
               remove_outliers: bool = True,
               level: bool = True,
               align_yaw: bool = True) -> PreparedScan:
    """:func:`prepare_scan` without the resampling: outliers, up axis, levelling, yaw."""
    report = list(loaded.report)
    xyz = loaded.points[:, :3]
    keep = np.ones(len(xyz), dtype=bool)
    if remove_outliers:
        keep = ~sparse_points(xyz)
        dropped = int((~keep).sum())
        if dropped > len(xyz) / 2:  # not outliers: the whole scan is sparse
            keep[:] = True
            report.append(f'outliers: the scan is too sparse for the density test ({dropped:,} '
                          f'of {len(xyz):,} points in sparse cells); all kept')
        else:
            report.append(f'outliers: removed {dropped:,} points in sparse isolated '
                          f'{OUTLIER_CELL * 100:g} cm cells')
    points = loaded.points[keep]
    xyz = points[:, :3]
    sample = xyz[::max(1, len(xyz) // FIT_POINTS)]

    up_axis = detect_up_axis(sample, origin=loaded.origin)
    rotation = _up_rotation(up_axis)
    report.append(f'up axis: {up_axis}' +
                  ('' if up_axis == '+z' else ' (turned to z; results use the scan\'s axes '
                   'turned the same way)'))
    floor = 0.0
    if level:
        rotation, floor, line = _levelled(sample @ rotation.T, rotation)
        report.append(line)
    else:
        floor = float(np.percentile(sample @ rotation[2], 1.0))
        report.append('levelling: off; floor taken at the 1st height percentile')
    yaw = 0.0
    if align_yaw:
        heights = sample @ rotation[2] - floor
        top = float(np.percentile(heights, 95.0))
        band = (heights > 0.3) & (heights < max(0.6, top - 0.2))
        if band.sum() >= 100:
            angle = dominant_direction(sample[band] @ rotation[:2].T)
            yaw = angle if angle < math.pi / 4 else angle - math.pi / 2
            rotation = rotation_z(-yaw) @ rotation
            report.append(f'yaw: walls at {math.degrees(yaw):.2f} deg, turned onto the axes')
        else:
            report.append('yaw: no wall points between 0.3 m and the top; not aligned')
    else:
        report.append('yaw: alignment off')

    prepared = np.empty_like(points)
    prepared[:, :3] = xyz @ rotation.T
    prepared[:, 2] -= floor
    prepared[:, 3:] = points[:, 3:]
    to_scan = np.eye(4)
    to_scan[:3, :3] = rotation.T
    to_scan[:3, 3] = rotation.T @ np.array([0.0, 0.0, floor]) + loaded.origin

    density = floor_density(prepared[:, :3])
    return PreparedScan(
        points=prepared,
        to_scan=to_scan,
        yaw=yaw,
        report=report,
        up_axis=up_axis,
        source=loaded.source,
        density=density)


# --------------------------------------------------------------------------- outliers


def _packed_cells(xyz: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell keys of the points packed into one int64 (21 bits an axis around the points'
    median cell) and whether each point's cell fits that range (+-2^20 cells). The cells are
    counted in float64 first, so a stray point at 1e300 m is a cell that does not fit, not an
    int64 overflow."""
    cells = np.floor(xyz / cell)
    cells -= np.trunc(np.median(cells[::max(1, len(cells) // 100_000)], axis=0))
    fits = (np.abs(cells) < 2**20 - 2).all(axis=1)
    keys = np.where(fits[:, None], cells, 0.0).astype(np.int64) + 2**20
    return (keys[:, 0] << 42) | (keys[:, 1] << 21) | keys[:, 2], fits


def sparse_points(xyz: np.ndarray, cell: float = OUTLIER_CELL) -> np.ndarray:
    """Points in sparse isolated cells: their 3 x 3 x 3 neighbourhood of ``cell`` cubes holds
    fewer than ``MIN_NEIGHBOURS`` points, or fewer than ``MIN_NEIGHBOUR_SHARE`` of what the
    median point's holds. Cells are a sorted hash of the occupied ones, never a grid over the
    bounding box, so a point kilometres away costs what any other point costs."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=bool)
    packed, fits = _packed_cells(xyz, cell)
    cells, inverse, counts = np.unique(packed[fits], return_inverse=True, return_counts=True)
    neighbours = np.zeros(len(cells), dtype=np.int64)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                shifted = cells + ((dx << 42) + (dy << 21) + dz)
                position = np.minimum(np.searchsorted(cells, shifted), len(cells) - 1)
                neighbours += np.where(cells[position] == shifted, counts[position], 0)
    per_point = neighbours[inverse.ravel()]
    threshold = max(MIN_NEIGHBOURS, MIN_NEIGHBOUR_SHARE * float(np.median(per_point)))
    sparse = np.ones(len(xyz), dtype=bool)  # cells beyond the packed range: kilometres away
    sparse[fits] = per_point < threshold
    return sparse


# --------------------------------------------------------------------------- up axis, levelling


def _up_rotation(up_axis: str) -> np.ndarray:
    direction = np.zeros(3)
    direction[AXIS_NAMES.index(up_axis[1])] = 1.0 if up_axis[0] == '+' else -1.0
    return rotation_between(direction, [0.0, 0.0, 1.0])


def _end_masses(values: np.ndarray) -> tuple[float, float, float, float]:
    """Shares of points on the plane at each end of ``values`` (the densest 6 cm slab within
    30 cm of the 0.5th / 99.5th percentile) and in the 0.1-1.2 m band inside each end."""
    low, high = np.percentile(values, [0.5, 99.5])
    count = float(len(values))

    def slab(start: float, stop: float) -> float:
        inside = np.sort(values[(values >= start) & (values <= stop)])
        if len(inside) == 0:
            return 0.0
        return float(np.max(np.searchsorted(inside, inside + 0.06) - np.arange(len(inside))))

    def band(start: float, stop: float) -> float:
        return float(((values > start) & (values < stop)).sum())

    return (slab(low - 0.05, low + 0.3) / count, slab(high - 0.3, high + 0.05) / count,
            band(low + 0.1, low + 1.2) / count, band(high - 1.2, high - 0.1) / count)


def _levelled_end_masses(xyz: np.ndarray, axis: int) -> tuple[np.ndarray, tuple[float, ...]]:
    """:func:`_end_masses` of the heights along ``axis`` tilted by up to ``MAX_TILT`` (2 degree
    steps) towards the two other axes, at the tilt with the biggest end plane: a floor a few
    degrees off the axis spreads over more than a 6 cm slab. Returns the heights too."""
    others = [a for a in range(3) if a != axis]
    search = xyz[::max(1, len(xyz) // UP_AXIS_POINTS)]
    slopes = np.tan(np.arange(-MAX_TILT, MAX_TILT + 1e-9, math.radians(2.0)))
    best, best_plane = (0.0, 0.0), -1.0
    for first in slopes:
        for second in slopes:
            heights = search[:, axis] + first * search[:, others[0]] + \
                second * search[:, others[1]]
            plane = max(_end_masses(heights)[:2])
            if plane > best_plane:
                best, best_plane = (first, second), plane
    heights = xyz[:, axis] + best[0] * xyz[:, others[0]] + best[1] * xyz[:, others[1]]
    return heights, _end_masses(heights)


def _is_camera_frustum(xyz: np.ndarray) -> bool:
    """Whether the points fill a depth camera's view frustum in its own frame (x right, y
    down, z forward, as PCL and Kinect frames are): all in front (z > 0) and within
    ``CAMERA_HALF_FOV`` of the optical axis. No room scanned from inside looks like that: its
    floor reaches the camera's feet."""
    depth = xyz[:, 2]
    if len(xyz) < 100 or np.percentile(depth, 0.5) <= 0.1:
        return False
    spread = np.abs(xyz[:, :2]) / depth[:, None]
    return bool((np.percentile(spread, 99.5, axis=0) < math.tan(CAMERA_HALF_FOV)).all())


def _floor_end(xyz: np.ndarray, heights: np.ndarray, axis: int,
               masses: tuple[float, ...]) -> bool:
    """Whether the floor is at the low end of ``heights``: furniture stands on floors, so the
    inside of the room (plan cells 0.5 m or more from its rim) holds more points in the 0.1-1.2 m
    band above the floor than below the ceiling. When both hold about as many (an empty
    room), the end with more points on its plane and band (:func:`_end_masses`)."""
    others = [a for a in range(3) if a != axis]
    # 0.25 m cells over the bulk of the points (far strays clipped onto the rim): at most
    # 1000 x 1000 cells whatever the coordinates' range
    low_corner, high_corner = np.percentile(xyz[:, others], [0.5, 99.5], axis=0)
    cell = max(0.25, float((high_corner - low_corner).max()) / 1000)
    plan = np.floor((np.clip(xyz[:, others], low_corner, high_corner) - low_corner) /
                    cell).astype(np.int64)
    shape = plan.max(axis=0) + 1
    occupied = np.zeros(shape, dtype=bool)
    occupied[plan[:, 0], plan[:, 1]] = True
    padded = np.pad(occupied, 2)
    inner = np.ones(shape, dtype=bool)  # occupied with all cells within 2 occupied too
    for dx in range(5):
        for dy in range(5):
            inner &= padded[dx:dx + shape[0], dy:dy + shape[1]]
    inside = inner[plan[:, 0], plan[:, 1]]
    low, high = np.percentile(heights, [0.5, 99.5])
    near_low = np.count_nonzero(inside & (heights > low + 0.1) & (heights < low + 1.2))
    near_high = np.count_nonzero(inside & (heights > high - 1.2) & (heights < high - 0.1))
    if max(near_low, near_high) >= 100 and \
            max(near_low, near_high) >= FURNITURE_MARGIN * min(near_low, near_high):
        return near_low > near_high
    low_plane, high_plane, low_band, high_band = masses
    return low_plane + low_band >= high_plane + high_band


def detect_up_axis(xyz: np.ndarray, origin: np.ndarray | None = None) -> str:
    """The scan's up direction (``'+z'``, ``'+y'``, ``'-x'``...).

    A depth camera's frame (points filling a view frustum along +z) has y pointing down:
    ``'-y'``. Otherwise the floor is the largest plane of a room or hall (larger than any one
    wall when the room is wider than tall), so the up axis is the one with the most points on
    a plane at one end of its range, each axis allowed a tilt of up to ``MAX_TILT``; z is kept
    unless another axis beats it by ``UP_AXIS_MARGIN`` and z is not the shortest extent (a
    reconstructed mesh's floor can hold fewer points than one wall). On a turned axis the
    floor is the end with the furniture (:func:`_floor_end`). A z-up scan is never turned
    upside down. ``origin`` is the local origin the points were shifted by (the frustum test
    needs the file's own coordinates, where the camera is at 0).
    """
    xyz = np.asarray(xyz, dtype=np.float64)[::max(1, len(xyz) // FIT_POINTS)]
    in_file_frame = xyz if origin is None else xyz + np.asarray(origin, dtype=np.float64)
    if _is_camera_frustum(in_file_frame):
        return '-y'
    levelled = [_levelled_end_masses(xyz, axis) for axis in range(3)]
    plane = [max(masses[:2]) for _, masses in levelled]
    axis = int(np.argmax(plane))
    if axis == 2 or plane[axis] < UP_AXIS_MARGIN * plane[2]:
        return '+z'
    extent = np.percentile(xyz, 99.5, axis=0) - np.percentile(xyz, 0.5, axis=0)
    if extent[2] <= extent.min():  # rooms are wider than tall: a sparse floor, a big wall
        return '+z'
    heights, masses = levelled[axis]
    return ('+' if _floor_end(xyz, heights, axis, masses) else '-') + AXIS_NAMES[axis]


def _levelled(xyz: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, float, str]:
    """Level the floor of z-up points: the tilt whose height histogram is sharpest, then a
    plane fit to the floor points. Returns the rotation (applied after ``rotation``), the
    floor height in the levelled frame and the report line."""
    search = xyz[::max(1, len(xyz) // TILT_POINTS)]
    best = np.zeros(2)
    for step, span in ((math.radians(1.0), MAX_TILT), (math.radians(0.1), math.radians(1.0))):
        offsets = np.arange(-span, span + step / 2, step)
        candidates = [best + (a, b) for a in offsets for b in offsets]
        scores = [
            projection_sharpness(search @ _tilted_up(c), None, LEVEL_CELL) for c in candidates
        ]
        best = candidates[int(np.argmax(scores))]
    up = _tilted_up(best)
    for _ in range(2):  # total least squares on the floor slab
        heights = xyz @ up
        floor = _floor_level(heights)
        slab = xyz[np.abs(heights - floor) < 0.03]
        if len(slab) < 100:
            return rotation, float(np.percentile(xyz[:, 2], 1.0)), \
                'levelling: no floor plane found; left as read'
        centre = slab.mean(axis=0)
        _, vectors = np.linalg.eigh(np.cov((slab - centre).T))
        up = vectors[:, 0] * np.sign(vectors[2, 0])
    level = rotation_between(up, [0.0, 0.0, 1.0])
    floor = float(np.median(slab @ up))
    tilt = math.degrees(math.acos(min(1.0, float(up[2]))))
    return level @ rotation, floor, (f'levelling: floor tilted {tilt:.2f} deg, levelled; '
                                     f'{len(slab):,} floor points, floor at z = 0')


def _tilted_up(angles: np.ndarray) -> np.ndarray:
    up = np.array([math.tan(angles[0]), math.tan(angles[1]), 1.0])
    return up / np.linalg.norm(up)


def _floor_level(heights: np.ndarray) -> float:
    """The lowest strong peak of the height histogram (a quarter of the lower half's peak)."""
    low, high = np.percentile(heights, [0.5, 99.5])
    edges = np.arange(low - 0.1, high + 0.1 + LEVEL_CELL, LEVEL_CELL)
    hist = np.convolve(np.histogram(heights, edges)[0], [1, 2, 1], mode='same')
    centres = (edges[:-1] + edges[1:]) / 2
    lower = centres < (low + high) / 2
    strong = np.flatnonzero(lower & (hist >= 0.25 * hist[lower].max()) & (hist >= np.roll(hist, 1))
                            & (hist >= np.roll(hist, -1)))
    peak = centres[strong[0]] if len(strong) else low
    near = heights[np.abs(heights - peak) < 2 * LEVEL_CELL]
    return float(np.median(near)) if len(near) else float(peak)


# --------------------------------------------------------------------------- density


def floor_density(xyz: np.ndarray, cell: float = FOOTPRINT_CELL) -> float:
    """Points per m^2 of the floor footprint: the occupied ``cell`` squares seen from above."""
    if len(xyz) == 0:
        return 0.0
    packed, fits = _packed_cells(np.column_stack([xyz[:, :2], np.zeros(len(xyz))]), cell)
    area = len(np.unique(packed[fits])) * cell * cell
    return len(xyz) / max(area, cell * cell)


def _resampled(points: np.ndarray, density: float, target: float | None,
               seed: int) -> tuple[np.ndarray, str]:
    if target is None:
        return points, f'density: {density:,.0f} points per m^2 of floor; no target, kept'
    line = f'density: {density:,.0f} points per m^2 of floor, the model was trained on ' \
        f'{target:,.0f}'
    if density > target:
        count = int(round(len(points) * target / density))
        chosen = np.sort(np.random.default_rng(seed).choice(len(points), count, replace=False))
        points = points[chosen]
        line += f'; resampled to {count:,} points'
    if density < target / FAR_DENSITY:
        line = f'warning: {line}; the scan is {target / density:.1f}x sparser than training, ' \
            f'expect weaker detections'
    elif density > target * FAR_DENSITY:
        line = f'warning: {line} ({density / target:.1f}x denser than training)'
    return points, line
