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
- ``.pcd``: Point Cloud Library files, ``ascii`` or ``binary``;
- ``.xyz``/``.pts``/``.csv``: text columns; delimiter and header lines are detected, the
  columns come from ``columns`` (``x,y,z,r,g,b``, ``x,y,z,i``, ``_`` skips one) or the count.

Scans without colours get their intensity as grey, or zeros without intensity; the notes say
which. Errors for bad files are ``ScanFormatError`` naming the file (and the line for text).
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

import numpy as np

from synthdet.ply import read_ply_vertices, write_ply
from synthdet.point_text import PointFileError, format_lines, read_point_blocks
from synthdet.voxels import VoxelFilter

CHUNK_POINTS = 1_000_000  # default points per chunk: about 50 MB of float64 rows
MAX_HEIGHT = 200.0  # metres; a taller scan (robust extent) is taken to be in other units
MAX_WIDTH = 20_000.0  # metres
COLUMN_NAMES = ('x', 'y', 'z', 'r', 'g', 'b', 'i')


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
        head = [stream.readline() for _ in range(64)]
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
                                  delimiter, notes)


def _text_blocks(path: Path, skip: int, chunk_lines: int) -> Iterator[tuple[int, list[bytes]]]:
    """Blocks of up to ``chunk_lines`` lines after ``skip`` header lines, with the 1-based
    number of each block's first line."""
    with open(path, 'rb') as stream:
        for _ in range(skip):
            stream.readline()
        number = skip + 1
        while True:
            block = list(itertools.islice(stream, chunk_lines))
            if not block:
                return
            yield number, block
            number += len(block)


def _parse_text_blocks(path: Path, blocks: Iterable[tuple[int, list[bytes]]], names: Sequence[str],
                       delimiter: str, notes: list[str]) -> Iterator[np.ndarray]:
    """Parse blocks of text lines holding the columns ``names`` into ``(n, 6)`` chunks."""
    index = {name: i for i, name in enumerate(names) if name != '_'}
    has_colour, has_intensity = 'r' in index, 'i' in index
    if not has_colour:
        notes.append(_no_colour_note(path, has_intensity))
    colour_scale, intensity_scale = _Scale(), _Scale()
    for first_line, block in blocks:
        try:
            values = np.loadtxt(
                io.BytesIO(b''.join(block)),
                delimiter=None if delimiter == ' ' else delimiter,
                ndmin=2,
                dtype=np.float64)
        except ValueError as error:
            raise ScanFormatError(f'{path}:{_bad_line(block, len(names), delimiter) + first_line}'
                                  f': {_short(error)}') from None
        if values.shape[1] != len(names):
            raise ScanFormatError(f'{path}:{first_line}: expected {len(names)} values per line '
                                  f'({",".join(names)}), found {values.shape[1]}')
        chunk = np.zeros((len(values), 6))
        chunk[:, :3] = values[:, [index['x'], index['y'], index['z']]]
        if has_colour:
            chunk[:, 3:] = colour_scale(values[:, [index['r'], index['g'], index['b']]])
        elif has_intensity:
            chunk[:, 3:] = _grey(intensity_scale(values[:, index['i']]))
        yield chunk


def _bad_line(block: list[bytes], count: int, delimiter: str) -> int:
    """Offset in the block of its first line that is not ``count`` numbers (0 if none)."""
    for offset, line in enumerate(block):
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
    try:  # ~48 bytes a line: blocks of about chunk_points lines, split to at most that many
        for block in read_point_blocks(path, 48 * chunk_points, columns=count):
            for start in range(0, len(block), chunk_points):
                part = block[start:start + chunk_points]
                yield part if count == 6 else np.hstack([part, np.zeros((len(part), 3))])
    except PointFileError as error:
        raise ScanFormatError(str(error)) from None


def _s3dis_columns(path: Path) -> int:
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
        try:
            for points in reader.chunk_iterator(chunk_points):
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
        except (OSError, ValueError, RuntimeError) as error:
            raise ScanFormatError(f'{path}: cannot decode the points ({_short(error)})') from None


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


