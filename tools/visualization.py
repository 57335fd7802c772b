"""Drawing scans from above with their boxes, and PLY export (the library of tools/visualize.py).

A scan is an ``(N, 6)`` array ``x y z r g b`` (metres, colours 0-255) plus, when known, a
per-point class name. Boxes are ``Box`` records (centre, size, yaw in radians, class, score);
they come from a generator ``meta.json`` (oriented), an info pickle (axis-aligned) or a
``synthdet.predictions/1`` file. Everything is drawn in the scan's own frame.
"""
from __future__ import annotations

import json
import os
import pickle
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# The converter's semantic ids (docs/dataset.md): the 13 S3DIS classes, then yumi, 3dprinter.
SEMANTIC_CLASSES = ('ceiling', 'floor', 'wall', 'beam', 'column', 'window', 'door', 'table',
                    'chair', 'sofa', 'bookcase', 'board', 'clutter', 'yumi', '3dprinter')
# Colours (0-255) per class: structure in greys, the detection classes in strong hues.
CLASS_COLOURS = {
    'ceiling': (222, 222, 222),
    'floor': (196, 196, 196),
    'wall': (158, 158, 158),
    'beam': (140, 140, 120),
    'column': (120, 120, 140),
    'window': (120, 190, 235),
    'door': (176, 140, 104),
    'clutter': (112, 112, 112),
    'table': (31, 119, 180),
    'chair': (255, 127, 14),
    'sofa': (44, 160, 44),
    'bookcase': (140, 86, 75),
    'board': (227, 119, 194),
    'yumi': (214, 39, 40),
    '3dprinter': (148, 103, 189),
}
UNKNOWN_COLOUR = (60, 60, 60)
STRUCTURE_CLASSES = frozenset(
    ('ceiling', 'floor', 'wall', 'beam', 'column', 'window', 'door', 'clutter'))


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
        half = np.array(self.size[:2], dtype=float) / 2
        local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * half
        cos, sin = np.cos(self.yaw), np.sin(self.yaw)
        rotation = np.array([[cos, -sin], [sin, cos]])
        return local @ rotation.T + np.array(self.center[:2], dtype=float)


@dataclass
class Scan:
    """Points of one scan and, when annotations were found, the class name of every point."""
    points: np.ndarray
    labels: np.ndarray | None = None  # (N,) array of class names, or None
    source: str = ''


def _read_json(path: Path, expected_format: str) -> dict:
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f'{path}:{error.lineno}: not valid JSON ({error.msg})') from None
    found = data.get('format') if isinstance(data, dict) else None
    if found != expected_format:
        raise ValueError(f'{path}: expected "format": "{expected_format}", found {found!r}')
    return data


def _annotation_class(path: Path) -> str:
    """The class of an S3DIS annotation file: its name before the first ``_``."""
    return path.stem.split('_', 1)[0]


def _natural_key(path: Path) -> list:
    return [int(part) if part.isdigit() else part for part in re.split(r'(\d+)', path.name)]


