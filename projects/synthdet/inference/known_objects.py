"""Objects of an earlier, corrected scan of the same room, found again in a new scan.

A hall is scanned again and again; once one scan's detections are corrected (a FreeCAD
document turned into labels by ``python -m configurator labels``), a later scan of the same
room starts from them. Both scans are prepared (z up, floor at z = 0, walls along the axes), so
they differ by a quarter turn about z and a shift: each quarter turn is tried, the shift taken
where the two floor plans' occupancy grids overlap most (one FFT correlation), refined by
point-to-plane ICP (Open3D), and the turn under which the two scans overlap most kept (the
smaller of the shares of each scan's points above the floor within 5 cm of the other's).

A corrected box is *found again* when most of the earlier scan's occupied cells inside it are
occupied in the new scan too (``support``): an object moved away leaves its cells empty. A
detection of the model is dropped when it overlaps a box found again (the corrected box stands
for it) or when it lies in a part of the room that the earlier scan already held and the user
labelled nothing there (a detection the correction removed). What remains of the model's
detections is what changed: moved or new objects.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Sequence

import numpy as np
import open3d as o3d
from scipy.signal import fftconvolve
from scipy.spatial import cKDTree

from projects.synthdet.core.rotated_iou import box_tensor, rotated_iou_3d
from synthdet.contracts import labels_path, read_labels
from synthdet.outputs import readable
from synthdet.prepare import PreparedScan, prepare_scan
from synthdet.scan_io import load_scan

CELL = 0.05  # m: occupancy cells of the floor plans and of the support
ICP_VOXEL = 0.03  # m: the points ICP fits, one per voxel
ICP_REACH = (0.1, 0.05)  # m: ICP's correspondence distance, coarse then fine
MAX_PLAN_CELLS = 4096  # cells per side of the floor-plan grid; larger plans get larger cells
FLOOR_SLAB = 0.1  # m: the floor's points fit anywhere on a floor; the fit counts those above
# the overlap two scans need: on the development scans two scans of one room share 0.40-0.76,
# two rooms at most 0.09
MIN_OVERLAP = 0.2
MIN_SUPPORT = 0.5  # share of a box's occupied cells found again
MIN_BOX_CELLS = 8  # a box with fewer occupied cells in the earlier scan is not carried over
OVERLAP_IOU = 0.1  # a detection overlapping a box found again at this 3D IoU is dropped


class KnownScanError(ValueError):
    """A known scan that cannot be used (unreadable, no labels, not the same room); the message
    names the files."""


class RegistrationError(KnownScanError):
    """Two scans that do not register: not the same room, or too little of it in common."""


@dataclass(frozen=True)
class Registration:
    """The earlier scan's prepared frame -> the new scan's, and how much the two overlap."""

    transform: np.ndarray  # (4, 4)
    overlap: float


def _cloud(xyz: np.ndarray) -> o3d.geometry.PointCloud:
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, np.float64)))


def _plan(xyz: np.ndarray, low: np.ndarray, shape: tuple[int, int], cell: float) -> np.ndarray:
    """Occupancy (0/1) of the floor plan cells."""
    ij = np.floor((xyz[:, :2] - low) / cell).astype(np.int64)
    grid = np.zeros(shape, dtype=np.float32)
    grid[ij[:, 0], ij[:, 1]] = 1.0
    return grid


def quarter_turn(turns: int) -> np.ndarray:
    """(3, 3) rotation by ``turns`` quarter turns counter-clockwise about z."""
    cos, sin = np.cos(turns * np.pi / 2), np.sin(turns * np.pi / 2)
    return np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])


def plan_shift(earlier: np.ndarray, later: np.ndarray, cell: float = CELL) -> np.ndarray:
    """The xy shift that lays ``earlier``'s floor plan best on ``later``'s (FFT correlation of
    their occupancy grids)."""
    low = np.minimum(earlier.min(0), later.min(0))[:2] - 1.0
    high = np.maximum(earlier.max(0), later.max(0))[:2] + 1.0
    cell = max(cell, float((high - low).max()) / MAX_PLAN_CELLS)
    shape = tuple(int(n) for n in np.ceil((high - low) / cell).astype(np.int64) + 1)
    correlation = fftconvolve(_plan(later, low, shape, cell),
                              _plan(earlier, low, shape, cell)[::-1, ::-1], mode='same')
    peak = np.unravel_index(int(np.argmax(correlation)), correlation.shape)
    # mode='same' puts zero shift at index (n - 1) // 2 of the flipped kernel
    return (np.array(peak) - (np.array(shape) - 1) // 2) * cell


def _near_share(points: np.ndarray, other: np.ndarray) -> float:
    """The share of ``points`` above the floor with a point of ``other`` within the fine ICP
    reach."""
    points = points[points[:, 2] > FLOOR_SLAB]
    if not len(points) or not len(other):
        return 0.0
    distances, _ = cKDTree(other).query(points, distance_upper_bound=ICP_REACH[-1])
    return float(np.isfinite(distances).mean())


def overlap(earlier: np.ndarray, later: np.ndarray, transform: np.ndarray) -> float:
    """How much two scans of one room share under ``transform`` (earlier -> later): the smaller
    of the two shares of each scan's points above the floor that lie within 5 cm of the other
    scan's. The smaller one, so that a small room laid inside a large one does not count."""
    moved = earlier @ transform[:3, :3].T + transform[:3, 3]
    return min(_near_share(moved, later), _near_share(later, moved))


