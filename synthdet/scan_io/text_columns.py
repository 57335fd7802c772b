"""Text scans of columns (``.xyz``, ``.pts``, ``.csv``): one point a line.

The delimiter (comma, semicolon or blanks) and the header lines (a PTS point count, a CSV title
line) are detected; the columns come from ``columns`` (``x,y,z,r,g,b``, ``x,y,z,i``, ``_`` skips
one) or from the number of values per line (``DEFAULT_COLUMNS``). Written as ``x y z r g b``.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np

from synthdet.scan_io.common import (NON_FINITE, NUMBER, Scale, ScanFormatError, bad_line,
                                     colors_0_255, grey, no_color_note, one_line, read_line,
                                     split_tokens, text_blocks, token_problem)

COLUMN_NAMES = ('x', 'y', 'z', 'r', 'g', 'b', 'i')


def parse_columns(text: str | Sequence[str]) -> tuple[str, ...]:
    """Column names of a text scan from ``'x,y,z,r,g,b'`` (``_`` skips a column).

    Names are ``x y z`` (needed), ``r g b`` (all three or none) and ``i`` (intensity).
    """
    names = tuple(name.strip().lower()
                  for name in (text.split(',') if isinstance(text, str) else text))
    unknown = [name for name in names if name not in COLUMN_NAMES + ('_', )]
    if unknown:
        raise ValueError(f'unknown column {unknown[0]!r} in {",".join(names)!r}: expected '
                         f'x, y, z, r, g, b, i or _ (skip)')
    for name in COLUMN_NAMES:
        if names.count(name) > 1:
            raise ValueError(f'column {name!r} appears twice in {",".join(names)!r}')
    if not {'x', 'y', 'z'} <= set(names):
        raise ValueError(f'columns {",".join(names)!r} need x, y and z')
    if 0 < len({'r', 'g', 'b'} & set(names)) < 3:
        raise ValueError(f'columns {",".join(names)!r} need all of r, g, b or none')
    return names


DEFAULT_COLUMNS = {
    3: ('x', 'y', 'z'),
    4: ('x', 'y', 'z', 'i'),
    6: ('x', 'y', 'z', 'r', 'g', 'b'),
    7: ('x', 'y', 'z', 'i', 'r', 'g', 'b'),  # the PTS layout
}


def _text_layout(path: Path, columns: tuple[str, ...] | None) -> tuple[str, int, int]:
    """The delimiter, the number of header lines and the number of values per line.

    The first line whose tokens are all numbers, with as many as the next numeric line,
    starts the data: a PTS point count or a CSV title line before it is a header.
    """
    with open(path, 'rb') as stream:
        head = [read_line(stream, path, number) for number in range(1, 65)]
    lines = [line for line in head if line.strip()]
    if not lines:
        raise ScanFormatError(f'{path}: the scan holds no points')
    sample = b''.join(lines[-8:])
    delimiter = ',' if b',' in sample else ';' if b';' in sample else ' '
    for index, line in enumerate(head):
        tokens = split_tokens(line, delimiter)
        if len(tokens) >= 3 and all(NUMBER.match(t) or NON_FINITE.match(t) for t in tokens) \
                and not all(NUMBER.match(t) for t in tokens):
            raise ScanFormatError(f'{path}:{index + 1}: {token_problem(tokens)}')
        if not tokens or not all(NUMBER.match(token) for token in tokens):
            continue
        following = [split_tokens(other, delimiter) for other in head[index + 1:] if other.strip()]
        if len(tokens) >= 3 and (not following or len(following[0]) == len(tokens)):
            count = len(tokens)
            if columns is not None and len(columns) != count:
                raise ScanFormatError(f'{path}:{index + 1}: {count} values per line but the '
                                      f'columns {",".join(columns)!r} name {len(columns)}')
            if columns is None and count not in DEFAULT_COLUMNS:
                raise ScanFormatError(f'{path}:{index + 1}: {count} values per line; say what '
                                      f'they are with columns such as x,y,z,i,r,g,b')
            return delimiter, index, count
    raise ScanFormatError(f'{path}: no line of 3 or more numbers in its first 64 lines')


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of a text scan whose columns are ``columns`` or, if None, those of
    ``DEFAULT_COLUMNS`` for its number of values per line."""
    delimiter, header_lines, count = _text_layout(path, columns)
    names = columns or DEFAULT_COLUMNS[count]
    yield from _parse_text_blocks(path, text_blocks(path, header_lines, chunk_points), names,
                                  delimiter, chunk_points, notes)


def _parse_text_blocks(path: Path, blocks: Iterable[tuple[int, bytes]], names: Sequence[str],
                       delimiter: str, chunk_points: int,
                       notes: list[str]) -> Iterator[np.ndarray]:
    """Parse blocks of text lines holding the columns ``names`` into ``(n, 6)`` chunks."""
    index = {name: i for i, name in enumerate(names) if name != '_'}
    has_color, has_intensity = 'r' in index, 'i' in index
    if not has_color:
        notes.append(no_color_note(path, has_intensity))
    color_scale, intensity_scale = Scale(), Scale()
    for first_line, block in blocks:
        try:
            values = np.loadtxt(
                io.BytesIO(block),
                delimiter=None if delimiter == ' ' else delimiter,
                ndmin=2,
                dtype=np.float64)
        except ValueError as error:
            offset, problem = bad_line(block, len(names), delimiter)
            raise ScanFormatError(f'{path}:{first_line + offset}: {problem or one_line(error)}'
                                  ) from None
        if values.shape[1] != len(names):
            raise ScanFormatError(f'{path}:{first_line}: expected {len(names)} values per line '
                                  f'({",".join(names)}), found {values.shape[1]}')
        if not np.isfinite(values).all():
            offset, problem = bad_line(block, len(names), delimiter)
            raise ScanFormatError(f'{path}:{first_line + offset}: {problem}')
        for start in range(0, len(values), chunk_points):
            part = values[start:start + chunk_points]
            chunk = np.zeros((len(part), 6))
            chunk[:, :3] = part[:, [index['x'], index['y'], index['z']]]
            if has_color:
                chunk[:, 3:] = color_scale(part[:, [index['r'], index['g'], index['b']]])
            elif has_intensity:
                chunk[:, 3:] = grey(intensity_scale(part[:, index['i']]))
            yield chunk


def write(path: Path, points: np.ndarray) -> None:
    """``x y z r g b`` lines, millimetre-exact at any coordinate (6 decimals, float64)."""
    with open(path, 'w') as stream:
        np.savetxt(
            stream,
            np.column_stack([points[:, :3], colors_0_255(points)]),
            fmt=['%.6f'] * 3 + ['%d'] * 3)
