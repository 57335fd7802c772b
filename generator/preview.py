"""Top-down PNG preview of a generated room: points coloured by class, object boxes outlined."""
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from generator.layout import box_corners_xy

CLASS_COLOURS = {
    'table': (230, 159, 0),
    'chair': (86, 180, 233),
    'sofa': (0, 158, 115),
    'yumi': (213, 94, 0),
    '3dprinter': (204, 121, 167),
    'clutter': (120, 120, 120),
    'wall': (200, 200, 200),
    'floor': (60, 60, 60),
    'ceiling': (240, 240, 240),
    'door': (140, 90, 40),
    'window': (120, 200, 240)
}


def write_preview(path: Path,
                  xyz: np.ndarray,
                  part: np.ndarray,
                  part_classes: Sequence[str],
                  meta: dict[str, Any],
                  pixels_per_metre: int = 40) -> None:
    """Top-down PNG: points coloured by class (higher points drawn last), boxes outlined."""
    from PIL import Image, ImageDraw
    polygon = np.asarray(meta['room']['polygon'], dtype=float)
    lo = polygon.min(axis=0) - 0.3
    hi = polygon.max(axis=0) + 0.3
    size = np.ceil((hi - lo) * pixels_per_metre).astype(int) + 1
    image = np.full((size[1], size[0], 3), 255, dtype=np.uint8)
    part_palette = np.array([CLASS_COLOURS.get(c, (0, 0, 0)) for c in part_classes], np.uint8)
    visible = np.array([c != 'ceiling' for c in part_classes])[part]
    order = np.flatnonzero(visible)[np.argsort(xyz[visible, 2], kind='stable')]
    pts, palette = xyz[order], part_palette[part[order]]
    col = ((pts[:, 0] - lo[0]) * pixels_per_metre).astype(int)
    row = (size[1] - 1 - (pts[:, 1] - lo[1]) * pixels_per_metre).astype(int)
    image[row.clip(0, size[1] - 1), col.clip(0, size[0] - 1)] = palette
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)

    def to_pixels(xy):
        return [(float(
            (x - lo[0]) * pixels_per_metre), float(size[1] - 1 - (y - lo[1]) * pixels_per_metre))
                for x, y in xy]

    draw.polygon(to_pixels(polygon), outline=(0, 0, 0))
    for obj in meta['objects']:
        box = obj['box']
        corners = box_corners_xy(box['center'], box['size'], box['yaw'])
        draw.polygon(to_pixels(corners), outline=CLASS_COLOURS.get(obj['class'], (0, 0, 0)))
    picture.save(path)
