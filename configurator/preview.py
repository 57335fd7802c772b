"""Top-view preview PNG of a scan with its room outline drawn on it (matplotlib, Agg)."""
from __future__ import annotations
import os

import numpy as np


def save_preview(path: str | os.PathLike,
                 points: np.ndarray,
                 corners: np.ndarray,
                 title: str = '',
                 max_points: int = 300_000,
                 seed: int = 0) -> None:
    """Draw ``points`` seen from above (their colours, subsampled) and the closed polygon
    ``corners`` with numbered corners, and save it as a PNG at ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    points = np.asarray(points)
    corners = np.asarray(corners)
    if len(points) > max_points:
        points = points[np.random.default_rng(seed).choice(len(points), max_points, replace=False)]
    points = points[np.argsort(points[:, 2])]  # higher points drawn last, as seen from above
    if points.shape[1] >= 6 and np.ptp(points[:, 3:6]) > 0:
        colours = np.clip(points[:, 3:6] / 255.0, 0, 1)
    else:
        colours = points[:, 2]
    figure, axes = plt.subplots(figsize=(8, 8), dpi=100)
    axes.scatter(points[:, 0], points[:, 1], c=colours, s=0.2, linewidths=0, rasterized=True)
    ring = np.vstack([corners, corners[:1]])
    axes.plot(ring[:, 0], ring[:, 1], '-', color='red', linewidth=1.5)
    axes.plot(corners[:, 0], corners[:, 1], 'o', color='red', markersize=4)
    for index, (x, y) in enumerate(corners):
        axes.annotate(
            str(index), (x, y), textcoords='offset points', xytext=(4, 4), color='red', fontsize=9)
    axes.set_aspect('equal')
    axes.set_xlabel('x (m)')
    axes.set_ylabel('y (m)')
    axes.set_title(title or f'{len(corners)} corners, clockwise from 0')
    figure.tight_layout()
    figure.savefig(os.fspath(path))
    plt.close(figure)
