"""Read and write scans: the project's only scan reader.

Every reader yields ``(n, 6)`` float64 chunks ``x y z r g b`` (metres, colors 0-255) in the
file's own coordinates, so georeferenced scans stay exact: ``read_scan`` joins the chunks,
``read_scan_chunks`` streams them and ``load_scan`` streams them into a local frame with an
optional voxel filter, in memory bounded by the kept voxels rather than the file. The formats
are tables keyed by file suffix, each format a module of this package with ``read_chunks``
(and ``write``), so a new format is one module and one entry:

- ``.txt`` (:mod:`~synthdet.scan_io.s3dis_txt`): ``x y z r g b`` or ``x y z`` lines (S3DIS);
- ``.bin`` (:mod:`~synthdet.scan_io.points_bin`): float32 rows of ``x y z r g b`` (the
  converted data's ``points/*.bin``);
- ``.ply`` (:mod:`~synthdet.scan_io.ply`): a ``vertex`` element with ``x y z`` and optional
  colors;
- ``.las``/``.laz`` (:mod:`~synthdet.scan_io.las`): ASPRS LAS by ``laspy`` (+ ``lazrs``),
  scale and offset in float64;
- ``.e57`` (:mod:`~synthdet.scan_io.e57`): every scan of the file by ``pye57``, each moved by
  its pose;
- ``.pcd`` (:mod:`~synthdet.scan_io.pcd`): Point Cloud Library files, ``ascii``, ``binary`` or
  ``binary_compressed`` (LZF);
- ``.xyz``/``.pts``/``.csv`` (:mod:`~synthdet.scan_io.text_columns`): text columns; delimiter
  and header lines are detected, the columns come from ``columns`` (``x,y,z,r,g,b``,
  ``x,y,z,i``, ``_`` skips one) or the count.

Scans without colors get their intensity as grey, or zeros without intensity; the notes say
which. Errors for bad files are ``ScanFormatError`` naming the file (and the line for text),
among them a header counting points the data does not hold and a text line longer than
``MAX_LINE_BYTES`` (:mod:`~synthdet.scan_io.common`, shared by the formats).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from synthdet.outputs import replaced_paths
from synthdet.scan_io import e57, las, pcd, ply, points_bin, s3dis_txt, text_columns
from synthdet.scan_io.common import (CHUNK_POINTS, MAX_LINE_BYTES, TEXT_BYTES_PER_POINT,
                                     ChunkReader, ScanFormatError)
from synthdet.scan_io.e57 import write_e57_scans
from synthdet.scan_io.las import write_las_chunks
from synthdet.scan_io.pcd import LZF_BLOCK, LZF_LONGEST, LZF_WINDOW
from synthdet.scan_io.ply import PLY_COLOR_NAMES, PLY_INTENSITY_NAMES, ply_vertex
from synthdet.scan_io.text_columns import COLUMN_NAMES, DEFAULT_COLUMNS, parse_columns
from synthdet.voxels import VoxelFilter

__all__ = [
    'CHUNK_POINTS', 'COLUMN_NAMES', 'DEFAULT_COLUMNS', 'LZF_BLOCK', 'LZF_LONGEST', 'LZF_WINDOW',
    'MAX_HEIGHT', 'MAX_LINE_BYTES', 'MAX_WIDTH', 'PLY_COLOR_NAMES', 'PLY_INTENSITY_NAMES',
    'READERS', 'SCAN_SUFFIXES', 'TEXT_BYTES_PER_POINT', 'WRITERS', 'ChunkReader', 'LoadedScan',
    'ScanFormatError', 'check_units', 'load_scan', 'parse_columns', 'ply_vertex', 'read_scan',
    'read_scan_chunks', 'write_e57_scans', 'write_las_chunks', 'write_scan'
]

MAX_HEIGHT = 200.0  # metres; a taller scan (robust extent) is taken to be in other units
MAX_WIDTH = 20_000.0  # metres

# suffix -> generator of (n, 6) float64 chunks: reader(path, chunk_points, columns, notes)
READERS: dict[str, ChunkReader] = {
    '.txt': s3dis_txt.read_chunks,
    '.bin': points_bin.read_chunks,
    '.ply': ply.read_chunks,
    '.las': las.read_chunks,
    '.laz': las.read_chunks,
    '.e57': e57.read_chunks,
    '.pcd': pcd.read_chunks,
    '.xyz': text_columns.read_chunks,
    '.pts': text_columns.read_chunks,
    '.csv': text_columns.read_chunks,
}
SCAN_SUFFIXES = tuple(READERS)

# suffix -> function writing an (N, 6) float64 array in that format
WRITERS: dict[str, Callable[[Path, np.ndarray], None]] = {
    '.txt': s3dis_txt.write,
    '.bin': points_bin.write,
    '.ply': ply.write,
    '.xyz': text_columns.write,
    '.pcd': pcd.write,
    '.las': las.write,
    '.laz': las.write,
    '.e57': e57.write,
}


def read_scan_chunks(path: str | os.PathLike,
                     chunk_points: int = CHUNK_POINTS,
                     columns: str | Sequence[str] | None = None,
                     notes: list[str] | None = None) -> Iterator[np.ndarray]:
    """Stream a scan file as ``(n, 6)`` float64 chunks of ``x y z r g b`` (n <= chunk_points).

    Coordinates are the file's own (georeferenced ones exact in float64). ``columns`` names
    the values of a text scan's lines (``'x,y,z,i'``). One-line notes (no colors...) are
    appended to ``notes``. Raises ``ScanFormatError`` naming the file on an unknown suffix,
    malformed, empty or non-finite input, ``FileNotFoundError`` if it does not exist.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'{path}: scan file not found')
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise ScanFormatError(f'{path}: unknown scan type {path.suffix.lower()!r}, expected one '
                              f'of {", ".join(SCAN_SUFFIXES)}')
    if chunk_points < 1:
        raise ValueError(f'chunk_points must be positive, got {chunk_points}')
    try:
        names = None if columns is None else parse_columns(columns)
    except ValueError as error:
        raise ScanFormatError(f'{path}: {error}') from None
    notes = [] if notes is None else notes
    total = 0
    for chunk in reader(path, chunk_points, names, notes):
        bad_rows = np.flatnonzero(~np.isfinite(chunk).all(axis=1))
        if len(bad_rows):
            raise ScanFormatError(f'{path} (point {total + bad_rows[0]}): non-finite coordinate '
                                  f'or color ({len(bad_rows)} bad points among points {total}-'
                                  f'{total + len(chunk) - 1})')
        total += len(chunk)
        if len(chunk):
            yield chunk
    if total == 0:
        raise ScanFormatError(f'{path}: the scan holds no points')


