"""PLY scans: a ``vertex`` element with ``x y z`` and optional colors or intensity, read and
written by :mod:`synthdet.ply`."""
from __future__ import annotations

from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from synthdet.ply import read_ply_vertices
from synthdet.ply import write_ply as write_ply_file
from synthdet.scan_io.common import (Scale, ScanFormatError, colors_0_255, no_color_note,
                                     structured_chunk)

PLY_COLOR_NAMES = (
    ('red', 'green', 'blue'),
    ('r', 'g', 'b'),
    ('diffuse_red', 'diffuse_green', 'diffuse_blue'),
)
PLY_INTENSITY_NAMES = ('intensity', 'scalar_intensity', 'scalar_Intensity', 'reflectance')


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of the ``vertex`` element (memory-mapped when binary)."""
    try:
        vertex = read_ply_vertices(path)
    except ValueError as error:
        raise ScanFormatError(str(error)) from None
    yield from _structured_chunks(path, vertex, PLY_COLOR_NAMES, PLY_INTENSITY_NAMES,
                                  chunk_points, notes, 'PLY vertices')


def _structured_chunks(path: Path, table: np.ndarray, color_names: Sequence[Sequence[str]],
                       intensity_names: Sequence[str], chunk_points: int, notes: list[str],
                       what: str) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of a structured array with ``x y z`` and optional color fields."""
    names = table.dtype.names or ()
    if not {'x', 'y', 'z'} <= set(names):
        raise ScanFormatError(f'{path}: {what} need x, y and z properties, got {names}')
    color = next((list(group) for group in color_names if set(group) <= set(names)), None)
    intensity = next((name for name in intensity_names if name in names), None)
    if color is None:
        notes.append(no_color_note(path, intensity is not None))
    scale = Scale(0.0, 255.0)
    if color is not None and table.dtype[color[0]].kind == 'f':
        scale = Scale()  # float colors: [0, 1] or 0-255, from the first chunk
    intensity_scale = Scale()
    for start in range(0, len(table), chunk_points):
        part = table[start:start + chunk_points]
        colors = None if color is None else scale(
            np.column_stack([part[name] for name in color]))
        yield structured_chunk(part, colors, intensity, intensity_scale)


def write(path: Path, points: np.ndarray) -> None:
    """A binary PLY of float64 ``x y z`` and uchar ``red green blue``."""
    vertex = ply_vertex(points)
    for i, name in enumerate('xyz'):  # double, so georeferenced coordinates stay exact
        vertex[name] = points[:, i]
    write_ply_file(path, vertex)


def ply_vertex(points: np.ndarray) -> dict[str, np.ndarray]:
    """PLY vertex properties of an ``(N, 6)`` scan: ``x y z`` float32, ``red green blue``
    uchar."""
    colors = colors_0_255(points).astype(np.uint8)
    return {
        'x': points[:, 0].astype(np.float32),
        'y': points[:, 1].astype(np.float32),
        'z': points[:, 2].astype(np.float32),
        'red': colors[:, 0],
        'green': colors[:, 1],
        'blue': colors[:, 2],
    }
