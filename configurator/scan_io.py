"""Read and write room scans: S3DIS ``.txt``, raw ``.bin`` (float32 N x 6) and ``.ply``.

Every reader returns an ``(N, 6)`` float64 array ``x y z r g b`` (metres, colours 0-255).
This is the project's shared scan reader; it depends on numpy, pandas and plyfile only.
"""
from __future__ import annotations
import os
from pathlib import Path

import numpy as np

SCAN_SUFFIXES = ('.txt', '.bin', '.ply')
MAX_FLOAT32_RESOLUTION = 0.01  # metres between neighbouring float32 coordinates of a scan


class ScanFormatError(ValueError):
    """A scan file that is empty, malformed or holds non-finite values."""


def read_scan(path: str | os.PathLike) -> np.ndarray:
    """Read a scan file into an ``(N, 6)`` float64 array of ``x y z r g b``.

    ``.txt`` holds 6 (or 3, colours then 0) whitespace-separated numbers per line,
    ``.bin`` float32 rows of 6 values, ``.ply`` a ``vertex`` element with ``x y z`` and
    optional ``red green blue``. Raises ``ScanFormatError`` naming the file (and the line
    for text) on empty or malformed input, ``FileNotFoundError`` if it does not exist.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'{path}: scan file not found')
    suffix = path.suffix.lower()
    if suffix == '.txt':
        points = _read_txt(path)
    elif suffix == '.bin':
        points = _read_bin(path)
    elif suffix == '.ply':
        points = _read_ply(path)
    else:
        raise ScanFormatError(f'{path}: unknown scan type {suffix!r}, expected one of '
                              f'{", ".join(SCAN_SUFFIXES)}')
    if len(points) == 0:
        raise ScanFormatError(f'{path}: the scan holds no points')
    _check_finite(path, points, line_numbers=suffix == '.txt')
    return points


def write_scan(path: str | os.PathLike, points: np.ndarray) -> None:
    """Write an ``(N, 6)`` (or ``(N, 3)``) array as ``.txt``, ``.bin`` or ``.ply`` by suffix.

    The file is written next to its destination and renamed into place, so readers never
    see a partial file. Non-finite points, and coordinates too large for float32 in a
    ``.bin``, raise ``ValueError``; a ``.ply`` holds them as float64.
    """
    path = Path(path)
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (3, 6):
        raise ValueError(f'{path}: points must be (N, 3) or (N, 6), got {points.shape}')
    if points.shape[1] == 3:
        points = np.hstack([points, np.zeros((len(points), 3))])
    if not np.isfinite(points).all():
        raise ValueError(f'{path}: points must be finite')
    suffix = path.suffix.lower()
    largest, resolution = _float32_resolution(points[:, :3])
    if suffix == '.bin' and not resolution <= MAX_FLOAT32_RESOLUTION:
        raise ValueError(f'{path}: float32 .bin coordinates up to {largest:.0f} m would be only '
                         f'{resolution:g} m apart; subtract a local origin or write .ply/.txt')
    coordinate_type = 'f4' if resolution <= MAX_FLOAT32_RESOLUTION else 'f8'
    tmp = path.with_name(path.name + '.tmp')
    if suffix == '.txt':
        colours = np.clip(np.rint(points[:, 3:]), 0, 255)
        np.savetxt(tmp, np.hstack([points[:, :3], colours]), fmt='%.6f %.6f %.6f %d %d %d')
    elif suffix == '.bin':
        points.astype(np.float32).tofile(tmp)
    elif suffix == '.ply':
        from plyfile import PlyData, PlyElement
        vertex = np.empty(
            len(points),
            dtype=[('x', coordinate_type), ('y', coordinate_type), ('z', coordinate_type),
                   ('red', 'u1'), ('green', 'u1'), ('blue', 'u1')])
        for i, name in enumerate(('x', 'y', 'z')):
            vertex[name] = points[:, i]
        for i, name in enumerate(('red', 'green', 'blue')):
            vertex[name] = np.clip(np.rint(points[:, 3 + i]), 0, 255)
        PlyData([PlyElement.describe(vertex, 'vertex')]).write(str(tmp))
    else:
        raise ValueError(f'{path}: unknown scan type {suffix!r}, expected one of '
                         f'{", ".join(SCAN_SUFFIXES)}')
    os.replace(tmp, path)


def _read_txt(path: Path) -> np.ndarray:
    import pandas as pd
    try:
        frame = pd.read_csv(
            path, sep=r'\s+', header=None, dtype=np.float64, engine='c', comment=None)
    except pd.errors.EmptyDataError:
        raise ScanFormatError(f'{path}: the scan holds no points') from None
    except (ValueError, pd.errors.ParserError):
        error = _first_bad_line_error(path)
        raise error or ScanFormatError(f'{path}: not whitespace-separated numbers') from None
    values = frame.to_numpy()
    if np.isnan(values).any():  # short lines are padded with NaN: report the line itself
        error = _first_bad_line_error(path)
        if error is not None:
            raise error
    if values.shape[1] not in (3, 6):
        raise ScanFormatError(f'{path}:1: expected 6 numbers per line (x y z r g b), '
                              f'got {values.shape[1]}')
    if values.shape[1] == 3:
        values = np.hstack([values, np.zeros((len(values), 3))])
    return values


def _first_bad_line_error(path: Path) -> ScanFormatError | None:
    """Scan a text file line by line and describe the first line that does not parse."""
    expected = None
    with open(path, encoding='utf-8', errors='replace') as handle:
        for number, line in enumerate(handle, start=1):
            fields = line.split()
            if not fields:
                continue  # blank lines are skipped, as by the fast reader
            if expected is None:
                expected = len(fields)
                if expected not in (3, 6):
                    return ScanFormatError(f'{path}:{number}: expected 6 numbers per line '
                                           f'(x y z r g b), got {expected}')
            if len(fields) != expected:
                return ScanFormatError(f'{path}:{number}: expected {expected} numbers, '
                                       f'got {len(fields)}')
            for field in fields:
                try:
                    float(field)
                except ValueError:
                    return ScanFormatError(f'{path}:{number}: not a number: {field!r}')
    return None


def _read_bin(path: Path) -> np.ndarray:
    size = path.stat().st_size
    if size % (6 * 4):
        raise ScanFormatError(f'{path}: {size} bytes is not a whole number of float32 rows of '
                              f'6 values (x y z r g b)')
    points = np.fromfile(path, dtype=np.float32).reshape(-1, 6)
    _check_float32_resolution(path, points)
    return points.astype(np.float64)


def _float32_resolution(xyz: np.ndarray) -> tuple[float, float]:
    """The largest absolute coordinate and the float32 spacing there (NaN if not finite)."""
    largest = float(np.abs(xyz).max()) if len(xyz) else 0.0
    return largest, float(np.spacing(np.float32(largest)))


def _check_float32_resolution(path: Path, points: np.ndarray) -> None:
    largest, resolution = _float32_resolution(points[:, :3])
    if resolution > MAX_FLOAT32_RESOLUTION:  # NaN for inf: the finite check reports that
        raise ScanFormatError(f'{path}: float32 coordinates up to {largest:.0f} m are only '
                              f'{resolution:g} m apart; store a georeferenced scan with a local '
                              'origin (subtract a point near the room) or as float64 .ply/.txt')


def _read_ply(path: Path) -> np.ndarray:
    from plyfile import PlyData
    try:
        ply = PlyData.read(str(path))
    except Exception as error:  # plyfile raises several types for broken headers and bodies
        raise ScanFormatError(f'{path}: not a readable PLY file ({error})') from None
    if 'vertex' not in ply:
        raise ScanFormatError(f'{path}: PLY file has no vertex element')
    vertex = ply['vertex'].data
    names = vertex.dtype.names or ()
    if not {'x', 'y', 'z'} <= set(names):
        raise ScanFormatError(f'{path}: PLY vertices need x, y and z properties, got {names}')
    points = np.zeros((len(vertex), 6))
    for i, name in enumerate(('x', 'y', 'z')):
        points[:, i] = vertex[name]
    if vertex['x'].dtype.itemsize < 8:
        _check_float32_resolution(path, points)
    for colour_names in (('red', 'green', 'blue'), ('r', 'g', 'b'),
                         ('diffuse_red', 'diffuse_green', 'diffuse_blue')):
        if set(colour_names) <= set(names):
            for i, name in enumerate(colour_names):
                points[:, 3 + i] = vertex[name]
            if vertex[colour_names[0]].dtype.kind == 'f' and len(points) and \
                    np.nanmax(points[:, 3:]) <= 1.0:
                points[:, 3:] *= 255.0  # float colours in [0, 1]
            break
    return points


def _check_finite(path: Path, points: np.ndarray, line_numbers: bool) -> None:
    bad_rows = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if len(bad_rows):
        where = f'{path}:{bad_rows[0] + 1}' if line_numbers else f'{path} (point {bad_rows[0]})'
        raise ScanFormatError(f'{where}: non-finite coordinate or colour '
                              f'({len(bad_rows)} bad points in total)')
