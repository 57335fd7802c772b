"""Self-training on unlabelled scans (``tools/adapt.py``): pseudo-labels a slowly moving teacher
agrees on, written as S3DIS rooms, and the training runs between two refreshes of them.

- The teacher detects each prepared scan with test-time augmentation (the config's
  ``tta_model`` and ``tta_pipeline``: flips and point samples fused, a box found by few passes
  scoring low) once per seed of ``seeds``. A pseudo-label is a box of the first run scoring at
  least ``score_thr`` that every other run also finds: a box of the same class scoring at
  least ``score_thr`` with axis-aligned 3D IoU of at least ``agree_iou``
  (:func:`agreeing_detections`).
- Each scan becomes an S3DIS room of the prepared frame (floor at z = 0, walls along the axes)
  by the rules of ``python -m configurator labels`` (``configurator.labels``): a point belongs
  to the smallest pseudo-box it lies in, else to the nearest within 5 mm; ``floor_1`` are the
  other points within 5 cm of the floor, the rest ``clutter_1``. A pseudo-box without a point
  is dropped.
- What the teacher is unsure of is ignored, not trained as background: every box that some run
  found scoring at least ``unsure_thr`` and that is no pseudo-label (too low a score, or the
  runs disagree), grown by ``UNSURE_MARGIN``, becomes an ignored region of the room's info
  (``ignored_regions``, read by
  :class:`~projects.synthdet.datasets.synthdet_s3dis.SynthdetS3DISDataset`): the
  detector's class loss leaves the locations inside it out. The points stay, so the scan keeps
  its shape. An object the teacher half-sees is then neither a label nor background: as
  background, the model would learn to stop finding it.
- A training run continues from the previous one's checkpoint: the student from its own
  weights, the teacher (``MeanTeacherEMAHook``, an exponential moving average of the
  student's weights) from its average. The pseudo-labelled area is mixed with the config's
  generated training areas, repeated to make ``adapt_share`` of the samples.
"""
from __future__ import annotations

import copy
import math
import pickle
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from mmengine.config import Config

from configurator.labels import (SURFACE_BAND, holds_points, instance_names, point_owners,
                                 shadowed_boxes, write_s3dis_room)
from projects.synthdet.config_helpers import area_info_file
from projects.synthdet.core.box_ops import pairwise_iou_3d
from projects.synthdet.inference.detector import ModelDetector
from projects.synthdet.inference.windows import Detections, WindowSpec
from synthdet.info_files import RAW_DIR, load_info_pickle
from synthdet.outputs import replaced_paths

UNSURE_MARGIN = 0.05  # metres an unsure box grows on every side to an ignored region
UNSURE_THR = 0.3  # the default lowest score of an unsure box (docs/teach.md: measured 0.1, 0.3)
PSEUDO_LABEL_THR = 0.4  # the default lowest score of a pseudo-label (docs/teach.md: 0.4, 0.5)


@dataclass(frozen=True)
class PseudoLabelRule:
    """What makes a teacher's box a pseudo-label: its score, and agreement between runs."""

    score_thr: float
    agree_iou: float
    seeds: tuple[int, ...]
    unsure_thr: float


def agreeing_detections(runs: list[Detections], score_thr: float, agree_iou: float) -> Detections:
    """The boxes of ``runs[0]`` scoring at least ``score_thr`` that every other run finds too:
    a box of the same class scoring at least ``score_thr`` whose axis-aligned 3D IoU with it is
    at least ``agree_iou``."""
    first = runs[0].select(runs[0].scores >= score_thr)
    keep = np.ones(len(first.scores), dtype=bool)
    for other in runs[1:]:
        other = other.select(other.scores >= score_thr)
        if not len(other.scores) or not len(first.scores):
            keep[:] = False
            continue
        overlaps = pairwise_iou_3d(torch.from_numpy(first.boxes), torch.from_numpy(other.boxes))
        same_class = first.labels[:, None] == other.labels[None, :]
        keep &= ((overlaps.numpy() >= agree_iou) & same_class).any(axis=1)
    return first.select(keep)


