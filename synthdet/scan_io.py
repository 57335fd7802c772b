"""Read and write room scans: the project's only scan reader.

Every reader returns an ``(N, 6)`` float64 array ``x y z r g b`` (metres, colours 0-255;
scans without colours get 0). The formats are tables keyed by file suffix, so a new format is
one reader (and writer) function and one table entry:

- ``.txt``: ``x y z r g b`` or ``x y z`` lines (S3DIS), by :mod:`synthdet.point_text`;
- ``.bin``: float32 rows of ``x y z r g b`` (the converted data's ``points/*.bin``);
- ``.ply``: a ``vertex`` element with ``x y z`` and optional colours, by :mod:`synthdet.ply`.

Errors for bad files are ``ScanFormatError`` naming the file (and the line for text).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np

from synthdet.ply import read_ply_vertices, write_ply
from synthdet.point_text import PointFileError, format_lines, read_point_file


MAX_FLOAT32_RESOLUTION = 0.01  # metres between neighbouring float32 coordinates of a scan


class ScanFormatError(ValueError):
    """A scan file that is empty, malformed or holds non-finite values."""


def _float32_resolution(xyz: np.ndarray) -> tuple[float, float]:
    """The largest absolute coordinate and the float32 spacing there (NaN if not finite)."""
    largest = float(np.abs(xyz).max()) if len(xyz) else 0.0
    return largest, float(np.spacing(np.float32(largest)))


def _check_float32_resolution(path: Path, xyz: np.ndarray) -> None:
    """Refuse float32 coordinates too large for centimetres (e.g. georeferenced ones)."""
    largest, resolution = _float32_resolution(xyz)
    if resolution > MAX_FLOAT32_RESOLUTION:  # NaN for inf: the finite check reports that
        raise ScanFormatError(f'{path}: float32 coordinates up to {largest:.0f} m are only '
                              f'{resolution:g} m apart; store a georeferenced scan with a local '
                              'origin (subtract a point near the room) or as float64 .ply/.txt')


def _read_txt(path: Path) -> np.ndarray:
    try:
        points, _ = read_point_file(path, columns=_text_columns(path))
    except PointFileError as error:
        raise ScanFormatError(str(error)) from None
    if points.shape[1] == 3:
        points = np.hstack([points, np.zeros((len(points), 3))])
    return points


def _text_columns(path: Path) -> int:
    """The number of values on the first non-blank line: 6 (x y z r g b) or 3 (x y z)."""
    with open(path, 'rb') as stream:
        for number, line in enumerate(stream, start=1):
            count = len(line.split())
            if count in (3, 6):
                return count
            if count:
                raise ScanFormatError(f'{path}:{number}: expected 6 numbers per line '
                                      f'(x y z r g b) or 3 (x y z), got {count}')
    raise ScanFormatError(f'{path}: the scan holds no points')


def _read_bin(path: Path) -> np.ndarray:
    size = path.stat().st_size
    if size % (6 * 4):
        raise ScanFormatError(f'{path}: {size} bytes is not a whole number of float32 rows of '
                              f'6 values (x y z r g b)')
    points = np.fromfile(path, dtype=np.float32).reshape(-1, 6)
    _check_float32_resolution(path, points[:, :3])
    return points.astype(np.float64)


PLY_COLOUR_NAMES = (
    ('red', 'green', 'blue'),
    ('r', 'g', 'b'),
    ('diffuse_red', 'diffuse_green', 'diffuse_blue'),
)


def _read_ply(path: Path) -> np.ndarray:
    try:
        vertex = read_ply_vertices(path)
    except ValueError as error:
        raise ScanFormatError(str(error)) from None
    names = vertex.dtype.names or ()
    if not {'x', 'y', 'z'} <= set(names):
        raise ScanFormatError(f'{path}: PLY vertices need x, y and z properties, got {names}')
    points = np.zeros((len(vertex), 6))
    for i, name in enumerate(('x', 'y', 'z')):
        points[:, i] = vertex[name]
    if vertex['x'].dtype.itemsize < 8:
        _check_float32_resolution(path, points[:, :3])
    for colour_names in PLY_COLOUR_NAMES:
        if set(colour_names) <= set(names):
            for i, name in enumerate(colour_names):
                points[:, 3 + i] = vertex[name]
            if vertex[colour_names[0]].dtype.kind == 'f' and len(points) and \
                    np.nanmax(points[:, 3:]) <= 1.0:
                points[:, 3:] *= 255.0  # float colours in [0, 1]
            break
    return points


def _write_txt(path: Path, points: np.ndarray) -> None:
    text, _ = format_lines(points[:, :3], _colours_0_255(points), decimals=6)
    path.write_bytes(text)


def _write_bin(path: Path, points: np.ndarray) -> None:
    largest, resolution = _float32_resolution(points[:, :3])
    if not resolution <= MAX_FLOAT32_RESOLUTION:
        raise ValueError(f'{path}: float32 .bin coordinates up to {largest:.0f} m would be only '
                         f'{resolution:g} m apart; subtract a local origin or write .ply/.txt')
    points.astype(np.float32).tofile(path)


def _write_ply(path: Path, points: np.ndarray) -> None:
    write_ply(path, ply_vertex(points))


def ply_vertex(points: np.ndarray) -> dict[str, np.ndarray]:
    """PLY vertex properties of an ``(N, 6)`` scan: ``x y z`` float32 (float64 when float32
    would be more than 1 cm apart, as for georeferenced coordinates), ``red green blue`` uchar.
    """
    colours = _colours_0_255(points).astype(np.uint8)
    _, resolution = _float32_resolution(points[:, :3])
    coordinate = np.float32 if resolution <= MAX_FLOAT32_RESOLUTION else np.float64
    return {
        'x': points[:, 0].astype(coordinate),
        'y': points[:, 1].astype(coordinate),
        'z': points[:, 2].astype(coordinate),
        'red': colours[:, 0],
        'green': colours[:, 1],
        'blue': colours[:, 2],
    }


def _colours_0_255(points: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(points[:, 3:6]), 0, 255).astype(np.int64)


# suffix -> function reading that format into (N, 6) float64
READERS: dict[str, Callable[[Path], np.ndarray]] = {
    '.txt': _read_txt,
    '.bin': _read_bin,
    '.ply': _read_ply,
}
# suffix -> function writing an (N, 6) float64 array in that format
WRITERS: dict[str, Callable[[Path, np.ndarray], None]] = {
    '.txt': _write_txt,
    '.bin': _write_bin,
    '.ply': _write_ply,
}
SCAN_SUFFIXES = tuple(READERS)


def read_scan(path: str | os.PathLike) -> np.ndarray:
    """Read a scan file into an ``(N, 6)`` float64 array of ``x y z r g b``.

    Raises ``ScanFormatError`` naming the file (and the line for text) on an unknown suffix,
    empty or malformed input and non-finite values; ``FileNotFoundError`` if it does not exist.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'{path}: scan file not found')
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise ScanFormatError(f'{path}: unknown scan type {path.suffix.lower()!r}, expected one '
                              f'of {", ".join(SCAN_SUFFIXES)}')
    points = reader(path)
    if len(points) == 0:
        raise ScanFormatError(f'{path}: the scan holds no points')
    bad_rows = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if len(bad_rows):
        raise ScanFormatError(f'{path} (point {bad_rows[0]}): non-finite coordinate or colour '
                              f'({len(bad_rows)} bad points in total)')
    return points


def write_scan(path: str | os.PathLike, points: np.ndarray) -> None:
    """Write an ``(N, 6)`` (or ``(N, 3)``) array in the format of the path's suffix.

    Colours are rounded to integers 0-255; ``.txt`` keeps 6 decimals (micrometres), ``.bin``
    and ``.ply`` float32 (a ``.ply`` float64 for coordinates float32 cannot hold to 1 cm, which
    a ``.bin`` refuses). Non-finite points raise ``ValueError``. The file is written next to
    its destination and renamed into place, so readers never see a partial file.
    """
    path = Path(path)
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (3, 6):
        raise ValueError(f'{path}: points must be (N, 3) or (N, 6), got {points.shape}')
    if points.shape[1] == 3:
        points = np.hstack([points, np.zeros((len(points), 3))])
    if not np.isfinite(points).all():
        raise ValueError(f'{path}: points must be finite')
    writer = WRITERS.get(path.suffix.lower())
    if writer is None:
        raise ValueError(f'{path}: unknown scan type {path.suffix.lower()!r}, expected one of '
                         f'{", ".join(WRITERS)}')
    temporary = path.with_name(f'{path.name}.tmp{os.getpid()}{path.suffix}')
    writer(temporary, points)
    os.replace(temporary, path)
