"""Read and write scans: the project's only scan reader.

Every reader yields ``(n, 6)`` float64 chunks ``x y z r g b`` (metres, colours 0-255) in the
file's own coordinates, so georeferenced scans stay exact: ``read_scan`` joins the chunks,
``read_scan_chunks`` streams them and ``load_scan`` streams them into a local frame with an
optional voxel filter, in memory bounded by the kept voxels rather than the file. The formats
are tables keyed by file suffix, so a new format is one reader (and writer) and one entry:

- ``.txt``: ``x y z r g b`` or ``x y z`` lines (S3DIS), by :mod:`synthdet.point_text`;
- ``.bin``: float32 rows of ``x y z r g b`` (the converted data's ``points/*.bin``);
- ``.ply``: a ``vertex`` element with ``x y z`` and optional colours, by :mod:`synthdet.ply`;
- ``.las``/``.laz``: ASPRS LAS by ``laspy`` (+ ``lazrs``), scale and offset in float64;
- ``.e57``: every scan of the file by ``pye57``, each moved by its pose;
- ``.pcd``: Point Cloud Library files, ``ascii``, ``binary`` or ``binary_compressed`` (LZF);
- ``.xyz``/``.pts``/``.csv``: text columns; delimiter and header lines are detected, the
  columns come from ``columns`` (``x,y,z,r,g,b``, ``x,y,z,i``, ``_`` skips one) or the count.

Scans without colours get their intensity as grey, or zeros without intensity; the notes say
which. Errors for bad files are ``ScanFormatError`` naming the file (and the line for text),
among them a header counting points the data does not hold and a text line longer than
``MAX_LINE_BYTES``.
"""
from __future__ import annotations

import io
import itertools
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

import numba
import numpy as np

from synthdet.ply import read_ply_vertices, write_ply
from synthdet.point_text import PointFileError, format_lines, read_point_file
from synthdet.voxels import VoxelFilter

CHUNK_POINTS = 1_000_000  # default points per chunk: about 50 MB of float64 rows
MAX_HEIGHT = 200.0  # metres; a taller scan (robust extent) is taken to be in other units
MAX_WIDTH = 20_000.0  # metres
COLUMN_NAMES = ('x', 'y', 'z', 'r', 'g', 'b', 'i')
MAX_LINE_BYTES = 1 << 20  # longest text line read (1 MiB); a longer one is refused
TEXT_BYTES_PER_POINT = 48  # text blocks hold about this many bytes per chunk point


class ScanFormatError(ValueError):
    """A scan file that is empty, malformed, holds non-finite values or looks mis-scaled."""


# --------------------------------------------------------------------------- colours


def _grey(intensity: np.ndarray) -> np.ndarray:
    """``(n, 3)`` grey colours of intensities already scaled to 0-255."""
    grey = np.clip(intensity, 0.0, 255.0)
    return np.repeat(grey[:, None], 3, axis=1)