def load_scan(path: str | os.PathLike) -> Scan:
    """Read a scan (S3DIS room ``.txt``, ``.bin`` or ``.ply``) with per-point classes if known.

    An S3DIS room whose ``Annotations/`` folder sits next to it is read from its annotation
    files (the room is their concatenation), which gives every point its class. A converted
    ``points/<name>.bin`` gets its classes from ``../semantic_mask/<name>.bin``.
    """
    from configurator.scan_io import read_scan

    path = Path(path)
    annotations = path.parent / 'Annotations'
    if path.suffix.lower() == '.txt' and annotations.is_dir():
        files = sorted(annotations.glob('*.txt'), key=_natural_key)
        parts = [read_scan(file) for file in files]
        labels = np.concatenate([
            np.full(len(part), _annotation_class(file), dtype=object)
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


def boxes_from_meta(path: str | os.PathLike) -> list[Box]:
    """Ground-truth oriented boxes of a generator ``meta.json`` (``synthdet.room/1``)."""
    path = Path(path)
    meta = _read_json(path, 'synthdet.room/1')
    boxes = []
    for index, item in enumerate(meta.get('objects', [])):
        try:
            box = item['box']
            boxes.append(
                Box(item['class'], tuple(map(float, box['center'])),
                    tuple(map(float, box['size'])), float(box.get('yaw', 0.0))))
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f'{path}: objects[{index}] is not a valid box ({error})') from None
    return boxes


def boxes_from_info(path: str | os.PathLike, scan_name: str) -> list[Box]:
    """Axis-aligned ground-truth boxes of the room ``scan_name`` (e.g. ``Area_9_factory_1.bin``)
    in an mmdet3d info pickle written by ``tools/create_data.py``."""
    path = Path(path)
    with open(path, 'rb') as handle:
        infos = pickle.load(handle)
    categories = infos['metainfo']['categories']
    names = {index: name for name, index in categories.items()}
    for entry in infos['data_list']:
        if Path(entry['lidar_points']['lidar_path']).name == scan_name:
            return [
                Box(
                    names.get(int(item['bbox_label_3d']), 'unknown'),
                    tuple(map(float, item['bbox_3d'][:3])),
                    tuple(map(float, item['bbox_3d'][3:6]))) for item in entry['instances']
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
    path = Path(path)
    data = _read_json(path, 'synthdet.predictions/1')
    boxes = []
    for index, item in enumerate(data.get('detections', [])):
        try:
            box = Box(item['class'], tuple(map(float, item['center'])),
                      tuple(map(float, item['size'])), float(item.get('yaw', 0.0)),
                      float(item['score']))
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f'{path}: detections[{index}] is not valid ({error})') from None
        if box.score >= min_score:
            boxes.append(box)
    return boxes


def load_corners(path: str | os.PathLike) -> np.ndarray:
    """The (K, 2) corner polygon of a ``synthdet.corners/1`` file."""
    path = Path(path)
    corners = np.asarray(_read_json(path, 'synthdet.corners/1')['corners'], dtype=float)
    if corners.ndim != 2 or corners.shape[1] != 2 or len(corners) < 3:
        raise ValueError(f'{path}: "corners" must hold at least 3 [x, y] pairs')
    return corners


def class_colours(labels: np.ndarray) -> np.ndarray:
    """(N, 3) colours in 0-1 for an array of class names."""
    table = {name: np.array(colour) / 255.0 for name, colour in CLASS_COLOURS.items()}
    unknown = np.array(UNKNOWN_COLOUR) / 255.0
    unique, inverse = np.unique(labels.astype(str), return_inverse=True)
    palette = np.array([table.get(name, unknown) for name in unique])
    return palette[inverse]


def point_colours(scan: Scan, colour_by: str) -> np.ndarray:
    """Colours (0-1) of the points: ``class`` (needs labels), ``rgb`` or ``height``."""
    import matplotlib

    if colour_by == 'class':
        if scan.labels is None:
            raise ValueError(f'{scan.source}: no annotations found, cannot colour by class')
        return class_colours(scan.labels)
    if colour_by == 'rgb':
        return np.clip(scan.points[:, 3:6] / 255.0, 0, 1)
    if colour_by == 'height':
        z = scan.points[:, 2]
        return matplotlib.colormaps['viridis']((z - z.min()) / max(np.ptp(z), 1e-9))[:, :3]
    raise ValueError(f'unknown colouring {colour_by!r}, expected class, rgb or height')


def default_colouring(scan: Scan) -> str:
    """By class when annotations exist, else by RGB when the scan has colours, else height."""
    if scan.labels is not None:
        return 'class'
    return 'rgb' if np.ptp(scan.points[:, 3:6]) > 0 else 'height'


def draw_top_view(out: str | os.PathLike,
                  scan: Scan,
                  gt: list[Box] = (),
                  pred: list[Box] = (),
                  corners: np.ndarray | None = None,
                  colour_by: str | None = None,
                  title: str = '',
                  max_points: int = 400_000,
                  seed: int = 0) -> None:
    """Save a PNG of the scan seen from above: points (ceiling removed), ground-truth boxes as
    solid outlines, predicted boxes dashed with their scores, the corner polygon in black."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Polygon

    colour_by = colour_by or default_colouring(scan)
    points, labels = scan.points, scan.labels
    keep = np.ones(len(points), dtype=bool)
    if labels is not None:
        keep = labels != 'ceiling'  # the ceiling would hide the room
    else:
        z = points[:, 2]
        keep = z < z.min() + 0.85 * np.ptp(z)  # no labels: cut the top (ceiling) off
    colours = point_colours(scan, colour_by)[keep]
    points = points[keep]
    labels = labels[keep] if labels is not None else None
    if len(points) > max_points:
        chosen = np.sort(
            np.random.default_rng(seed).choice(len(points), max_points, replace=False))
        points, colours = points[chosen], colours[chosen]
        labels = labels[chosen] if labels is not None else None
    order = np.argsort(points[:, 2], kind='stable')  # higher points on top, as seen from above

    extent = np.vstack([points[:, :2]] + [box.footprint() for box in (*gt, *pred)] +
                       ([corners] if corners is not None else []))
    lo, hi = extent.min(axis=0), extent.max(axis=0)
    width = 9.0
    height = float(np.clip(width * (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-6), 4.0, 14.0))
    figure, axes = plt.subplots(figsize=(width + 2.6, height), dpi=110)
    # marker area (pt^2) from the point density, so sparse and dense scans both read well
    marker = float(np.clip(0.12 * (72 * width) * (72 * height) / max(len(points), 1), 0.25, 8))
    axes.scatter(
        points[order, 0],
        points[order, 1],
        c=colours[order],
        s=marker,
        linewidths=0,
        rasterized=True)
    for box in gt:
        colour = np.array(CLASS_COLOURS.get(box.label, UNKNOWN_COLOUR)) / 255.0
        axes.add_patch(
            Polygon(box.footprint(), closed=True, fill=False, edgecolor=colour, linewidth=2.2))
    for box in pred:
        colour = np.array(CLASS_COLOURS.get(box.label, UNKNOWN_COLOUR)) / 255.0
        axes.add_patch(
            Polygon(
                box.footprint(),
                closed=True,
                fill=False,
                edgecolor='black',
                linewidth=1.6,
                linestyle=(0, (3, 2))))
        axes.add_patch(
            Polygon(
                box.footprint(),
                closed=True,
                fill=False,
                edgecolor=colour,
                linewidth=1.0,
                linestyle=(3, (3, 2))))
        corner = box.footprint().max(axis=0)
        axes.annotate(
            f'{box.label} {box.score:.2f}' if box.score is not None else box.label,
            (box.center[0], corner[1]),
            ha='center',
            va='bottom',
            fontsize=6.5,
            color='black',
            bbox=dict(boxstyle='round,pad=0.15', fc='white', ec=colour, lw=0.8, alpha=0.85))
    if corners is not None:
        ring = np.vstack([corners, corners[:1]])
        axes.plot(ring[:, 0], ring[:, 1], '-', color='black', linewidth=1.6)
        axes.plot(corners[:, 0], corners[:, 1], 'o', color='black', markersize=4)
        for index, (x, y) in enumerate(corners):
            axes.annotate(
                str(index), (x, y), textcoords='offset points', xytext=(4, 4), fontsize=8)

    handles = []
    shown = set(labels.astype(str)) if labels is not None else set()
    shown |= {box.label for box in (*gt, *pred)}
    if colour_by == 'class':
        handles += [
            Patch(color=np.array(CLASS_COLOURS.get(name, UNKNOWN_COLOUR)) / 255, label=name)
            for name in CLASS_COLOURS if name in shown
        ]
    if gt:
        handles.append(Line2D([], [], color='grey', lw=2.2, label='ground truth'))
    if pred:
        handles.append(Line2D([], [], color='black', lw=1.6, ls=(0, (3, 2)), label='prediction'))
    if corners is not None:
        handles.append(
            Line2D([], [],
                   color='black',
                   lw=1.6,
                   marker='o',
                   ms=4,
                   label=f'corners ({len(corners)})'))
    if handles:
        axes.legend(
            handles=handles,
            loc='upper left',
            bbox_to_anchor=(1.01, 1.0),
            fontsize=8,
            frameon=False)
    margin = 0.3
    axes.set_xlim(lo[0] - margin, hi[0] + margin)
    axes.set_ylim(lo[1] - margin, hi[1] + margin)
    axes.set_aspect('equal')
    axes.set_xlabel('x (m)')
    axes.set_ylabel('y (m)')
    axes.set_title(title or Path(scan.source).name, fontsize=10)
    figure.tight_layout()
    figure.savefig(os.fspath(out))
    plt.close(figure)


def write_ply(out: str | os.PathLike, scan: Scan) -> None:
    """Write the scan as a binary PLY for CloudCompare: ``x y z`` (float32), ``red green blue``
    (the scan's colours) and, with annotations, a ``class`` index into ``SEMANTIC_CLASSES``
    (-1 for classes outside it), also listed in the header's comment."""
    out = Path(out)
    fields = [('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('red', 'u1'), ('green', 'u1'),
              ('blue', 'u1')]
    if scan.labels is not None:
        fields.append(('class', '<i4'))
    vertex = np.empty(len(scan.points), dtype=fields)
    for column, name in enumerate(('x', 'y', 'z')):
        vertex[name] = scan.points[:, column]
    for column, name in enumerate(('red', 'green', 'blue')):
        vertex[name] = np.clip(np.rint(scan.points[:, 3 + column]), 0, 255)
    header = ['ply', 'format binary_little_endian 1.0']
    if scan.labels is not None:
        index = {name: i for i, name in enumerate(SEMANTIC_CLASSES)}
        unique, inverse = np.unique(scan.labels.astype(str), return_inverse=True)
        vertex['class'] = np.array([index.get(name, -1) for name in unique])[inverse]
        header.append('comment class ' + ' '.join(f'{i}={n}'
                                                  for i, n in enumerate(SEMANTIC_CLASSES)))
    types = {'<f4': 'float', 'u1': 'uchar', '<i4': 'int'}
    header.append(f'element vertex {len(vertex)}')
    header += [f'property {types[kind]} {name}' for name, kind in fields]
    header.append('end_header')
    tmp = out.with_name(out.name + '.tmp')
    with open(tmp, 'wb') as handle:
        handle.write(('\n'.join(header) + '\n').encode('ascii'))
        handle.write(vertex.tobytes())
    os.replace(tmp, out)
