"""S3DIS ``.txt`` scans: ``x y z r g b`` or ``x y z`` lines, by :mod:`synthdet.point_text`."""
from __future__ import annotations

import itertools
from pathlib import Path
from typing import Iterator

import numpy as np

from synthdet.point_text import PointFileError, format_lines, read_point_file
from synthdet.scan_io import text_columns
from synthdet.scan_io.common import (ScanFormatError, colors_0_255, no_color_note, read_line,
                                     text_blocks)


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of an S3DIS ``.txt`` (``x y z`` points get black), or of any text
    scan whose ``columns`` are given."""
    if columns is not None:
        yield from text_columns.read_chunks(path, chunk_points, columns, notes)
        return
    count = _s3dis_columns(path)
    if count == 3:
        notes.append(no_color_note(path, False))
    for first_line, block in text_blocks(path, 0, chunk_points):
        if not block.strip():
            continue
        try:
            values, _ = read_point_file(path, data=block, columns=count)
        except PointFileError as error:  # its line counts from the block's first
            raise ScanFormatError(
                f'{path}:{first_line + error.line - 1}: {error.reason}') from None
        for start in range(0, len(values), chunk_points):
            part = values[start:start + chunk_points]
            yield part if count == 6 else np.hstack([part, np.zeros((len(part), 3))])


def _s3dis_columns(path: Path) -> int:
    """The number of values on the first non-blank line: 6 (x y z r g b) or 3 (x y z)."""
    with open(path, 'rb') as stream:
        for number in itertools.count(1):
            line = read_line(stream, path, number)
            if not line:
                break
            count = len(line.split())
            if count in (3, 6):
                return count
            if count:
                raise ScanFormatError(f'{path}:{number}: expected 6 numbers per line '
                                      f'(x y z r g b) or 3 (x y z), got {count}')
    raise ScanFormatError(f'{path}: the scan holds no points')


def write(path: Path, points: np.ndarray) -> None:
    """``x y z r g b`` lines as S3DIS writes them (6 decimals)."""
    text, _ = format_lines(points[:, :3], colors_0_255(points), decimals=6)
    path.write_bytes(text)
