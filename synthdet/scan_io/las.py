"""ASPRS LAS and LAZ scans (``.las``, ``.laz``) by ``laspy`` (and ``lazrs``), imported when a
file is read or written."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np

from synthdet.scan_io.common import (Scale, ScanFormatError, colors_0_255, grey, no_color_note,
                                     one_line)


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of the points, scale and offset applied in float64; intensity as grey
    when the point format has no colors."""
    import laspy
    try:
        reader = laspy.open(path)
    except Exception as error:  # laspy raises several types for broken headers
        raise ScanFormatError(f'{path}: not a readable LAS/LAZ file ({one_line(error)})') from None
    with reader:
        dimensions = set(reader.header.point_format.dimension_names)
        has_color = {'red', 'green', 'blue'} <= dimensions
        if not has_color:
            notes.append(no_color_note(path, True))
        color_scale, intensity_scale = Scale(), Scale()
        total = 0
        try:
            for points in reader.chunk_iterator(chunk_points):
                total += len(points)
                chunk = np.empty((len(points), 6))
                chunk[:, 0] = points.x  # scale and offset applied in float64
                chunk[:, 1] = points.y
                chunk[:, 2] = points.z
                if has_color:  # 16-bit by the standard; some writers store 8-bit values
                    chunk[:, 3:] = color_scale(
                        np.column_stack([points.red, points.green, points.blue]))
                else:
                    chunk[:, 3:] = grey(intensity_scale(points.intensity))
                yield chunk
        except (OSError, ValueError, RuntimeError) as error:  # a record cut short, too
            raise ScanFormatError(f'{path}: cannot decode the {reader.header.point_count:,} '
                                  f'points its header counts ({one_line(error)})') from None
        if total != reader.header.point_count:
            raise ScanFormatError(f'{path}: the header counts {reader.header.point_count:,} '
                                  f'points but the data holds {total:,}')


def write(path: Path, points: np.ndarray) -> None:
    """One LAS or LAZ file (see :func:`write_las_chunks`)."""
    write_las_chunks(path, [points])


def write_las_chunks(path: str | os.PathLike,
                     chunks: Iterable[np.ndarray],
                     offset: Sequence[float] | None = None) -> int:
    """Write ``(n, 6)`` chunks as one LAS (or, for ``.laz``, LAZ) file; returns the count.

    Coordinates are stored to the millimetre (scale 0.001) around ``offset`` (default: the
    first chunk's minimum floored to metres), colors as 16-bit (value x 257). Memory stays
    one chunk, so large test scans can be written.
    """
    import laspy
    path = Path(path)
    writer, total = None, 0
    try:
        for chunk in chunks:
            chunk = np.asarray(chunk, dtype=np.float64)
            if writer is None:
                header = laspy.LasHeader(point_format=2, version='1.2')
                header.scales = np.array([0.001, 0.001, 0.001])
                header.offsets = np.floor(chunk[:, :3].min(axis=0)) if offset is None else \
                    np.asarray(offset, dtype=np.float64)
                writer = laspy.open(
                    path, mode='w', header=header, do_compress=path.suffix.lower() == '.laz')
            record = laspy.ScaleAwarePointRecord.zeros(len(chunk), header=writer.header)
            record.x, record.y, record.z = chunk[:, 0], chunk[:, 1], chunk[:, 2]
            colors = colors_0_255(chunk).astype(np.uint16) * 257
            record.red, record.green, record.blue = colors[:, 0], colors[:, 1], colors[:, 2]
            writer.write_points(record)
            total += len(chunk)
    finally:
        if writer is not None:
            writer.close()
    if writer is None:
        raise ValueError(f'{path}: no points to write')
    return total