def register(earlier: np.ndarray, later: np.ndarray) -> Registration:
    """Register two prepared scans' points ``(N, 3)``, ``(M, 3)`` of one room (module doc).
    Raises ``RegistrationError`` when no quarter turn reaches an :func:`overlap` of
    ``MIN_OVERLAP``."""
    source = _cloud(earlier).voxel_down_sample(ICP_VOXEL)
    target = _cloud(later).voxel_down_sample(ICP_VOXEL)
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * ICP_VOXEL, max_nn=30))
    plane = o3d.pipelines.registration.TransformationEstimationPointToPlane()
    source_points, target_points = np.asarray(source.points), np.asarray(target.points)
    best = Registration(np.eye(4), -1.0)
    for turns in range(4):
        start = np.eye(4)
        start[:3, :3] = quarter_turn(turns)
        start[:2, 3] = plan_shift(source_points @ start[:3, :3].T, target_points)
        transform = start
        for reach in ICP_REACH:
            fit = o3d.pipelines.registration.registration_icp(source, target, reach, transform,
                                                              plane)
            transform = np.asarray(fit.transformation)
        shared = overlap(source_points, target_points, transform)
        if shared > best.overlap:
            best = Registration(transform, shared)
    if best.overlap < MIN_OVERLAP:
        raise RegistrationError(
            f'the scans overlap by {best.overlap:.0%} at the best fit (at least '
            f'{MIN_OVERLAP:.0%} needed): not two scans of the same room')
    return best


def move_boxes(boxes: Sequence[dict], transform: np.ndarray) -> list[dict]:
    """Contract boxes (``center``, ``size``, ``yaw``) moved by a rigid ``transform`` (4, 4)
    whose rotation turns about z; other keys kept."""
    turn = float(np.arctan2(transform[1, 0], transform[0, 0]))
    moved = []
    for box in boxes:
        center = transform[:3, :3] @ np.asarray(box['center'], np.float64) + transform[:3, 3]
        moved.append({**box, 'center': center.tolist(), 'yaw': float(box.get('yaw', 0.0)) + turn})
    return moved


def in_box(xyz: np.ndarray, box: dict) -> np.ndarray:
    """Which points ``(N, 3)`` lie inside the turned box."""
    offset = xyz - np.asarray(box['center'], np.float64)
    yaw = float(box.get('yaw', 0.0))
    along = offset[:, 0] * np.cos(yaw) + offset[:, 1] * np.sin(yaw)
    across = -offset[:, 0] * np.sin(yaw) + offset[:, 1] * np.cos(yaw)
    half = np.asarray(box['size'], np.float64) / 2
    return (np.abs(along) <= half[0]) & (np.abs(across) <= half[1]) & (np.abs(offset[:, 2])
                                                                          <= half[2])


def _cell_keys(xyz: np.ndarray, cell: float) -> np.ndarray:
    """One int64 key per occupied cell (21 bits per axis, offset so negatives pack)."""
    ijk = np.floor(xyz / cell).astype(np.int64) + (1 << 20)
    return np.unique((ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2])


def occupied_cells(xyz: np.ndarray, cell: float = CELL) -> np.ndarray:
    """The keys of every cell within one cell of a point (sorted): what counts as occupied when
    another scan's cells are looked up, so that a 1-cell registration error does not count."""
    offsets = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)])
    return np.unique(np.concatenate([_cell_keys(xyz + offset * cell, cell)
                                     for offset in offsets]))


def support(box: dict, source: np.ndarray, target_cells: np.ndarray,
            cell: float = CELL) -> float:
    """The share of ``source``'s occupied cells inside ``box`` that ``target_cells``
    (:func:`occupied_cells` of the other scan) holds; 0 with fewer than ``MIN_BOX_CELLS``."""
    keys = _cell_keys(source[in_box(source, box)], cell)
    if len(keys) < MIN_BOX_CELLS:
        return 0.0
    return float(np.isin(keys, target_cells, assume_unique=True).mean())