def teacher_pseudo_labels(model: torch.nn.Module, points: np.ndarray, spec: WindowSpec,
                          rule: PseudoLabelRule) -> tuple[Detections, Detections]:
    """The pseudo-labels of one prepared scan and the boxes the teacher is unsure of: the
    teacher ``model`` (with test-time augmentation) runs once per seed of ``rule``; the labels
    are its boxes that pass :func:`agreeing_detections`, the unsure boxes every box of any run
    scoring at least ``rule.unsure_thr`` (the labels among them)."""
    floor = min(rule.unsure_thr, rule.score_thr)
    runs = [
        ModelDetector(model, floor, seed).detect(points, spec, progress=False)
        for seed in rule.seeds
    ]
    unsure = Detections.concatenate([run.select(run.scores >= rule.unsure_thr) for run in runs])
    return agreeing_detections(runs, rule.score_thr, rule.agree_iou), unsure


def pseudo_boxes(detections: Detections, classes: list[str]) -> list[dict]:
    """The detections as labelled boxes (``class``, ``label``, ``center``, ``size``, ``yaw``,
    ``score``), numbered per class."""
    counts: dict[str, int] = {}
    boxes = []
    for box, label, score in zip(detections.boxes, detections.labels, detections.scores):
        name = classes[int(label)]
        counts[name] = counts.get(name, 0) + 1
        boxes.append({
            'class': name,
            'label': f'{name} {counts[name]}',
            'center': [float(v) for v in box[:3]],
            'size': [float(v) for v in box[3:6]],
            'yaw': float(box[6]),
            'score': float(score)
        })
    return boxes


def write_pseudo_room(room_dir: Path, points: np.ndarray, boxes: list[dict]) -> list[dict]:
    """Write the prepared scan ``points`` as an S3DIS room labelled by ``boxes`` (the rules of
    ``configurator.labels``; floor at z = 0). Returns the boxes that hold points (the others
    are dropped)."""
    xyz = points[:, :3]
    held = [box for box in boxes if holds_points(xyz, box)]
    source = f'pseudo-labels of {room_dir.name}'
    names = instance_names(held, source)
    owners = point_owners(xyz, held, source)  # -1: in reach of no labelled box
    repeated, _ = shadowed_boxes(xyz, held, owners, source)
    elements = np.full(len(points), 'clutter_1', dtype=object)
    elements[np.abs(xyz[:, 2]) <= SURFACE_BAND] = 'floor_1'
    for index, name in enumerate(names):
        elements[owners == index] = name
    write_s3dis_room(room_dir, points, elements,
                     {names[index]: chunk for index, chunk in repeated.items()})
    return held


def ignored_regions(unsure: Detections, labels: Detections, agree_iou: float) -> np.ndarray:
    """``(K, 6)`` axis-aligned regions ``x y z dx dy dz`` (gravity centres) of the ``unsure``
    boxes that are no pseudo-label (no box of ``labels`` overlaps them with 3D IoU of at least
    ``agree_iou``), each grown by ``UNSURE_MARGIN`` on every side."""
    keep = np.ones(len(unsure.scores), dtype=bool)
    if len(unsure.scores) and len(labels.scores):
        overlaps = pairwise_iou_3d(torch.from_numpy(unsure.boxes), torch.from_numpy(labels.boxes))
        keep = overlaps.numpy().max(axis=1) < agree_iou
    regions = unsure.boxes[keep, :6].astype(np.float64)
    regions[:, 3:6] += 2 * UNSURE_MARGIN
    return regions


def room_offset(points: np.ndarray) -> np.ndarray:
    """The xyz the converter subtracts from a room written from ``points``: their per-axis
    minimum at the millimetres the room's text files keep."""
    return np.round(points[:, :3].astype(np.float64), 3).min(axis=0)


def add_ignored_regions(info_file: Path, regions: dict[str, np.ndarray]) -> None:
    """Add to each room's info in ``info_file`` its ``ignored_regions``: ``regions`` maps the
    room's points file name (``Area_11_scan_1.bin``) to ``(K, 6)`` boxes in the converted
    room's frame. The file is replaced atomically."""
    document = load_info_pickle(info_file)
    for info in document['data_list']:
        boxes = regions.get(info['lidar_points']['lidar_path'], np.zeros((0, 6)))
        info['ignored_regions'] = [{'bbox_3d': [float(v) for v in box]} for box in boxes]
    with replaced_paths([info_file]) as (partial, ):
        partial.write_bytes(pickle.dumps(document, protocol=pickle.HIGHEST_PROTOCOL))


