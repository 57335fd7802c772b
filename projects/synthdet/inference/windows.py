"""Whole-hall detection: overlapping windows the size of a training room, merged with 3D NMS.

A model trained on rooms samples a fixed number of points per scene (the test pipeline's
``PointSample``). A hall passed whole would get that number for its entire floor, far fewer points
per object than in training. So a scan larger than a window is cut into overlapping square
windows (all heights kept), each window is detected on its own, exactly as a training room is
sampled, and the detections are merged:

- the window side is the side of a square with the median floor area of the training rooms
  (their bounding boxes), rounded up to 0.5 m: a window then holds about as much floor as a
  training room, so the sampled points per square metre match training;
- the overlap is at least the largest training object's footprint diagonal (rounded up to 0.1 m),
  so every object lies whole inside some window;
- each window keeps only the boxes whose centre lies in its *core*, the part of the window nearer
  to it than to its neighbours (the overlaps are split at their middle): a complete object is then
  kept from the window where it is most central, at least half the overlap from its edges, hence
  whole; cut-off parts seen by a neighbour are dropped there;
- the kept boxes of all windows go through the project's class-wise axis-aligned 3D NMS
  (:mod:`projects.synthdet.core.nms`), which removes what is left of duplicates at the seams.

A scan whose x and y extents both fit in one window is one window, detected as a whole without
filtering or NMS (the model's own output, unchanged).

``configs/tr3d/_base_/s3dis-synthdet.py`` holds ``inference_window = dict(size=8.0,
overlap=2.6)``: :func:`window_spec_from_training` applied to the generator's default rooms (6-11 m
by 5-9 m) and to the largest object of its procedural library (a sofa, 2.54 m diagonal). Its
``inference_density = dict(floor_area=59.0)`` is that median floor area: the training density is
the test pipeline's ``PointSample`` ``num_points`` over it (:func:`density_from_config`), the
points per m^2 of floor a median training room was sampled to.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np
import torch
from tqdm import tqdm

from projects.synthdet.core.nms import axis_aligned_nms3d
from projects.synthdet.datasets.transforms import ThinRoomStructure


@dataclass(frozen=True)
class WindowSpec:
    """Square windows of side ``size`` metres that overlap by at least ``overlap`` metres."""

    size: float
    overlap: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.overlap < self.size:
            raise ValueError(f'window overlap {self.overlap} m must be in [0, size '
                             f'{self.size} m)')


@dataclass(frozen=True)
class Window:
    """One window: its xy bounds and its core (boxes centred there are kept from it)."""

    low: np.ndarray  # (2,) metres
    high: np.ndarray  # (2,)
    core_low: np.ndarray  # (2,) -inf on the scan's low sides
    core_high: np.ndarray  # (2,) +inf on the scan's high sides


@dataclass
class Detections:
    """Boxes ``(x, y, z, dx, dy, dz, yaw)`` (gravity centres, metres), scores and labels."""

    boxes: np.ndarray  # (K, 7) float64
    scores: np.ndarray  # (K,) float64
    labels: np.ndarray  # (K,) int64

    @classmethod
    def empty(cls) -> 'Detections':
        return cls(np.zeros((0, 7)), np.zeros(0), np.zeros(0, dtype=np.int64))

    def select(self, keep: np.ndarray) -> 'Detections':
        return Detections(self.boxes[keep], self.scores[keep], self.labels[keep])

    @classmethod
    def concatenate(cls, parts: list['Detections']) -> 'Detections':
        if not parts:
            return cls.empty()
        return cls(
            np.concatenate([p.boxes for p in parts]), np.concatenate([p.scores for p in parts]),
            np.concatenate([p.labels for p in parts]))


Detector = Callable[[np.ndarray], Detections]


def window_spec_from_training(room_extents: np.ndarray, object_sizes: np.ndarray) -> WindowSpec:
    """The window rule (module docstring) from the training rooms' xy extents ``(R, 2)`` and the
    training objects' box sizes ``(M, >=2)``."""
    room_extents = np.asarray(room_extents, dtype=np.float64)
    object_sizes = np.asarray(object_sizes, dtype=np.float64)
    side = math.sqrt(float(np.median(room_extents[:, 0] * room_extents[:, 1])))
    diagonal = float(np.hypot(object_sizes[:, 0], object_sizes[:, 1]).max())
    return WindowSpec(size=math.ceil(side * 2) / 2, overlap=math.ceil(diagonal * 10 - 1e-9) / 10)


def window_spec_from_config(cfg: Mapping) -> WindowSpec:
    """The ``inference_window = dict(size=..., overlap=...)`` of a model config."""
    window = cfg.get('inference_window')
    if window is None:
        raise ValueError('the config has no inference_window = dict(size=..., overlap=...): '
                         'see projects/synthdet/inference/windows.py for the rule')
    return WindowSpec(float(window['size']), float(window['overlap']))


