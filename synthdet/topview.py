"""Top views of scans: the project's one renderer (PNG, matplotlib with the Agg backend).

Points are colored by class, RGB or height; ground-truth boxes are drawn solid, predictions
dashed with their scores, and a room outline with its numbered corners. ``generator
--preview``, ``python -m configurator corners --preview`` and ``tools/visualize.py`` all draw
with :func:`draw_top_view`, in the class colors of :data:`synthdet.classes.CLASS_COLORS`.
"""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from synthdet.classes import CLASS_COLORS, class_color
from synthdet.outputs import write_bytes
from synthdet.room_data import Box, Scan


def class_colors(labels: np.ndarray) -> np.ndarray:
    """(N, 3) colors in 0-1 for an array of class names."""
    unique, inverse = np.unique(labels.astype(str), return_inverse=True)
    palette = np.array([class_color(name) for name in unique], dtype=float) / 255.0
    return palette[inverse.reshape(-1)]


def point_colors(scan: Scan, color_by: str) -> np.ndarray:
    """Colors (0-1) of the points: ``class`` (needs labels), ``rgb`` or ``height``."""
    import matplotlib

    if color_by == 'class':
        if scan.labels is None:
            raise ValueError(f'{scan.source}: no annotations found, cannot color by class')
        return class_colors(scan.labels)
    if color_by == 'rgb':
        return np.clip(scan.points[:, 3:6] / 255.0, 0, 1)
    if color_by == 'height':
        z = scan.points[:, 2]
        return matplotlib.colormaps['viridis']((z - z.min()) / max(np.ptp(z), 1e-9))[:, :3]
    raise ValueError(f'unknown coloring {color_by!r}, expected class, rgb or height')


def default_coloring(scan: Scan) -> str:
    """By class when annotations exist, else by RGB when the scan has colors, else height."""
    if scan.labels is not None:
        return 'class'
    return 'rgb' if np.ptp(scan.points[:, 3:6]) > 0 else 'height'


def draw_top_view(out: str | os.PathLike,
                  scan: Scan,
                  gt: list[Box] = (),
                  pred: list[Box] = (),
                  corners: np.ndarray | None = None,
                  color_by: str | None = None,
                  title: str = '',
                  max_points: int = 400_000,
                  seed: int = 0,
                  corners_label: str = 'corners') -> None:
    """Save a PNG of the scan seen from above: points (ceiling removed), ground-truth boxes as
    solid outlines, predicted boxes dashed with their scores, the corner polygon in black
    (``corners_label`` names it in the legend). The picture is drawn in memory and written
    through a checked temporary file (``synthdet.outputs``)."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    color_by = color_by or default_coloring(scan)
    points, colors, labels = _visible_points(scan, color_by, max_points, seed)
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
        c=colors[order],
        s=marker,
        linewidths=0,
        rasterized=True)
    _draw_boxes(axes, gt, pred)
    if corners is not None:
        _draw_corners(axes, corners)
    shown = set(labels.astype(str)) if labels is not None else set()
    handles = _legend_handles(shown | {box.label for box in (*gt, *pred)}, color_by, bool(gt),
                              bool(pred), corners, corners_label)
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
    picture = io.BytesIO()
    figure.savefig(picture, format='png')
    plt.close(figure)
    write_bytes(out, picture.getvalue())


def _visible_points(scan: Scan, color_by: str, max_points: int,
                    seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The points seen from above (the ceiling removed), their colors and labels, at most
    ``max_points`` of them (a seeded random choice)."""
    points, labels = scan.points, scan.labels
    if labels is not None:
        keep = labels != 'ceiling'  # the ceiling would hide the room
    else:
        z = points[:, 2]
        keep = z < z.min() + 0.85 * np.ptp(z)  # no labels: cut the top (ceiling) off
    colors = point_colors(scan, color_by)[keep]
    points = points[keep]
    labels = labels[keep] if labels is not None else None
    if len(points) > max_points:
        chosen = np.sort(
            np.random.default_rng(seed).choice(len(points), max_points, replace=False))
        points, colors = points[chosen], colors[chosen]
        labels = labels[chosen] if labels is not None else None
    return points, colors, labels


def _draw_boxes(axes, gt: list[Box], pred: list[Box]) -> None:
    """Ground-truth footprints solid in their class colors; predictions dashed, with a label
    of their class and score."""
    from matplotlib.patches import Polygon

    for box in gt:
        color = np.array(class_color(box.label)) / 255.0
        axes.add_patch(
            Polygon(box.footprint(), closed=True, fill=False, edgecolor=color, linewidth=2.2))
    for box in pred:
        color = np.array(class_color(box.label)) / 255.0
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
                edgecolor=color,
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
            bbox=dict(boxstyle='round,pad=0.15', fc='white', ec=color, lw=0.8, alpha=0.85))


def _draw_corners(axes, corners: np.ndarray) -> None:
    """The closed corner polygon in black, its corners numbered."""
    ring = np.vstack([corners, corners[:1]])
    axes.plot(ring[:, 0], ring[:, 1], '-', color='black', linewidth=1.6)
    axes.plot(corners[:, 0], corners[:, 1], 'o', color='black', markersize=4)
    for index, (x, y) in enumerate(corners):
        axes.annotate(str(index), (x, y), textcoords='offset points', xytext=(4, 4), fontsize=8)


def _legend_handles(shown: set[str], color_by: str, has_gt: bool, has_pred: bool,
                    corners: np.ndarray | None, corners_label: str) -> list:
    """Legend entries: the ``shown`` classes (when colored by class), then ground truth,
    predictions and the corners when drawn."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = []
    if color_by == 'class':
        handles += [
            Patch(color=np.array(class_color(name)) / 255, label=name) for name in CLASS_COLORS
            if name in shown
        ]
    if has_gt:
        handles.append(Line2D([], [], color='grey', lw=2.2, label='ground truth'))
    if has_pred:
        handles.append(Line2D([], [], color='black', lw=1.6, ls=(0, (3, 2)), label='prediction'))
    if corners is not None:
        handles.append(
            Line2D([], [],
                   color='black',
                   lw=1.6,
                   marker='o',
                   ms=4,
                   label=f'{corners_label} ({len(corners)})'))
    return handles