def raw_area_dir(root: Path, area: int) -> Path:
    """Where the S3DIS rooms of ``area`` go under a raw data ``root``."""
    return root / RAW_DIR / f'Area_{area}'


def generated_sets(cfg: Config) -> list[dict]:
    """The config's training datasets other than the pseudo-labelled area (``adapt_area``)."""
    adapt_file = area_info_file(cfg.adapt_area)
    return [
        entry for entry in cfg.train_dataloader.dataset.dataset.datasets
        if entry.ann_file != adapt_file
    ]


def generated_room_count(cfg: Config) -> int:
    """The number of rooms in the config's generated training areas (their info pickles under
    each dataset's ``data_root``); ``InfoFileError`` (a ``ValueError``) naming a missing or
    bad one."""
    return sum(
        len(load_info_pickle(Path(entry.data_root) / entry.ann_file)['data_list'])
        for entry in generated_sets(cfg))


def adapt_repeat(cfg: Config, scans: int) -> int:
    """How often the pseudo-labelled area is listed so that it makes ``adapt_share`` of the
    training samples (at least once)."""
    share = float(cfg.adapt_share)
    return max(1, round(share / (1.0 - share) * generated_room_count(cfg) / max(scans, 1)))


def round_config(cfg: Config, work_dir: Path, load_from: Path, data_root: Path, repeat: int,
                 iters: int, seed: int) -> Config:
    """The Runner config of one training run: ``iters`` iterations from ``load_from`` (one
    checkpoint at the end, no validation), the pseudo-labelled area read from ``data_root``
    and listed ``repeat`` times, seeded with ``seed``."""
    cfg = copy.deepcopy(cfg)
    cfg.work_dir, cfg.load_from, cfg.resume, cfg.launcher = str(work_dir), str(load_from), False, \
        'none'
    cfg.randomness = dict(seed=seed)
    # a name of its own: mmengine keeps one logger and visualizer per name in the process, and a
    # later run would write into an earlier run's log folder
    cfg.experiment_name = f'{work_dir.parent.name}_{time.strftime("%Y%m%d_%H%M%S")}'
    if cfg.get('visualizer'):
        cfg.visualizer.name = cfg.experiment_name
    cfg.train_cfg = dict(type='IterBasedTrainLoop', max_iters=iters)
    cfg.default_hooks.checkpoint.update(by_epoch=False, interval=iters)
    cfg.val_cfg = cfg.val_dataloader = cfg.val_evaluator = None
    datasets = cfg.train_dataloader.dataset.dataset.datasets
    adapt_file = area_info_file(cfg.adapt_area)
    for index, entry in enumerate(datasets):
        if entry.ann_file == adapt_file:
            datasets[index] = dict(
                type='RepeatDataset', times=repeat, dataset=dict(entry, data_root=f'{data_root}/'))
    return cfg


def train_round(cfg: Config) -> Path:
    """Train one run with mmengine's Runner (checkpoints loaded weights-only); returns its
    checkpoint."""
    from mmengine.runner import Runner

    from projects.synthdet.checkpoint import TRAINING_CHECKPOINT_TYPES
    with torch.serialization.safe_globals(TRAINING_CHECKPOINT_TYPES):
        Runner.from_cfg(cfg).train()
    return Path(cfg.work_dir) / f'iter_{cfg.train_cfg["max_iters"]}.pth'


def check_share(cfg: Config) -> None:
    """``ValueError`` naming the config when it lacks the self-training settings."""
    for key in ('adapt_area', 'adapt_share'):
        if key not in cfg:
            raise ValueError(f'{cfg.filename}: no {key}: use a self-training config such as '
                             'configs/tr3d/adapt_selftrain.py')
    share = cfg.adapt_share
    if not isinstance(share, (int, float)) or not math.isfinite(share) or not 0 < share < 1:
        raise ValueError(f'{cfg.filename}: adapt_share {share!r}: expected a number in (0, 1)')
    if not any(entry.ann_file == area_info_file(cfg.adapt_area)
               for entry in cfg.train_dataloader.dataset.dataset.datasets):
        raise ValueError(f'{cfg.filename}: the training datasets do not list adapt_area '
                         f'{cfg.adapt_area}')
