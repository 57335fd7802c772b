"""Scans with per-point classes and labelled boxes, loaded from the project's files.

A ``Scan`` is an ``(N, 6)`` array ``x y z r g b`` (metres, colors 0-255) plus, when known, the
class name of every point. ``Box`` records (centre, size, yaw in radians, class, score) come
from a generator ``meta.json`` (oriented), an info pickle (axis-aligned) or a
``synthdet.predictions/1`` file; the JSON files are read through :mod:`synthdet.contracts`.
Everything stays in the scan's own frame.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from synthdet.classes import SEMANTIC_CLASSES
from synthdet.contracts import read_corners, read_predictions, read_room
from synthdet.geometry import box_corners_xy
from synthdet.info_files import labelled_boxes
from synthdet.ply import write_ply
from synthdet.scan_io import ply_vertex, read_scan


@dataclass(frozen=True)
class Box:
    """A labelled 3D box: ``center`` and ``size`` in metres, ``yaw`` (rad, counter-clockwise
    about z; the size is along the box's own axes) and, for predictions, a ``score``."""
    label: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0
    score: float | None = None

    def footprint(self) -> np.ndarray:
        """The 4 floor corners of the box, counter-clockwise, as a (4, 2) array."""
        return box_corners_xy(self.center, self.size, self.yaw)


@dataclass
class Scan:
    """Points of one scan and, when annotations were found, the class name of every point."""
    points: np.ndarray
    labels: np.ndarray | None = None  # (N,) array of class names, or None
    source: str = ''


_ANNOTATION_NAME = re.compile(r'(?P<cls>.+)_\d+\.txt', re.IGNORECASE)


def annotation_class(path: Path) -> str | None:
    """The class of an S3DIS annotation file ``<class>_<index>.txt``: its name minus the
    ``_<index>.txt`` suffix (matched in any case), so ``yumi_robot_1.txt`` is ``yumi_robot``;
    None for a name without that suffix."""
    match = _ANNOTATION_NAME.fullmatch(path.name)
    return match['cls'] if match else None


def annotation_files(folder: Path) -> list[Path]:
    """The ``.txt`` files (any case of the suffix) of an ``Annotations`` folder, in natural
    order; none if the folder does not exist. A broken symbolic link is listed too, so that its
    reader reports it instead of leaving an object out without a word."""
    if not folder.is_dir():
        return []
    return sorted((p for p in folder.iterdir() if p.suffix.lower() == '.txt' and not p.is_dir()),
                  key=lambda p: natural_key(p.name))


def natural_key(name: str) -> list:
    """Sort key that puts ``office_2`` before ``office_10``."""
    return [int(part) if part.isdigit() else part for part in re.split(r'(\d+)', name)]


def load_scan(path: str | os.PathLike) -> Scan:
    """Read a scan (S3DIS room ``.txt`` or any ``synthdet.scan_io`` format) with per-point
    classes if known.

    An S3DIS room whose ``Annotations/`` folder sits next to it is read from its annotation
    files (the room is their concatenation), which gives every point its class. A converted
    ``points/<name>.bin`` gets its classes from ``../semantic_mask/<name>.bin``.
    """
    path = Path(path)
    annotations = path.parent / 'Annotations'
    if path.suffix.lower() == '.txt' and annotations.is_dir():
        files = annotation_files(annotations)
        parts = [read_scan(file) for file in files]
        labels = np.concatenate([
            np.full(len(part), annotation_class(file) or file.stem, dtype=object)
            for part, file in zip(parts, files)
        ])
        return Scan(np.concatenate(parts), labels, str(path))
    points = read_scan(path)
    mask = path.parent.parent / 'semantic_mask' / path.name
    if path.suffix.lower() == '.bin' and path.parent.name == 'points' and mask.is_file():
        ids = np.fromfile(mask, dtype=np.int64)
        if len(ids) != len(points):
            raise ValueError(f'{mask}: {len(ids)} labels for the {len(points)} points of {path}')
        names = np.array(SEMANTIC_CLASSES + ('unknown', ), dtype=object)
        return Scan(points, names[np.clip(ids, 0, len(SEMANTIC_CLASSES))], str(path))
    return Scan(points, None, str(path))


def boxes_from_room(room: dict) -> list[Box]:
    """Ground-truth oriented boxes of a validated ``synthdet.room/1`` document."""
    return [
        Box(item['class'], tuple(map(float, item['box']['center'])),
            tuple(map(float, item['box']['size'])), float(item['box'].get('yaw', 0.0)))
        for item in room['objects']
    ]


def boxes_from_meta(path: str | os.PathLike) -> list[Box]:
    """Ground-truth oriented boxes of a generator ``meta.json`` (``synthdet.room/1``)."""
    return boxes_from_room(read_room(path))


def boxes_from_info(path: str | os.PathLike, scan_name: str) -> list[Box]:
    """Axis-aligned ground-truth boxes of the room ``scan_name`` (e.g. ``Area_9_factory_1.bin``)
    in an mmdet3d info pickle written by ``tools/create_data.py`` (``InfoFileError`` naming
    the file for one that is not the converter's)."""
    for scan, boxes in labelled_boxes(path):
        if scan == scan_name:
            return [
                Box(name, tuple(map(float, box[:3])), tuple(map(float, box[3:6])))
                for name, box in boxes
            ]
    raise ValueError(f'{path}: no room with lidar_path {scan_name!r}')


def load_ground_truth(path: str | os.PathLike, scan_path: str | os.PathLike) -> list[Box]:
    """Ground-truth boxes from a ``meta.json`` or an info ``.pkl`` (matched by the scan's name)."""
    path = Path(path)
    if path.suffix == '.pkl':
        return boxes_from_info(path, Path(scan_path).name)
    return boxes_from_meta(path)


def boxes_from_predictions(path: str | os.PathLike, min_score: float = 0.0) -> list[Box]:
    """Detections of a ``synthdet.predictions/1`` file scoring at least ``min_score``."""
    return [
        Box(item['class'], tuple(item['center']), tuple(item['size']), item['yaw'], item['score'])
        for item in read_predictions(path)['detections'] if item['score'] >= min_score
    ]


def corner_polygon(path: str | os.PathLike) -> np.ndarray:
    """The (K, 2) clockwise corner polygon of a ``synthdet.corners/1`` file."""
    return np.array(read_corners(path)['corners'], dtype=np.float64)


def write_labelled_ply(out: str | os.PathLike, scan: Scan) -> None:
    """Write the scan as a binary PLY for CloudCompare: ``x y z`` (float32), ``red green blue``
    (the scan's colors) and, with annotations, a ``class`` index into ``SEMANTIC_CLASSES``
    (-1 for classes outside it), also listed in the header's comment."""
    vertex = ply_vertex(scan.points)
    comments = []
    if scan.labels is not None:
        index = {name: i for i, name in enumerate(SEMANTIC_CLASSES)}
        unique, inverse = np.unique(scan.labels.astype(str), return_inverse=True)
        vertex['class'] = np.array([index.get(name, -1) for name in unique], np.int32)[inverse]
        comments.append('class ' + ' '.join(f'{i}={n}' for i, n in enumerate(SEMANTIC_CLASSES)))
    write_ply(out, vertex, comments)