def _pcd_header(path: Path) -> _PcdHeader:
    entries: dict[str, list[str]] = {}
    offset = lines = 0
    with open(path, 'rb') as stream:
        for raw in stream:
            offset += len(raw)
            lines += 1
            words = raw.decode('ascii', errors='replace').split()
            if not words or words[0].startswith('#'):
                continue
            entries[words[0].upper()] = words[1:]
            if words[0].upper() == 'DATA':
                break
            if lines > 50:
                break
    if 'DATA' not in entries or 'FIELDS' not in entries:
        raise ScanFormatError(f'{path}: not a PCD file (no FIELDS or DATA line in its header)')
    fields = entries['FIELDS']
    sizes = entries.get('SIZE', ['4'] * len(fields))
    types = entries.get('TYPE', ['F'] * len(fields))
    counts = entries.get('COUNT', ['1'] * len(fields))
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise ScanFormatError(f'{path}: PCD header FIELDS, SIZE, TYPE and COUNT differ in length')
    layout = []
    for name, size, kind, count in zip(fields, sizes, types, counts):
        code = _PCD_TYPES.get((kind.upper(), int(size)))
        if code is None:
            raise ScanFormatError(f'{path}: PCD field {name} has unknown type {kind}{size}')
        layout.append((name, code, (int(count), )) if int(count) > 1 else (name, code))
    width = int(entries.get('WIDTH', ['0'])[0])
    height = int(entries.get('HEIGHT', ['1'])[0])
    points = int(entries.get('POINTS', [str(width * height)])[0])
    return _PcdHeader(fields, np.dtype(layout), points, entries['DATA'][0].lower(), offset, lines)


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
    if header.data == 'binary':
        expected = header.offset + header.points * header.dtype.itemsize
        if path.stat().st_size < expected:
            raise ScanFormatError(f'{path}: {path.stat().st_size} bytes, the header promises '
                                  f'{header.points} points ({expected} bytes)')
        if header.points == 0:
            return
        table = np.memmap(
            path, dtype=header.dtype, mode='r', offset=header.offset, shape=(header.points, ))
    elif header.data == 'ascii':
        table = None
    else:
        raise ScanFormatError(f'{path}: PCD data {header.data!r} is not supported; save it as '
                              f'binary or ascii')
    if colour is None:
        notes.append(_no_colour_note(path, intensity is not None))
    intensity_scale = _Scale()
    if table is not None:
        blocks = ((start, table[start:start + chunk_points])
                  for start in range(0, len(table), chunk_points))
    else:
        blocks = ((first, _pcd_ascii_rows(path, first, block, header))
                  for first, block in _text_blocks(path, header.lines, chunk_points))
    for _, part in blocks:
        chunk = np.zeros((len(part), 6))
        for i, name in enumerate('xyz'):
            chunk[:, i] = part[name]
        if colour is not None:
            chunk[:, 3:] = _pcd_colours(part[colour])
        elif intensity is not None:
            chunk[:, 3:] = _grey(intensity_scale(part[intensity]))
        yield chunk


def _pcd_ascii_rows(path: Path, first_line: int, block: list[bytes],
                    header: _PcdHeader) -> np.ndarray:
    """Parse a block of ASCII PCD lines into the header's structured dtype."""
    floats = np.dtype([(name, '<f8' if header.dtype[name].kind == 'f' else '<i8')
                       for name in header.fields if header.dtype[name].shape == ()])
    try:
        rows = np.loadtxt(
            io.BytesIO(b''.join(block)),
            dtype=floats,
            ndmin=1,
            usecols=[i for i, name in enumerate(header.fields) if header.dtype[name].shape == ()])
    except ValueError as error:
        raise ScanFormatError(f'{path}:{first_line + _bad_line(block, len(header.fields), " ")}'
                              f': {_short(error)}') from None
    table = np.zeros(len(rows), header.dtype)
    for name in floats.names:
        table[name] = rows[name]
    return table


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
