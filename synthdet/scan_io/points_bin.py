"""``.bin`` scans: float32 rows of ``x y z r g b`` (the converted data's ``points/*.bin``)."""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from synthdet.scan_io.common import ScanFormatError


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of the memory-mapped rows; a note when float32 loses millimetres."""
    size = path.stat().st_size
    if size % (6 * 4):
        raise ScanFormatError(f'{path}: {size} bytes is not a whole number of float32 rows of '
                              f'6 values (x y z r g b)')
    if size == 0:
        return
    rows = np.memmap(path, dtype=np.float32, mode='r').reshape(-1, 6)
    for start in range(0, len(rows), chunk_points):
        chunk = rows[start:start + chunk_points].astype(np.float64)
        if start == 0:
            largest = float(np.abs(chunk[:, :3]).max())
            step = float(np.spacing(np.float32(largest)))
            if step > 0.001:
                notes.append(f'{path}: warning: float32 coordinates as large as {largest:,.0f} '
                             f'are only exact to {step * 1000:,.0f} mm; write the scan as LAS, '
                             f'PLY or PCD to keep georeferenced coordinates')
        yield chunk


def write(path: Path, points: np.ndarray) -> None:
    """The points as float32 rows."""
    points.astype(np.float32).tofile(path)