def _overlaps(boxes: Sequence[dict], others: Sequence[dict]) -> np.ndarray:
    """For each of ``boxes``, whether it overlaps any of ``others`` at ``OVERLAP_IOU``."""
    if not boxes or not others:
        return np.zeros(len(boxes), dtype=bool)
    ious = rotated_iou_3d(box_tensor(boxes), box_tensor(others))
    return (ious >= OVERLAP_IOU).any(dim=1).numpy()


def scan_to_scan(earlier: PreparedScan, later: PreparedScan) -> tuple[np.ndarray, float]:
    """Register two prepared scans of one room (:func:`register`); returns the (4, 4) matrix
    from the earlier scan's output coordinates (those of its labels) to the later's, and their
    overlap."""
    registration = register(earlier.points[:, :3], later.points[:, :3])
    matrix = later.output_matrix() @ registration.transform @ np.linalg.inv(
        earlier.output_matrix())
    return matrix, registration.overlap


def with_known_objects(detections: Sequence[dict], known: Sequence[dict], later: np.ndarray,
                       earlier: np.ndarray, to_later: np.ndarray) -> tuple[list[dict], dict]:
    """The later scan's boxes from its ``detections`` and the corrected boxes ``known`` of an
    earlier scan of the room (module doc). ``later`` and ``earlier`` are the scans' points
    ``(N, 3)``, each in the coordinates of its boxes; ``to_later`` (4, 4) takes the earlier
    coordinates to the later ones (:func:`scan_to_scan`).

    Returns the boxes (those found again first, scored by their support, then the model's
    detections that remain) and the counts."""
    moved_earlier = earlier @ to_later[:3, :3].T + to_later[:3, 3]
    later_cells, earlier_cells = occupied_cells(later), occupied_cells(moved_earlier)
    found_again = []
    for box in move_boxes(known, to_later):
        share = support(box, moved_earlier, later_cells)
        if share >= MIN_SUPPORT:
            found_again.append({'class': box['class'], 'score': round(share, 6),
                                'center': box['center'], 'size': list(box['size']),
                                'yaw': box['yaw']})
    overlapping = _overlaps(detections, found_again)
    kept = [det for det, overlap in zip(detections, overlapping)
            if not overlap and support(det, later, earlier_cells) < MIN_SUPPORT]
    counts = {'known': len(known), 'found_again': len(found_again),
              'detections': len(detections), 'detections_kept': len(kept)}
    return found_again + kept, counts


@dataclass
class KnownScan:
    """An earlier scan of a room, prepared, and its corrected boxes."""

    path: Path
    prepared: PreparedScan
    boxes: list[dict]

    @cached_property
    def points(self) -> np.ndarray:
        """``(N, 3)`` its points in its output coordinates (those of its labels), computed once
        for all the later scans."""
        return self.prepared.points_to_scan(self.prepared.points[:, :3])


def read_known_scan(path: str | os.PathLike, *, voxel: float | None, columns: str | None,
                    density: float | None, seed: int) -> KnownScan:
    """Read an earlier scan (as the later ones are read and prepared) and the labels beside it
    (``<stem>.labels.json``); ``KnownScanError`` names the file that cannot be used."""
    path = Path(path)
    try:
        labels = read_labels(labels_path(path))
        loaded = load_scan(path, voxel=voxel, columns=columns)
    except (ValueError, OSError) as error:  # a missing file, SchemaError, ScanFormatError
        raise KnownScanError(readable(f'--known: {error}')) from None
    return KnownScan(path, prepare_scan(loaded, target_density=density, seed=seed),
                     list(labels['boxes']))


def apply_known_scan(known: KnownScan, scan: Path, prepared: PreparedScan,
                     predictions: dict) -> str:
    """Replace ``predictions``' detections (a ``synthdet.predictions/1`` document of the later
    scan ``scan``) by the known objects found again and the detections of what changed;
    returns the line saying so. ``RegistrationError`` names both scans."""
    try:
        to_later, shared = scan_to_scan(known.prepared, prepared)
    except RegistrationError as error:
        raise RegistrationError(readable(f'{scan} and --known {known.path}: {error}')) from None
    boxes = [box for box in known.boxes if box['class'] in predictions['classes']]
    predictions['detections'], counts = with_known_objects(
        predictions['detections'], boxes, prepared.points_to_scan(prepared.points[:, :3]),
        known.points, to_later)
    return (f'{scan.name}: registered on {known.path.name} (overlap {shared:.0%}); '
            f'{counts["found_again"]} of its {counts["known"]} objects found again, '
            f'{counts["detections_kept"]} of {counts["detections"]} detections where the room '
            'changed')