def read_scan(path: str | os.PathLike, columns: str | Sequence[str] | None = None) -> np.ndarray:
    """Read a whole scan file into an ``(N, 6)`` float64 array of ``x y z r g b``.

    The same readers and errors as :func:`read_scan_chunks`; the chunks are joined.
    """
    chunks = list(read_scan_chunks(path, CHUNK_POINTS, columns))
    return chunks[0] if len(chunks) == 1 else np.concatenate(chunks)


# --------------------------------------------------------------------------- bounded loading


@dataclass
class LoadedScan:
    """A scan streamed into a local frame: ``scan coordinates = points[:, :3] + origin``."""

    points: np.ndarray  # (N, 6) float64 x y z r g b, local frame (origin subtracted)
    origin: np.ndarray  # (3,) float64, the local frame's origin in the scan's coordinates
    source: str  # the scan file
    report: list[str] = field(default_factory=list)  # one-line notes, in the order made
    points_read: int = 0  # points in the file, before the voxel filter


def load_scan(path: str | os.PathLike,
              voxel: float | None = None,
              columns: str | Sequence[str] | None = None,
              chunk_points: int = CHUNK_POINTS) -> LoadedScan:
    """Stream a scan into a local float64 frame, keeping one point per ``voxel`` (metres).

    The origin is the median of the first chunk's first 1,000 points, floored to whole metres
    and kept in float64, so the local coordinates are small and the scan's own exact. With a
    voxel, memory is bounded by the kept voxels (64 bytes each) plus one chunk, whatever the
    file's size; without, every point is kept. Raises ``ScanFormatError`` as
    :func:`read_scan_chunks`, and when the scan's extent says its units are not metres.
    """
    if voxel is not None and not voxel > 0:
        raise ValueError(f'voxel must be positive, got {voxel}')
    notes: list[str] = []
    kept: list[np.ndarray] = []
    origin = None
    voxel_filter = None
    total = 0
    for chunk in read_scan_chunks(path, chunk_points, columns, notes):
        if origin is None:
            origin = np.floor(np.median(chunk[:1000, :3], axis=0))
            voxel_filter = VoxelFilter(voxel, origin) if voxel else None
        total += len(chunk)
        if voxel_filter is not None:
            chunk = chunk[voxel_filter.new_points(chunk[:, :3])]
        local = chunk.copy() if chunk.base is not None else chunk
        local[:, :3] -= origin
        kept.append(local)
    points = np.empty((sum(len(part) for part in kept), 6))
    start = 0
    while kept:  # join the kept chunks, freeing each once copied: no second full copy
        part = kept.pop(0)
        points[start:start + len(part)] = part
        start += len(part)
    check_units(points, path)
    report = notes + [
        f'read {total:,} points from {path}' +
        (f', kept {len(points):,} (one per {voxel * 100:g} cm voxel)' if voxel else '') +
        f'; local origin {origin[0]:.0f}, {origin[1]:.0f}, {origin[2]:.0f}'
    ]
    return LoadedScan(
        points=points, origin=origin, source=str(path), report=report, points_read=total)


def check_units(points: np.ndarray, path: str | os.PathLike) -> None:
    """Raise ``ScanFormatError`` when the scan's robust extent (0.5th to 99.5th percentile, so
    stray points do not count) is implausible in metres: taller than ``MAX_HEIGHT`` or wider
    than ``MAX_WIDTH``."""
    sample = points[::max(1, len(points) // 200_000), :3]
    low, high = np.percentile(sample, [0.5, 99.5], axis=0)
    extent = high - low
    if extent[2] > MAX_HEIGHT or max(extent[:2]) > MAX_WIDTH:
        raise ScanFormatError(
            f'{path}: the scan is {extent[2]:,.0f} m tall and {extent[0]:,.0f} x '
            f'{extent[1]:,.0f} m wide: the units look wrong (millimetres or centimetres?); '
            f'synthdet expects metres')


def write_scan(path: str | os.PathLike, points: np.ndarray) -> None:
    """Write an ``(N, 6)`` (or ``(N, 3)``) array in the format of the path's suffix.

    Colors are rounded to integers 0-255; ``.txt`` and ``.xyz`` keep 6 decimals, ``.las``/
    ``.laz`` millimetres, ``.ply`` and ``.pcd`` float64, ``.bin`` float32 and ``.e57`` float32
    around a float64 pose. Non-finite points raise ``ValueError``. The file is written next
    to its destination and renamed into place, so readers never see a partial file.
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
    with replaced_paths([path]) as (temporary, ):
        writer(temporary, points)