def density_from_config(cfg: Mapping) -> float:
    """The points per m^2 of floor the model was trained on: the ``num_points`` of the test
    pipeline's ``PointSample`` over the ``inference_density = dict(floor_area=...)`` of a model
    config (the median training floor area, as for the window size).

    A test pipeline that thins the room structure first (``ThinRoomStructure`` with ``keep``)
    needs ``1 / keep`` times as many: after thinning, even a window of structure alone still
    holds ``num_points`` points, so ``PointSample`` draws from the same mix of objects and
    structure as in training, where every room had more points than that.
    """
    density = cfg.get('inference_density')
    if density is None:
        raise ValueError('the config has no inference_density = dict(floor_area=...): see '
                         'configs/tr3d/_base_/s3dis-synthdet.py for the rule')
    pipeline = cfg['test_dataloader']['dataset']['pipeline']
    counts = [step['num_points'] for step in pipeline if step['type'] == 'PointSample']
    if not counts:
        raise ValueError('the test pipeline has no PointSample step, so no training density')
    default_keep = inspect.signature(ThinRoomStructure).parameters['keep'].default
    kept = math.prod(
        float(step.get('keep', default_keep)) for step in pipeline
        if step['type'] == 'ThinRoomStructure')
    return float(counts[0]) / float(density['floor_area']) / kept


def inference_settings(cfg: Mapping, config: str) -> tuple[WindowSpec, float]:
    """The window spec and the training density of a model config; a ``ValueError`` naming
    ``config`` (its path) when either is missing."""
    try:
        return window_spec_from_config(cfg), density_from_config(cfg)
    except ValueError as error:
        raise ValueError(f'{config}: {error}') from None


def _axis_windows(low: float, high: float,
                  spec: WindowSpec) -> list[tuple[float, float, float, float]]:
    """Windows along one axis as ``(start, end, core_start, core_end)``."""
    length = high - low
    if length <= spec.size:
        return [(low, high, -math.inf, math.inf)]
    count = math.ceil((length - spec.overlap) / (spec.size - spec.overlap) - 1e-9)
    stride = (length - spec.size) / (count - 1)
    starts = [low + i * stride for i in range(count)]
    windows = []
    for i, start in enumerate(starts):
        core_start = -math.inf if i == 0 else (start + starts[i - 1] + spec.size) / 2
        core_end = math.inf if i == count - 1 else (starts[i + 1] + start + spec.size) / 2
        windows.append((start, start + spec.size, core_start, core_end))
    return windows


def plan_windows(xy_low: np.ndarray, xy_high: np.ndarray, spec: WindowSpec) -> list[Window]:
    """Overlapping windows covering the xy bounds ``[xy_low, xy_high]``, row by row.

    Along an axis longer than ``spec.size`` the fewest windows whose overlaps are at least
    ``spec.overlap`` are spread evenly from end to end; a shorter axis gets one window.
    """
    along_x = _axis_windows(float(xy_low[0]), float(xy_high[0]), spec)
    along_y = _axis_windows(float(xy_low[1]), float(xy_high[1]), spec)
    return [
        Window(np.array([x0, y0]), np.array([x1, y1]), np.array([cx0, cy0]), np.array([cx1, cy1]))
        for y0, y1, cy0, cy1 in along_y for x0, x1, cx0, cx1 in along_x
    ]


def merge_window_detections(per_window: list[Detections], windows: list[Window],
                            iou_thr: float) -> Detections:
    """Keep each window's boxes centred in its core, then class-wise axis-aligned 3D NMS."""
    kept = []
    for found, window in zip(per_window, windows):
        centre = found.boxes[:, :2]
        inside = np.all((centre >= window.core_low) & (centre < window.core_high), axis=1)
        kept.append(found.select(inside))
    merged = Detections.concatenate(kept)
    survivors = []
    for label in np.unique(merged.labels):
        rows = np.flatnonzero(merged.labels == label)
        keep = axis_aligned_nms3d(
            torch.from_numpy(merged.boxes[rows]), torch.from_numpy(merged.scores[rows]), iou_thr)
        survivors.append(rows[keep.numpy()])
    rows = np.concatenate(survivors) if survivors else np.zeros(0, dtype=np.int64)
    return merged.select(rows[np.argsort(-merged.scores[rows], kind='stable')])


def detect_in_windows(points: np.ndarray,
                      detector: Detector,
                      spec: WindowSpec,
                      iou_thr: float,
                      progress: bool = True) -> tuple[Detections, list[Window]]:
    """Detect objects in an ``(N, 6)`` scan window by window; boxes in the scan's frame.

    ``detector`` maps the points of one window (in the scan's frame) to its detections in that
    frame. Windows without points are skipped. Returns the merged detections (descending score)
    and the windows.
    """
    xyz = points[:, :3]
    windows = plan_windows(xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0), spec)
    if len(windows) == 1:
        return detector(points), windows
    per_window = []
    for window in tqdm(windows, desc='windows', unit='window', disable=not progress):
        inside = np.all((xyz[:, :2] >= window.low) & (xyz[:, :2] <= window.high), axis=1)
        per_window.append(detector(points[inside]) if inside.any() else Detections.empty())
    return merge_window_detections(per_window, windows, iou_thr), windows
