"""Point Cloud Library scans (``.pcd``): ``DATA ascii``, ``binary`` and ``binary_compressed``.

Binary data is memory-mapped and compressed data decoded a chunk at a time (the LZF decoder
below), so memory stays one chunk whatever the file's size. Written as binary PCD with float64
``x y z`` and packed ``rgb``.
"""
from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import numba
import numpy as np

from synthdet.scan_io import common
from synthdet.scan_io.common import (Scale, ScanFormatError, bad_line, colors_0_255, no_color_note,
                                     one_line, structured_chunk, text_blocks)

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
            raw = stream.readline(common.MAX_LINE_BYTES + 1)
            if not raw or len(raw) > common.MAX_LINE_BYTES:
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
        raise ScanFormatError(f'{path}: PCD fields {fields}: {one_line(error)}') from None
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


def _pcd_colors(packed: np.ndarray) -> np.ndarray:
    """``(n, 3)`` colors of PCD's packed ``rgb``/``rgba`` (float32 or uint32 bits)."""
    bits = np.ascontiguousarray(packed).view(np.uint32)
    return np.column_stack([(bits >> 16) & 255, (bits >> 8) & 255, bits & 255]).astype(float)


def read_chunks(path: Path, chunk_points: int, columns: tuple[str, ...] | None,
                notes: list[str]) -> Iterator[np.ndarray]:
    """``(n, 6)`` chunks of the points, packed ``rgb`` as colors, else intensity as grey;
    records without coordinates (an organised cloud's pixels without a depth) left out."""
    header = _pcd_header(path)
    color = next((name for name in ('rgb', 'rgba') if name in header.fields), None)
    intensity = 'intensity' if 'intensity' in header.fields else None
    if not {'x', 'y', 'z'} <= set(header.fields):
        raise ScanFormatError(f'{path}: PCD fields need x, y and z, got {header.fields}')
    wanted = ['x', 'y', 'z'] + [name for name in (color or intensity, ) if name]
    if header.data == 'binary':
        blocks = _pcd_binary_tables(path, header, chunk_points)
    elif header.data == 'binary_compressed':
        blocks = _pcd_compressed_tables(path, header, wanted, chunk_points)
    elif header.data == 'ascii':
        blocks = (_pcd_ascii_rows(path, first, block, header)
                  for first, block in text_blocks(path, header.lines, chunk_points))
    else:
        raise ScanFormatError(f'{path}: PCD data {header.data!r} is not one of ascii, binary '
                              f'and binary_compressed')
    if color is None:
        notes.append(no_color_note(path, intensity is not None))
    intensity_scale = Scale()
    total = invalid = 0
    for block in blocks:
        total += len(block)
        for start in range(0, len(block), chunk_points):
            part = block[start:start + chunk_points]
            colors = None if color is None else _pcd_colors(part[color])
            chunk = structured_chunk(part, colors, intensity, intensity_scale)
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
        offset, problem = bad_line(block, sum(widths), ' ')
        raise ScanFormatError(f'{path}:{first_line + offset}: '
                              f'{problem or one_line(error)}') from None
    table = np.zeros(len(rows), header.dtype)
    for name in single:
        table[name] = rows[name]
    return table


def write(path: Path, points: np.ndarray) -> None:
    """A binary PCD with float64 ``x y z`` and packed ``rgb`` (uint32)."""
    colors = colors_0_255(points).astype(np.uint32)
    table = np.empty(len(points), dtype=[('x', '<f8'), ('y', '<f8'), ('z', '<f8'), ('rgb', '<u4')])
    for i, name in enumerate('xyz'):
        table[name] = points[:, i]
    table['rgb'] = (colors[:, 0] << 16) | (colors[:, 1] << 8) | colors[:, 2]
    header = (f'# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\n'
              f'SIZE 8 8 8 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\n'
              f'VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\nDATA binary\n')
    with open(path, 'wb') as stream:
        stream.write(header.encode('ascii'))
        stream.write(table.tobytes())


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
