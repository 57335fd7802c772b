"""S3DIS raw-format writer: room text files, per-instance annotations, meta.json, PLY and preview.

Layout of one room (exactly as the Stanford S3DIS release)::

    Area_N/<room>/<room>.txt                 all points, lines 'x y z r g b'
    Area_N/<room>/Annotations/<class>_<i>.txt the points of one element
    Area_N/<room>/meta.json                   synthdet ground truth ("synthdet.room/1")

The room file is the concatenation of the annotation files. Coordinates carry a fixed number of
decimals (3, like S3DIS), colours are integers. Lines are formatted by vectorised numpy code (no
per-line Python formatting). A room is built in a temporary folder next to its final place and
renamed at the end, so a room folder either exists complete or not at all.
"""
import json
import os
import shutil
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

ROOM_FORMAT = 'synthdet.room/1'
TMP_PREFIX = '.tmp.'


def _digit_table(count: int, width: int) -> np.ndarray:
    """ASCII digits of 0..count-1, right-aligned in ``width`` columns, 0 bytes as left padding."""
    values = np.arange(count)
    table = np.zeros((count, width), dtype=np.uint8)
    n_digits = np.array([len(str(v)) for v in range(count)])
    for col in range(width):
        power = width - 1 - col
        table[:, col] = np.where(n_digits > power, 48 + (values // 10**power) % 10, 0)
    return table


_COLOUR_DIGITS = _digit_table(256, 3)


def format_lines(xyz: np.ndarray, rgb: np.ndarray, decimals: int = 3) -> tuple[bytes, np.ndarray]:
    """Format points as 'x y z r g b' lines; return the bytes and the (N+1,) line start offsets.

    ``x`` is printed as ``round(x * 10**decimals)`` scaled back, so parsing the text gives
    ``np.rint(x * 10**decimals) / 10**decimals`` exactly. Digits come from lookup tables.
    """
    n = len(xyz)
    scale = 10**decimals
    fraction_digits = _digit_table(scale, decimals)
    fraction_digits[fraction_digits == 0] = 48  # fractions keep their leading zeros
    quantised = np.rint(np.asarray(xyz, dtype=np.float64) * scale).astype(np.int64)
    whole_max = int(np.abs(quantised).max()) // scale if n else 0
    if whole_max >= 10**7:
        raise ValueError(f'coordinates up to {whole_max} m are out of range for the text writer')
    whole_digits = _digit_table(whole_max + 1, len(str(whole_max)))
    colours = np.asarray(rgb, dtype=np.int64)
    if n and (colours.min() < 0 or colours.max() > 255):
        raise ValueError('colours must be integers in 0..255')
    w = whole_digits.shape[1]
    field_width = 1 + w + 1 + decimals + 1
    whole_rows = np.ascontiguousarray(whole_digits.T)
    fraction_rows = np.ascontiguousarray(fraction_digits.T)
    colour_rows = np.ascontiguousarray(_COLOUR_DIGITS.T)
    whole_len = (whole_digits != 0).sum(axis=1)
    colour_len = (_COLOUR_DIGITS != 0).sum(axis=1)
    lengths = np.full(n, 3 * (2 + decimals) + 3 * 1, dtype=np.int64)  # '.', fraction, separators
    # built with one contiguous row per character position, transposed once at the end
    table = np.zeros((3 * field_width + 12, n), dtype=np.uint8)
    for axis in range(3):
        q = np.ascontiguousarray(quantised[:, axis])
        negative = q < 0
        m = np.abs(q)
        whole, fraction = np.divmod(m, scale)
        col = axis * field_width
        table[col] = negative * np.uint8(ord('-'))
        for r in range(w):
            table[col + 1 + r] = whole_rows[r][whole]
        table[col + 1 + w] = ord('.')
        for r in range(decimals):
            table[col + 2 + w + r] = fraction_rows[r][fraction]
        table[col + 2 + w + decimals] = 32
        lengths += negative + whole_len[whole]
    for channel in range(3):
        c = np.ascontiguousarray(colours[:, channel])
        col = 3 * field_width + 4 * channel
        for r in range(3):
            table[col + r] = colour_rows[r][c]
        table[col + 3] = 32 if channel < 2 else 10
        lengths += colour_len[c]
    table = np.ascontiguousarray(table.T)
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    return table[table != 0].tobytes(), offsets


def parse_lines(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an S3DIS text file back into xyz (N, 3) float64 and rgb (N, 3) int64."""
    data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    if data.shape[1] != 6:
        raise ValueError(f'{path}: expected 6 columns "x y z r g b", got {data.shape[1]}')
    return data[:, :3], data[:, 3:].astype(np.int64)


def write_ply(path: Path, xyz: np.ndarray, rgb: np.ndarray, class_index: np.ndarray,
              instance_index: np.ndarray) -> None:
    """Binary little-endian PLY with x y z (float64), red green blue (uchar), class, instance."""
    vertex = np.empty(
        len(xyz),
        dtype=[('x', '<f8'), ('y', '<f8'), ('z', '<f8'), ('red', 'u1'), ('green', 'u1'),
               ('blue', 'u1'), ('class', '<i4'), ('instance', '<i4')])
    vertex['x'], vertex['y'], vertex['z'] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    vertex['red'], vertex['green'], vertex['blue'] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    vertex['class'], vertex['instance'] = class_index, instance_index
    header = ('ply\nformat binary_little_endian 1.0\n'
              f'element vertex {len(xyz)}\n'
              'property double x\nproperty double y\nproperty double z\n'
              'property uchar red\nproperty uchar green\nproperty uchar blue\n'
              'property int class\nproperty int instance\nend_header\n')
    with open(path, 'wb') as f:
        f.write(header.encode('ascii'))
        f.write(vertex.tobytes())


def write_room(area_dir: Path,
               room: str,
               xyz: np.ndarray,
               rgb: np.ndarray,
               part: np.ndarray,
               part_names: Sequence[str],
               meta: dict[str, Any],
               decimals: int = 3,
               ply: bool = False,
               preview: bool = False,
               extra_files: Mapping[str, Path] | None = None) -> Path:
    """Write one room atomically into ``area_dir/room`` and return that folder.

    ``part[i]`` indexes ``part_names`` (annotation names such as ``chair_1``); parts without
    points get no annotation file. Annotation files follow the order of ``part_names``.
    ``extra_files`` (name -> path, e.g. a saved .blend) are moved into the room folder before
    it is published.
    """
    area_dir = Path(area_dir)
    final = area_dir / room
    if final.exists():
        raise FileExistsError(f'{final}: room already exists')
    area_dir.mkdir(parents=True, exist_ok=True)
    tmp = area_dir / f'{TMP_PREFIX}{room}.{os.getpid()}'
    if tmp.exists():
        shutil.rmtree(tmp)
    (tmp / 'Annotations').mkdir(parents=True)

    order = np.argsort(part, kind='stable')
    xyz, rgb, part = xyz[order], rgb[order], part[order]
    text, offsets = format_lines(xyz, rgb, decimals)
    bounds = np.searchsorted(part, np.arange(len(part_names) + 1))
    with open(tmp / f'{room}.txt', 'wb') as f:
        f.write(text)
    for index, name in enumerate(part_names):
        start, stop = bounds[index], bounds[index + 1]
        if stop > start:
            with open(tmp / 'Annotations' / f'{name}.txt', 'wb') as f:
                f.write(text[offsets[start]:offsets[stop]])
    with open(tmp / 'meta.json', 'w') as f:
        json.dump(meta, f, indent=1)
        f.write('\n')
    classes = [name.rsplit('_', 1)[0] for name in part_names]
    if ply:
        class_names = sorted(set(classes))
        class_index = np.array([class_names.index(c) for c in classes], dtype=np.int32)[part]
        write_ply(tmp / f'{room}.ply', xyz, rgb, class_index, part)
        with open(tmp / f'{room}.ply.json', 'w') as f:
            json.dump(
                {
                    'format': 'synthdet.ply-labels/1',
                    'classes': class_names,
                    'instances': list(part_names)
                },
                f,
                indent=1)
    if preview:
        from generator.preview import write_preview
        write_preview(tmp / f'{room}.png', xyz, part, classes, meta)
    for name, path in (extra_files or {}).items():
        shutil.move(str(path), str(tmp / name))
    os.rename(tmp, final)
    return final


def clean_stale(area_dir: Path, room: str) -> None:
    """Remove temporary folders left by an interrupted run for ``room``."""
    area_dir = Path(area_dir)
    if area_dir.is_dir():
        for path in area_dir.glob(f'{TMP_PREFIX}{room}.*'):
            _remove(path)


def remove_orphaned_tmp(area_dir: Path) -> None:
    """Remove temporary folders and files (``.tmp.<room>.<pid>...``) of processes that ended."""
    area_dir = Path(area_dir)
    if not area_dir.is_dir():
        return
    for path in area_dir.glob(f'{TMP_PREFIX}*'):
        pid = path.name[len(TMP_PREFIX):].split('.')[1:2]
        if pid and pid[0].isdigit() and not _process_exists(int(pid[0])):
            _remove(path)


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink()


def _process_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True