class _Scale:
    """Maps raw colour or intensity values to 0-255 with a range fixed by the first chunk.

    The range is the header's when known, else the smallest usual one holding the first
    chunk's values: [0, 1] (float), 0-255 (8 bit), 0-4095 (12 bit), 0-65535 (16 bit), or
    -2048-2047 (PTS intensity); every chunk then uses that range, so chunks agree.
    """

    def __init__(self, low: float | None = None, high: float | None = None):
        self.low, self.high = low, high

    def __call__(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        if self.high is None and len(values):
            low, high = float(values.min()), float(values.max())
            if low < 0:
                self.low, self.high = -2048.0, 2047.0
            else:
                self.low = 0.0
                self.high = next(
                    top for top in (1.0, 255.0, 4095.0, 65535.0, math.inf) if high <= top)
                if math.isinf(self.high):
                    self.high = high
        if self.high is None or self.high <= self.low:
            return np.zeros_like(values)
        return np.clip((values - self.low) * (255.0 / (self.high - self.low)), 0.0, 255.0)


def _no_colour_note(path: Path, has_intensity: bool) -> str:
    if has_intensity:
        return f'{path}: no colours: the model gets the intensity as grey instead'
    return f'{path}: no colours and no intensity: the model gets zeros (black) instead'


# --------------------------------------------------------------------------- text columns


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
_SPLIT = {',': b',', ';': b';', ' ': None}
_NUMBER = re.compile(rb'^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$')


def _split(line: bytes, delimiter: str) -> list[bytes]:
    return [
        token.strip() for token in line.split(_SPLIT[delimiter])
        if token.strip() or delimiter != ' '
    ]


def _text_layout(path: Path, columns: tuple[str, ...] | None) -> tuple[str, int, int]:
    """The delimiter, the number of header lines and the number of values per line.

    The first line whose tokens are all numbers, with as many as the next numeric line,
    starts the data: a PTS point count or a CSV title line before it is a header.
    """
    with open(path, 'rb') as stream:
        head = [_read_line(stream, path, number) for number in range(1, 65)]
    lines = [line for line in head if line.strip()]
    if not lines:
        raise ScanFormatError(f'{path}: the scan holds no points')
    sample = b''.join(lines[-8:])
    delimiter = ',' if b',' in sample else ';' if b';' in sample else ' '
    for index, line in enumerate(head):
        tokens = _split(line, delimiter)
        if not tokens or not all(_NUMBER.match(token) for token in tokens):
            continue
        following = [_split(other, delimiter) for other in head[index + 1:] if other.strip()]
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


def _read_text_columns(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                       notes: list[str]) -> Iterator[np.ndarray]:
    delimiter, header_lines, count = _text_layout(path, columns)
    names = columns or DEFAULT_COLUMNS[count]
    yield from _parse_text_blocks(path, _text_blocks(path, header_lines, chunk_points), names,
                                  delimiter, chunk_points, notes)


def _long_line(path: Path, number: int) -> ScanFormatError:
    return ScanFormatError(f'{path}:{number}: line longer than {MAX_LINE_BYTES:,} bytes; a '
                           f'text scan holds one point a line')


def _read_line(stream: io.BufferedReader, path: Path, number: int) -> bytes:
    """The next line (line ``number`` of the file), read no further than ``MAX_LINE_BYTES``."""
    line = stream.readline(MAX_LINE_BYTES + 1)
    if len(line) > MAX_LINE_BYTES and not line.endswith(b'\n'):
        raise _long_line(path, number)
    return line


@numba.njit(cache=True, nogil=True)
def _first_long_line(text: np.ndarray, limit: int) -> int:
    """Index of the first line of ``text`` (uint8) longer than ``limit`` bytes, or -1."""
    start = 0
    line = 0
    for i in range(text.shape[0]):
        if text[i] == 10:
            if i - start > limit:
                return line
            start = i + 1
            line += 1
    return line if text.shape[0] - start > limit else -1


def _text_blocks(path: Path, skip: int, chunk_points: int) -> Iterator[tuple[int, bytes]]:
    """Blocks of whole lines, about ``TEXT_BYTES_PER_POINT * chunk_points`` bytes each, after
    ``skip`` header lines, with the 1-based number of each block's first line.

    Memory stays one block plus one line: a line longer than ``MAX_LINE_BYTES`` raises
    ``ScanFormatError`` naming the file and the line, wherever it is.
    """
    block_bytes = TEXT_BYTES_PER_POINT * chunk_points
    with open(path, 'rb') as stream:
        for number in range(1, skip + 1):
            _read_line(stream, path, number)
        number, rest = skip + 1, b''
        while True:
            data = stream.read(block_bytes)
            if data and b'\n' not in data:  # the line goes on: keep it, up to the limit
                rest += data
                if len(rest) > MAX_LINE_BYTES:
                    raise _long_line(path, number)
                continue
            cut = data.rfind(b'\n') + 1 if data else len(rest)
            block, rest = rest + data[:cut], data[cut:]
            if len(block) > MAX_LINE_BYTES:
                long = _first_long_line(np.frombuffer(block, dtype=np.uint8), MAX_LINE_BYTES)
                if long >= 0:
                    raise _long_line(path, number + long)
            if block:
                yield number, block
                number += block.count(b'\n')
            if not data:
                return


def _parse_text_blocks(path: Path, blocks: Iterable[tuple[int, bytes]], names: Sequence[str],
                       delimiter: str, chunk_points: int,
                       notes: list[str]) -> Iterator[np.ndarray]:
    """Parse blocks of text lines holding the columns ``names`` into ``(n, 6)`` chunks."""
    index = {name: i for i, name in enumerate(names) if name != '_'}
    has_colour, has_intensity = 'r' in index, 'i' in index
    if not has_colour:
        notes.append(_no_colour_note(path, has_intensity))
    colour_scale, intensity_scale = _Scale(), _Scale()
    for first_line, block in blocks:
        try:
            values = np.loadtxt(
                io.BytesIO(block),
                delimiter=None if delimiter == ' ' else delimiter,
                ndmin=2,
                dtype=np.float64)
        except ValueError as error:
            raise ScanFormatError(f'{path}:{_bad_line(block, len(names), delimiter) + first_line}'
                                  f': {_short(error)}') from None
        if values.shape[1] != len(names):
            raise ScanFormatError(f'{path}:{first_line}: expected {len(names)} values per line '
                                  f'({",".join(names)}), found {values.shape[1]}')
        for start in range(0, len(values), chunk_points):
            part = values[start:start + chunk_points]
            chunk = np.zeros((len(part), 6))
            chunk[:, :3] = part[:, [index['x'], index['y'], index['z']]]
            if has_colour:
                chunk[:, 3:] = colour_scale(part[:, [index['r'], index['g'], index['b']]])
            elif has_intensity:
                chunk[:, 3:] = _grey(intensity_scale(part[:, index['i']]))
            yield chunk


def _bad_line(block: bytes, count: int, delimiter: str) -> int:
    """Offset in the block of its first line that is not ``count`` numbers (0 if none)."""
    for offset, line in enumerate(block.split(b'\n')):
        tokens = _split(line, delimiter)
        if tokens and (len(tokens) != count or not all(_NUMBER.match(t) for t in tokens)):
            return offset
    return 0


def _short(error: Exception) -> str:
    return ' '.join(str(error).split())


# --------------------------------------------------------------------------- readers


def _read_txt(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
              notes: list[str]) -> Iterator[np.ndarray]:
    if columns is not None:
        yield from _read_text_columns(path, chunk_points, columns, notes)
        return
    count = _s3dis_columns(path)
    if count == 3:
        notes.append(_no_colour_note(path, False))
    for first_line, block in _text_blocks(path, 0, chunk_points):
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
            line = _read_line(stream, path, number)
            if not line:
                break
            count = len(line.split())
            if count in (3, 6):
                return count
            if count:
                raise ScanFormatError(f'{path}:{number}: expected 6 numbers per line '
                                      f'(x y z r g b) or 3 (x y z), got {count}')
    raise ScanFormatError(f'{path}: the scan holds no points')


def _read_bin(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
              notes: list[str]) -> Iterator[np.ndarray]:
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


PLY_COLOUR_NAMES = (
    ('red', 'green', 'blue'),
    ('r', 'g', 'b'),
    ('diffuse_red', 'diffuse_green', 'diffuse_blue'),
)
PLY_INTENSITY_NAMES = ('intensity', 'scalar_intensity', 'scalar_Intensity', 'reflectance')


def _read_ply(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
              notes: list[str]) -> Iterator[np.ndarray]:
    try:
        vertex = read_ply_vertices(path)  # memory-mapped for binary files
    except ValueError as error:
        raise ScanFormatError(str(error)) from None
    yield from _structured_chunks(path, vertex, PLY_COLOUR_NAMES, PLY_INTENSITY_NAMES,
                                  chunk_points, notes, 'PLY vertices')


def _structured_chunks(path: Path, table: np.ndarray, colour_names: Sequence[Sequence[str]],
                       intensity_names: Sequence[str], chunk_points: int, notes: list[str],
                       what: str) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of a structured array with ``x y z`` and optional colour fields."""
    names = table.dtype.names or ()
    if not {'x', 'y', 'z'} <= set(names):
        raise ScanFormatError(f'{path}: {what} need x, y and z properties, got {names}')
    colour = next((list(group) for group in colour_names if set(group) <= set(names)), None)
    intensity = next((name for name in intensity_names if name in names), None)
    if colour is None:
        notes.append(_no_colour_note(path, intensity is not None))
    scale = _Scale(0.0, 255.0)
    if colour is not None and table.dtype[colour[0]].kind == 'f':
        scale = _Scale()  # float colours: [0, 1] or 0-255, from the first chunk
    intensity_scale = _Scale()
    for start in range(0, len(table), chunk_points):
        part = table[start:start + chunk_points]
        chunk = np.zeros((len(part), 6))
        for i, name in enumerate('xyz'):
            chunk[:, i] = part[name]
        if colour is not None:
            chunk[:, 3:] = scale(np.column_stack([part[name] for name in colour]))
        elif intensity is not None:
            chunk[:, 3:] = _grey(intensity_scale(part[intensity]))
        yield chunk


def _read_las(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
              notes: list[str]) -> Iterator[np.ndarray]:
    import laspy
    try:
        reader = laspy.open(path)
    except Exception as error:  # laspy raises several types for broken headers
        raise ScanFormatError(f'{path}: not a readable LAS/LAZ file ({_short(error)})') from None
    with reader:
        dimensions = set(reader.header.point_format.dimension_names)
        has_colour = {'red', 'green', 'blue'} <= dimensions
        if not has_colour:
            notes.append(_no_colour_note(path, True))
        colour_scale, intensity_scale = _Scale(), _Scale()
        total = 0
        try:
            for points in reader.chunk_iterator(chunk_points):
                total += len(points)
                chunk = np.empty((len(points), 6))
                chunk[:, 0] = points.x  # scale and offset applied in float64
                chunk[:, 1] = points.y
                chunk[:, 2] = points.z
                if has_colour:  # 16-bit by the standard; some writers store 8-bit values
                    chunk[:, 3:] = colour_scale(
                        np.column_stack([points.red, points.green, points.blue]))
                else:
                    chunk[:, 3:] = _grey(intensity_scale(points.intensity))
                yield chunk
        except (OSError, ValueError, RuntimeError) as error:  # a record cut short, too
            raise ScanFormatError(f'{path}: cannot decode the {reader.header.point_count:,} '
                                  f'points its header counts ({_short(error)})') from None
        if total != reader.header.point_count:
            raise ScanFormatError(f'{path}: the header counts {reader.header.point_count:,} '
                                  f'points but the data holds {total:,}')


def _read_e57(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
              notes: list[str]) -> Iterator[np.ndarray]:
    import pye57
    try:
        e57 = pye57.E57(os.fspath(path))
    except Exception as error:  # libE57 raises its own exception type
        raise ScanFormatError(f'{path}: not a readable E57 file ({_short(error)})') from None
    try:
        scan_count = e57.scan_count
        missing = 0
        for index in range(scan_count):
            fields = set(e57.get_header(index).point_fields)
            has_colour = {'colorRed', 'colorGreen', 'colorBlue'} <= fields
            missing += not has_colour
            yield from _e57_scan_chunks(path, e57, index, fields, has_colour, chunk_points)
        if missing:
            note = _no_colour_note(path, True)
            notes.append(note if missing ==
                         scan_count else f'{note} ({missing} of {scan_count} scans)')
    finally:
        e57.close()


def _e57_scan_chunks(path: Path, e57, index: int, fields: set[str], has_colour: bool,
                     chunk_points: int) -> Iterator[np.ndarray]:
    """The points of the E57 file's scan ``index``, moved by its pose into the file's frame."""
    header = e57.get_header(index)
    cartesian = ['cartesianX', 'cartesianY', 'cartesianZ']
    spherical = ['sphericalRange', 'sphericalAzimuth', 'sphericalElevation']
    coordinates = cartesian if set(cartesian) <= fields else spherical
    if not set(coordinates) <= fields:
        raise ScanFormatError(f'{path}: scan {index} has neither cartesian '
                              f'nor spherical coordinates')
    invalid = 'cartesianInvalidState' if coordinates is cartesian else 'sphericalInvalidState'
    colour_names = ['colorRed', 'colorGreen', 'colorBlue']
    wanted = coordinates + (
        colour_names if has_colour else ['intensity'] if 'intensity' in fields else [])
    wanted += [invalid] if invalid in fields else []
    capacity = max(1, min(chunk_points, header.point_count))
    buffers_by_name, buffers = e57.make_buffers(wanted, capacity)
    rotation, translation = np.eye(3), np.zeros(3)
    if header.has_pose():
        rotation = _quaternion_matrix(np.asarray(header.rotation, dtype=np.float64))
        translation = np.asarray(header.translation, dtype=np.float64)
    scale = _Scale(*_e57_limits(header, 'colorRed' if has_colour else 'intensity'))
    reader = header.points.reader(buffers)
    try:
        while True:
            count = reader.read()
            if count == 0:
                break
            values = {name: buffers_by_name[name][:count] for name in wanted}
            xyz = np.column_stack([values[name].astype(np.float64) for name in coordinates])
            if coordinates is spherical:
                xyz = _spherical_to_cartesian(xyz)
            chunk = np.zeros((count, 6))
            chunk[:, :3] = xyz @ rotation.T + translation
            if has_colour:
                chunk[:, 3:] = scale(np.column_stack([values[name] for name in colour_names]))
            elif 'intensity' in values:
                chunk[:, 3:] = _grey(scale(values['intensity']))
            if invalid in values:
                chunk = chunk[values[invalid] == 0]
            yield chunk
    finally:
        reader.close()


def _e57_limits(header, name: str) -> tuple[float | None, float | None]:
    """The header's colour or intensity limits (``colorRedMinimum``...), if it has them."""
    node = {'colorRed': 'colorLimits', 'intensity': 'intensityLimits'}[name]
    try:
        limits = header[node]
        return float(limits[f'{name}Minimum'].value()), float(limits[f'{name}Maximum'].value())
    except Exception:  # libE57 raises its own exception type for absent nodes
        return None, None


def _quaternion_matrix(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = quaternion / np.linalg.norm(quaternion)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _matrix_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (w >= 0)."""
    w = math.sqrt(max(0.0, 1.0 + np.trace(rotation))) / 2
    if w > 1e-6:
        x = (rotation[2, 1] - rotation[1, 2]) / (4 * w)
        y = (rotation[0, 2] - rotation[2, 0]) / (4 * w)
        z = (rotation[1, 0] - rotation[0, 1]) / (4 * w)
        return np.array([w, x, y, z])
    axis_values, axis_vectors = np.linalg.eigh(rotation + rotation.T)  # 180 degree turn
    x, y, z = axis_vectors[:, int(np.argmax(axis_values))]
    return np.array([0.0, x, y, z])


def _spherical_to_cartesian(rae: np.ndarray) -> np.ndarray:
    """E57 spherical ``range, azimuth, elevation`` (metres, radians) to ``x y z``."""
    horizontal = rae[:, 0] * np.cos(rae[:, 2])
    return np.column_stack([
        horizontal * np.cos(rae[:, 1]), horizontal * np.sin(rae[:, 1]),
        rae[:, 0] * np.sin(rae[:, 2])
    ])


_PCD_TYPES = {
    ('F', 4): '<f4',
    ('F', 8): '<f8',
    ('U', 1): 'u1',
    ('U', 2): '<u2',
    ('U', 4): '<u4',
    ('I', 1): 'i1',
    ('I', 2): '<i2',
    ('I', 4): '<i4',
    ('U', 8): '<u8',
    ('I', 8): '<i8'
}


@dataclass
class _PcdHeader:
    fields: list[str]
    dtype: np.dtype
    points: int
    data: str
    offset: int  # bytes before the data
    lines: int  # header lines
    declared: bool  # the header gives the point count (POINTS, or WIDTH and HEIGHT)


def _pcd_header(path: Path) -> _PcdHeader:
    entries: dict[str, list[str]] = {}
    offset = lines = 0
    with open(path, 'rb') as stream:
        while lines < 50 and 'DATA' not in entries:
            raw = stream.readline(MAX_LINE_BYTES + 1)
            if not raw or len(raw) > MAX_LINE_BYTES:
                break
            offset += len(raw)
            lines += 1
            words = raw.decode('ascii', errors='replace').split()
            if words and not words[0].startswith('#'):
                entries[words[0].upper()] = words[1:]
    if not entries.get('DATA') or 'FIELDS' not in entries:
        raise ScanFormatError(f'{path}: not a PCD file (no FIELDS or DATA line in its header)')
    fields = entries['FIELDS']
    sizes = entries.get('SIZE', ['4'] * len(fields))
    types = entries.get('TYPE', ['F'] * len(fields))
    counts = entries.get('COUNT', ['1'] * len(fields))
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise ScanFormatError(f'{path}: PCD header FIELDS, SIZE, TYPE and COUNT differ in length')
    layout = []
    for name, size, kind, count in zip(fields, sizes, types, counts):
        code = _PCD_TYPES.get((kind.upper(), _pcd_number(path, 'SIZE', size)))
        if code is None:
            raise ScanFormatError(f'{path}: PCD field {name} has unknown type {kind}{size}')
        count = _pcd_number(path, 'COUNT', count)
        layout.append((name, code, (count, )) if count != 1 else (name, code))
    try:
        dtype = np.dtype(layout)
    except (TypeError, ValueError) as error:  # a field named twice, a count of zero
        raise ScanFormatError(f'{path}: PCD fields {fields}: {_short(error)}') from None
    width = _pcd_number(path, 'WIDTH', entries.get('WIDTH', ['0'])[0])
    height = _pcd_number(path, 'HEIGHT', entries.get('HEIGHT', ['1'])[0])
    points = _pcd_number(path, 'POINTS', entries.get('POINTS', [str(width * height)])[0])
    declared = 'POINTS' in entries or 'WIDTH' in entries
    return _PcdHeader(fields, dtype, points, entries['DATA'][0].lower(), offset, lines, declared)


def _pcd_number(path: Path, key: str, text: str) -> int:
    """A whole number >= 0 of the PCD header's ``key`` line."""
    if not text.isdigit() or len(text) > 18:
        raise ScanFormatError(f'{path}: PCD header {key} {text[:20]!r} is not a whole number')
    return int(text)


def _pcd_colours(packed: np.ndarray) -> np.ndarray:
    """``(n, 3)`` colours of PCD's packed ``rgb``/``rgba`` (float32 or uint32 bits)."""
    bits = np.ascontiguousarray(packed).view(np.uint32)
    return np.column_stack([(bits >> 16) & 255, (bits >> 8) & 255, bits & 255]).astype(float)


def _read_pcd(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
              notes: list[str]) -> Iterator[np.ndarray]:
    header = _pcd_header(path)
    colour = next((name for name in ('rgb', 'rgba') if name in header.fields), None)
    intensity = 'intensity' if 'intensity' in header.fields else None
    if not {'x', 'y', 'z'} <= set(header.fields):
        raise ScanFormatError(f'{path}: PCD fields need x, y and z, got {header.fields}')
    wanted = ['x', 'y', 'z'] + [name for name in (colour or intensity, ) if name]
    if header.data == 'binary':
        blocks = _pcd_binary_tables(path, header, chunk_points)
    elif header.data == 'binary_compressed':
        blocks = _pcd_compressed_tables(path, header, wanted, chunk_points)
    elif header.data == 'ascii':
        blocks = (_pcd_ascii_rows(path, first, block, header)
                  for first, block in _text_blocks(path, header.lines, chunk_points))
    else:
        raise ScanFormatError(f'{path}: PCD data {header.data!r} is not one of ascii, binary '
                              f'and binary_compressed')
    if colour is None:
        notes.append(_no_colour_note(path, intensity is not None))
    intensity_scale = _Scale()
    total = invalid = 0
    for block in blocks:
        total += len(block)
        for start in range(0, len(block), chunk_points):
            part = block[start:start + chunk_points]
            chunk = np.zeros((len(part), 6))
            for i, name in enumerate('xyz'):
                chunk[:, i] = part[name]
            if colour is not None:
                chunk[:, 3:] = _pcd_colours(part[colour])
            elif intensity is not None:
                chunk[:, 3:] = _grey(intensity_scale(part[intensity]))
            # An organised cloud (a depth camera's frame, HEIGHT > 1) keeps one record per
            # pixel and marks the pixels without a depth by NaN coordinates: they are no points.
            pixel_without_depth = np.isnan(chunk[:, :3]).all(axis=1)
            invalid += int(pixel_without_depth.sum())
            yield chunk[~pixel_without_depth]
    if header.data == 'ascii' and header.declared and total != header.points:
        raise ScanFormatError(f'{path}: the header counts {header.points:,} points but the data '
                              f'holds {total:,} lines of points')
    if invalid:
        notes.append(f'{path}: {invalid:,} of {total:,} records have no coordinates (NaN: pixels '
                     f'without a depth in an organised cloud), left out')


def _pcd_binary_tables(path: Path, header: _PcdHeader, chunk_points: int) -> Iterator[np.ndarray]:
    """The points of ``DATA binary`` (one record after the other), memory-mapped."""
    expected = header.offset + header.points * header.dtype.itemsize
    if path.stat().st_size < expected:
        raise ScanFormatError(f'{path}: {path.stat().st_size} bytes, the header promises '
                              f'{header.points:,} points ({expected:,} bytes)')
    if header.points == 0:
        return
    table = np.memmap(
        path, dtype=header.dtype, mode='r', offset=header.offset, shape=(header.points, ))
    for start in range(0, len(table), chunk_points):
        yield table[start:start + chunk_points]


def _pcd_ascii_rows(path: Path, first_line: int, block: bytes, header: _PcdHeader) -> np.ndarray:
    """Parse a block of ASCII PCD lines into the header's structured dtype (fields of one value;
    fields of several values are left zero)."""
    widths = [int(np.prod(header.dtype[name].shape)) for name in header.fields]
    starts = np.concatenate([[0], np.cumsum(widths)[:-1]]).tolist()
    single = [name for name, width in zip(header.fields, widths) if header.dtype[name].shape == ()]
    numbers = np.dtype([(name, '<f8' if header.dtype[name].kind == 'f' else '<i8')
                        for name in single])
    try:
        rows = np.loadtxt(
            io.BytesIO(block),
            dtype=numbers,
            ndmin=1,
            usecols=[starts[header.fields.index(name)] for name in single])
    except ValueError as error:
        raise ScanFormatError(f'{path}:{first_line + _bad_line(block, sum(widths), " ")}'
                              f': {_short(error)}') from None
    table = np.zeros(len(rows), header.dtype)
    for name in single:
        table[name] = rows[name]
    return table


# ------------------------------------------------------------------ PCD binary_compressed (LZF)
#
# ``DATA binary_compressed`` (PCL's and Open3D's compressed PCD) is two little-endian uint32,
# the compressed and the uncompressed size, then one LZF stream of the points stored field by
# field: every point's x, then every point's y, and so on. An LZF stream is a sequence of
# instructions: a control byte below 32 copies the next control + 1 bytes; any other is a back
# reference that repeats 3 to 264 bytes of the output from at most LZF_WINDOW bytes back. So a
# decoder needs only the last LZF_WINDOW bytes of its output: the points are read a chunk at a
# time with one such decoder per field, each started from the state a first pass over the whole
# stream (which also checks it) recorded at the start of its field.

LZF_WINDOW = 8192  # an LZF back reference reaches at most this many bytes back
LZF_LONGEST = 264  # bytes one LZF instruction writes at most
LZF_BLOCK = 1 << 22  # bytes the first pass decodes per call
_LZF_PROBLEMS = {
    1: 'the data ends inside an instruction',
    2: 'a back reference before the start of the data',
}


@numba.njit(cache=True, nogil=True)
def _lzf_decode(source: np.ndarray, position: int, out: np.ndarray, written: int, stop: int,
                overshoot: bool) -> tuple[int, int, int]:
    """Decode LZF instructions from ``source[position:]`` into ``out[written:]`` while
    ``written < stop`` (``out[:written]`` ends with the output so far, at least its last
    ``LZF_WINDOW`` bytes). Without ``overshoot`` it stops before an instruction that would
    write past ``stop``; ``out`` needs ``LZF_LONGEST`` bytes beyond ``stop``.

    Returns the new position and written count and 0, or a key of ``_LZF_PROBLEMS``.
    """
    end = source.shape[0]
    while position < end and written < stop:
        control = np.int64(source[position])
        if control < 32:  # a literal run
            length = control + 1
            if position + 1 + length > end:
                return position, written, 1
            if written + length > stop and not overshoot:
                break
            out[written:written + length] = source[position + 1:position + 1 + length]
            position += 1 + length
        else:  # a back reference: length in the top 3 bits (7: one more byte), then distance
            length = control >> 5
            step = 2
            if length == 7:
                if position + 1 >= end:
                    return position, written, 1
                length += np.int64(source[position + 1])
                step = 3
            if position + step > end:
                return position, written, 1
            distance = ((control & 31) << 8) + np.int64(source[position + step - 1]) + 1
            length += 2
            if distance > written:
                return position, written, 2
            if written + length > stop and not overshoot:
                break
            for k in range(length):  # byte by byte: the copy may overlap what it writes
                out[written + k] = out[written - distance + k]
            position += step
        written += length
    return position, written, 0


def _lzf_error(path: Path, problem: int, position: int) -> ScanFormatError:
    return ScanFormatError(f'{path}: corrupt binary_compressed data ({_LZF_PROBLEMS[problem]}, '
                           f'compressed byte {position:,})')


def _lzf_field_states(path: Path, source: np.ndarray, starts: Sequence[int],
                      size: int) -> list[tuple[int, int, np.ndarray]]:
    """Decode the whole stream once, checking that it is ``size`` bytes long; returns for each
    output offset of ``starts`` (increasing) the decoder's state at the last instruction that
    starts there or before: (source position, output offset, the output's last bytes)."""
    states = []
    buffer = np.empty(LZF_WINDOW + LZF_BLOCK + LZF_LONGEST, dtype=np.uint8)
    position = produced = kept = 0
    for target in [*starts, None]:
        while target is None or produced < target:
            room = LZF_BLOCK + LZF_WINDOW - kept
            want = room if target is None else min(room, target - produced)
            position, written, problem = _lzf_decode(source, position, buffer, kept,
                                                     kept + want, target is None)
            if problem:
                raise _lzf_error(path, problem, position)
            produced += written - kept
            if produced > size:
                raise ScanFormatError(f'{path}: binary_compressed data longer than the '
                                      f'{size:,} bytes its header gives')
            keep = min(LZF_WINDOW, written)
            buffer[:keep] = buffer[written - keep:written]
            progress, kept = written - kept, keep
            if progress == 0:
                break
        if target is not None:
            states.append((position, produced, buffer[:kept].copy()))
    if produced != size:
        raise ScanFormatError(f'{path}: binary_compressed data of {produced:,} bytes where the '
                              f'header gives {size:,}')
    return states


def _lzf_field_blocks(path: Path, source: np.ndarray, state: tuple[int, int, np.ndarray],
                      start: int, item_bytes: int, points: int,
                      chunk_points: int) -> Iterator[np.ndarray]:
    """The bytes of one field (``points`` items of ``item_bytes`` from output offset
    ``start``), ``chunk_points`` items at a time, decoded from ``state`` on."""
    position, produced, window = state
    chunk_bytes = min(chunk_points, points) * item_bytes
    buffer = np.empty(LZF_WINDOW + chunk_bytes + 2 * LZF_LONGEST, dtype=np.uint8)
    kept = len(window)
    buffer[:kept] = window
    for first in range(0, points, chunk_points):
        begin = start + first * item_bytes
        end = begin + min(chunk_points, points - first) * item_bytes
        if end > produced:
            position, written, problem = _lzf_decode(source, position, buffer, kept,
                                                     kept + end - produced, True)
            if problem or written < kept + end - produced:
                raise _lzf_error(path, problem or 1, position)
            produced += written - kept
            kept = written
        stop = kept - (produced - end)  # buffer[:kept] ends at output offset ``produced``
        yield buffer[stop - (end - begin):stop]
        keep = min(LZF_WINDOW, kept)
        buffer[:keep] = buffer[kept - keep:kept]
        kept = keep


def _pcd_compressed_tables(path: Path, header: _PcdHeader, wanted: Sequence[str],
                           chunk_points: int) -> Iterator[np.ndarray]:
    """The ``wanted`` fields of ``DATA binary_compressed``, ``chunk_points`` points at a time,
    in memory bounded by the chunk: the file is memory-mapped, the fields decoded as above."""
    file_size = path.stat().st_size
    sizes = np.fromfile(path, dtype='<u4', count=2, offset=header.offset) \
        if file_size >= header.offset + 8 else np.zeros(0)
    if len(sizes) < 2 or file_size < header.offset + 8 + int(sizes[0]):
        raise ScanFormatError(f'{path}: {file_size:,} bytes, shorter than the binary_compressed '
                              f'data its header announces')
    compressed, size = int(sizes[0]), int(sizes[1])
    if size != header.points * header.dtype.itemsize:
        raise ScanFormatError(f'{path}: the header counts {header.points:,} points '
                              f'({header.points * header.dtype.itemsize:,} bytes) but the '
                              f'binary_compressed data holds {size:,} bytes')
    if header.points == 0:
        return
    source = np.zeros(0, dtype=np.uint8) if compressed == 0 else np.asarray(
        np.memmap(path, dtype=np.uint8, mode='r', offset=header.offset + 8, shape=(compressed, )))
    field_bytes = [header.dtype[name].itemsize for name in header.fields]
    field_starts = np.concatenate([[0], np.cumsum(field_bytes)[:-1]]) * header.points
    starts = {name: int(field_starts[header.fields.index(name)]) for name in wanted}
    ordered = sorted(wanted, key=starts.get)
    states = dict(zip(ordered, _lzf_field_states(path, source, [starts[n] for n in ordered],
                                                 size)))
    fields = [
        _lzf_field_blocks(path, source, states[name], starts[name], header.dtype[name].itemsize,
                          header.points, chunk_points) for name in wanted
    ]
    dtype = np.dtype([(name, header.dtype[name]) for name in wanted])
    for blocks in zip(*fields):
        table = np.empty(len(blocks[0]) // dtype[0].itemsize, dtype)
        for name, block in zip(wanted, blocks):
            table[name] = block.view(header.dtype[name].base).reshape(
                (len(table), ) + header.dtype[name].shape)
        yield table


# suffix -> generator of (n, 6) float64 chunks: reader(path, chunk_points, columns, notes)
ChunkReader = Callable[[Path, int, 'tuple[str, ...] | None', list], Iterator[np.ndarray]]
READERS: dict[str, ChunkReader] = {
    '.txt': _read_txt,
    '.bin': _read_bin,
    '.ply': _read_ply,
    '.las': _read_las,
    '.laz': _read_las,
    '.e57': _read_e57,
    '.pcd': _read_pcd,
    '.xyz': _read_text_columns,
    '.pts': _read_text_columns,
    '.csv': _read_text_columns,
}
SCAN_SUFFIXES = tuple(READERS)


def read_scan_chunks(path: str | os.PathLike,
                     chunk_points: int = CHUNK_POINTS,
                     columns: str | Sequence[str] | None = None,
                     notes: list[str] | None = None) -> Iterator[np.ndarray]:
    """Stream a scan file as ``(n, 6)`` float64 chunks of ``x y z r g b`` (n <= chunk_points).

    Coordinates are the file's own (georeferenced ones exact in float64). ``columns`` names
    the values of a text scan's lines (``'x,y,z,i'``). One-line notes (no colours...) are
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
                                  f'or colour ({len(bad_rows)} bad points among points {total}-'
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


# --------------------------------------------------------------------------- writers


def _write_txt(path: Path, points: np.ndarray) -> None:
    text, _ = format_lines(points[:, :3], _colours_0_255(points), decimals=6)
    path.write_bytes(text)


def _write_bin(path: Path, points: np.ndarray) -> None:
    points.astype(np.float32).tofile(path)


def _write_ply(path: Path, points: np.ndarray) -> None:
    vertex = ply_vertex(points)
    for i, name in enumerate('xyz'):  # double, so georeferenced coordinates stay exact
        vertex[name] = points[:, i]
    write_ply(path, vertex)


def _write_xyz(path: Path, points: np.ndarray) -> None:
    """``x y z r g b`` lines, millimetre-exact at any coordinate (6 decimals, float64)."""
    with open(path, 'w') as stream:
        np.savetxt(
            stream,
            np.column_stack([points[:, :3], _colours_0_255(points)]),
            fmt=['%.6f'] * 3 + ['%d'] * 3)


def _write_pcd(path: Path, points: np.ndarray) -> None:
    """A binary PCD with float64 ``x y z`` and packed ``rgb`` (uint32)."""
    colours = _colours_0_255(points).astype(np.uint32)
    table = np.empty(len(points), dtype=[('x', '<f8'), ('y', '<f8'), ('z', '<f8'), ('rgb', '<u4')])
    for i, name in enumerate('xyz'):
        table[name] = points[:, i]
    table['rgb'] = (colours[:, 0] << 16) | (colours[:, 1] << 8) | colours[:, 2]
    header = (f'# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\n'
              f'SIZE 8 8 8 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\n'
              f'VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\nDATA binary\n')
    with open(path, 'wb') as stream:
        stream.write(header.encode('ascii'))
        stream.write(table.tobytes())


def _write_las(path: Path, points: np.ndarray) -> None:
    write_las_chunks(path, [points])


def write_las_chunks(path: str | os.PathLike,
                     chunks: Iterable[np.ndarray],
                     offset: Sequence[float] | None = None) -> int:
    """Write ``(n, 6)`` chunks as one LAS (or, for ``.laz``, LAZ) file; returns the count.

    Coordinates are stored to the millimetre (scale 0.001) around ``offset`` (default: the
    first chunk's minimum floored to metres), colours as 16-bit (value x 257). Memory stays
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
            colours = _colours_0_255(chunk).astype(np.uint16) * 257
            record.red, record.green, record.blue = colours[:, 0], colours[:, 1], colours[:, 2]
            writer.write_points(record)
            total += len(chunk)
    finally:
        if writer is not None:
            writer.close()
    if writer is None:
        raise ValueError(f'{path}: no points to write')
    return total


def _write_e57(path: Path, points: np.ndarray) -> None:
    write_e57_scans(path, [(points, np.eye(3), np.zeros(3))])


def write_e57_scans(path: str | os.PathLike, scans: Sequence[tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]]) -> None:
    """Write ``(points, rotation, translation)`` scans into one E57 file.

    Each scan's ``(n, 6)`` points are in its own frame; its pose (3x3 rotation, translation)
    moves them into the file's. The points are stored as float32 around their floored
    minimum, which is folded into the float64 pose translation, so georeferenced coordinates
    keep sub-millimetre precision.
    """
    import pye57
    e57 = pye57.E57(os.fspath(path), mode='w')
    try:
        for points, rotation, translation in scans:
            points = np.asarray(points, dtype=np.float64)
            rotation = np.asarray(rotation, dtype=np.float64)
            shift = np.floor(points[:, :3].min(axis=0))
            local = points[:, :3] - shift
            colours = _colours_0_255(points).astype(np.uint8)
            data = {
                'cartesianX': local[:, 0],
                'cartesianY': local[:, 1],
                'cartesianZ': local[:, 2],
                'colorRed': colours[:, 0],
                'colorGreen': colours[:, 1],
                'colorBlue': colours[:, 2],
            }
            e57.write_scan_raw(
                data,
                rotation=_matrix_quaternion(rotation),
                translation=rotation @ shift + np.asarray(translation, float))
    finally:
        e57.close()


def ply_vertex(points: np.ndarray) -> dict[str, np.ndarray]:
    """PLY vertex properties of an ``(N, 6)`` scan: ``x y z`` float32, ``red green blue``
    uchar."""
    colours = _colours_0_255(points).astype(np.uint8)
    return {
        'x': points[:, 0].astype(np.float32),
        'y': points[:, 1].astype(np.float32),
        'z': points[:, 2].astype(np.float32),
        'red': colours[:, 0],
        'green': colours[:, 1],
        'blue': colours[:, 2],
    }


def _colours_0_255(points: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(points[:, 3:6]), 0, 255).astype(np.int64)


# suffix -> function writing an (N, 6) float64 array in that format
WRITERS: dict[str, Callable[[Path, np.ndarray], None]] = {
    '.txt': _write_txt,
    '.bin': _write_bin,
    '.ply': _write_ply,
    '.xyz': _write_xyz,
    '.pcd': _write_pcd,
    '.las': _write_las,
    '.laz': _write_las,
    '.e57': _write_e57,
}


def write_scan(path: str | os.PathLike, points: np.ndarray) -> None:
    """Write an ``(N, 6)`` (or ``(N, 3)``) array in the format of the path's suffix.

    Colours are rounded to integers 0-255; ``.txt`` and ``.xyz`` keep 6 decimals, ``.las``/
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
    temporary = path.with_name(f'{path.name}.tmp{os.getpid()}{path.suffix}')
    writer(temporary, points)
    os.replace(temporary, path)
