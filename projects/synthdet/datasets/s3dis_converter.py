"""Convert S3DIS-format areas (the real S3DIS or synthetic ones) to mmdet3d's v1.1 infos.

Reads ``root/Stanford3dDataset_v1.2_Aligned_Version/Area_N/<room>/Annotations/<class>_<k>.txt``
and writes, in ``out_dir``, for every room:

- ``points/Area_N_<room>.bin``: float32 (N, 6), xyz shifted so the room's minimum is 0,
  colors 0-255;
- ``semantic_mask/Area_N_<room>.bin``: int64 ids of :data:`SEMANTIC_CLASSES`;
- ``instance_mask/Area_N_<room>.bin``: int64, annotation files numbered 1..K in natural file
  order (structural ones included; 0 means unannotated), like mmdet3d's collect step;

and per area ``s3dis_infos_Area_N.pkl`` (``<info_prefix>_infos_Area_N.pkl``) in the format
mmdet3d 1.4's ``update_infos_to_v2`` writes for S3DIS. The known stray byte of the real S3DIS
(``Area_5/hallway_6``) is repaired in memory as mmdet3d's converter does (``s3dis_repairs``).
Boxes are the axis-aligned min/max of each detection instance's points. An annotation file's
class is its name minus the ``_<index>.txt`` suffix (matched without regard to case). The
pickles do not depend on the number of workers; worker processes end with their parent, and
leftover ``.partial`` files of the converted areas are removed at the start.
Importing this module needs numpy and numba only (no torch, no mmdet3d).
"""
import math
import mmap
import os
import pickle
import re
import warnings
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numba
import numpy as np
from tqdm import tqdm

from synthdet.classes import DETECTION_CLASSES, FALLBACK_CLASS, SEMANTIC_CLASSES
from synthdet.info_files import RAW_DIR as S3DIS_DIR
from synthdet.outputs import write_bytes
from synthdet.point_text import PointFileError, compile_parser, max_rows, read_point_file
from synthdet.processes import die_with_parent
from synthdet.room_data import annotation_class, annotation_files, natural_key

from .s3dis_repairs import repaired_point_text

OUTPUT_DIRS = ('points', 'instance_mask', 'semantic_mask')
PARTIAL_SUFFIX = '.partial'
ON_ERROR_CHOICES = ('raise', 'skip')
_SEMANTIC_ID = {name: i for i, name in enumerate(SEMANTIC_CLASSES)}
_DETECTION_LABEL = {name: i for i, name in enumerate(DETECTION_CLASSES)}
# Output files are written in pieces of this size: small page-cache folios (see write_bin).
WRITE_PIECE_BYTES = 1 << 16


class S3DISLayoutError(ValueError):
    """The input folder does not have the S3DIS layout; the message names the path."""


class OutputOverflowError(ValueError):
    """Finite input values that are not finite once written as float32; names the file."""


class UnknownClassWarning(UserWarning):
    """Annotation files of classes outside SEMANTIC_CLASSES were converted as clutter."""


@dataclass
class SkippedInput:
    """A line, file or room left out by ``on_error='skip'``; ``line`` is None for whole files."""
    path: str
    line: int | None
    reason: str


@dataclass
class ConversionSummary:
    """What a conversion wrote and what it left out."""
    rooms_per_area: dict[int, int] = field(default_factory=dict)
    num_points: int = 0
    instances_per_class: Counter = field(default_factory=Counter)
    skipped: list[SkippedInput] = field(default_factory=list)
    unknown_classes: dict[str, list[str]] = field(default_factory=dict)
    repaired: list[str] = field(default_factory=list)

    def report(self) -> str:
        """Human-readable multi-line summary."""
        lines = [
            f'converted {sum(self.rooms_per_area.values())} rooms '
            f'({", ".join(f"Area_{a}: {n}" for a, n in self.rooms_per_area.items())}), '
            f'{self.num_points} points',
            'detection instances: ' + ', '.join(f'{name} {self.instances_per_class[name]}'
                                                for name in DETECTION_CLASSES)
        ]
        for name, files in sorted(self.unknown_classes.items()):
            lines.append(f'unknown class {name!r} converted as {FALLBACK_CLASS}: {len(files)} '
                         f'file(s), e.g. {files[0]}')
        lines += [
            f'repaired the known stray byte of {path} (as mmdet3d does)' for path in self.repaired
        ]
        if self.skipped:
            lines.append(f'skipped {len(self.skipped)} input(s):')
            lines += [
                f'  {s.path}' + (f':{s.line}' if s.line is not None else '') + f': {s.reason}'
                for s in self.skipped
            ]
        return '\n'.join(lines)


@dataclass
class RoomResult:
    name: str
    num_points: int
    instances: list[dict]
    skipped: list[SkippedInput]
    unknown: dict[str, list[str]]
    repaired: list[str] = field(default_factory=list)


def find_areas(root_path: str | Path) -> list[int]:
    """Area numbers N with a folder ``Area_N`` under the S3DIS data folder, sorted."""
    data_dir = Path(root_path) / S3DIS_DIR
    if not data_dir.is_dir():
        raise S3DISLayoutError(f'{data_dir}: S3DIS data folder not found')
    return sorted(
        int(p.name[5:]) for p in data_dir.iterdir()
        if p.is_dir() and re.fullmatch(r'Area_\d+', p.name))


def list_rooms(area_dir: Path) -> list[str]:
    """Room folder names of an area in natural order (``office_2`` before ``office_10``)."""
    return sorted(
        (p.name for p in area_dir.iterdir() if p.is_dir() and not p.name.startswith('.')),
        key=natural_key)


def _partial_paths(out_dir: Path, name: str) -> list[Path]:
    return [out_dir / sub / f'{name}.bin{PARTIAL_SUFFIX}' for sub in OUTPUT_DIRS]


def _xyz_min_max(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis min and max of the first three columns, in the points' dtype.

    Column by column: ~10x faster than ``min(axis=0)`` over an (N, 6) row-major array.
    """
    lo = np.array([points[:, axis].min() for axis in range(3)], dtype=points.dtype)
    hi = np.array([points[:, axis].max() for axis in range(3)], dtype=points.dtype)
    return lo, hi


@numba.njit(cache=True, nogil=True)
def _shift_to_float32(points: np.ndarray, out: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Write float64 (N, 6) ``points`` to float32 ``out`` with xyz shifted to their per-axis
    minimum (subtracted in float64, rounded to float32 once, as mmdet3d's collect step does);
    colors are converted as they are. Returns the float64 xyz minimum and maximum.

    Two passes over the rows instead of numpy's nine strided column passes."""
    low = points[0, :3].copy()
    high = points[0, :3].copy()
    for i in range(1, points.shape[0]):
        for axis in range(3):
            value = points[i, axis]
            if value < low[axis]:
                low[axis] = value
            elif value > high[axis]:
                high[axis] = value
    for i in range(points.shape[0]):
        for axis in range(3):
            out[i, axis] = points[i, axis] - low[axis]
        for column in range(3, 6):
            out[i, column] = points[i, column]
    return low, high


def _compile_kernels() -> None:
    """Compile (or load from numba's cache) the parser and the shift, before forking workers."""
    compile_parser()
    _shift_to_float32(np.zeros((1, 6)), np.empty((1, 6), dtype=np.float32))


class _Scratch:
    """Arrays reused from room to room within one process.

    First touches of fresh memory cost a page fault per page; on a virtual machine whose free
    page reporting hands free 2 MiB blocks back to its host, a host fault per 4 KiB page as
    well. One set of arrays, grown to the largest room, pays them once per process instead of
    once per room, and in 4 KiB pages of an anonymous mapping: numpy would ask for 2 MiB huge
    pages, which come from those reported blocks. Views of them live only while one room is
    converted; ``convert_s3dis`` releases them when it ends."""

    def __init__(self) -> None:
        self._arrays: dict[str, np.ndarray] = {}

    def take(self, name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
        """An uninitialised array of ``shape``: the first rows of the one kept under ``name``,
        which is replaced by a larger one when it has too few rows."""
        array = self._arrays.get(name)
        if array is None or len(array) < shape[0]:
            # twice the rows it had: a few larger rooms in a row need few new arrays, and rows
            # never used are never touched
            rows = shape[0] if array is None else max(shape[0], 2 * len(array))
            count = rows * math.prod(shape[1:])
            mapping = mmap.mmap(-1, max(count * np.dtype(dtype).itemsize, 1),
                                flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
            array = np.frombuffer(mapping, dtype, count).reshape((rows, ) + shape[1:])
            self._arrays[name] = array
        return array[:shape[0]]

    def clear(self) -> None:
        """Release the arrays."""
        self._arrays.clear()


_SCRATCH = _Scratch()


def write_bin(array: np.ndarray, path: Path) -> None:
    """Write the bytes of a C-contiguous ``array`` to ``path``, 64 KiB per ``write`` call.

    One multi-megabyte ``write`` lets Linux back the file with large page-cache folios (up to
    2 MiB), taken from the high-order free blocks that a virtual machine's free page reporting
    has handed back to its host; filling them then costs a host page fault per 4 KiB page
    (over a second of system time for the 245 MB of a 20-room area, in some runs and not in
    others). Small writes get small folios, mostly from the low-order free lists, which page
    reporting leaves alone."""
    data = memoryview(array).cast('B')
    with open(path, 'wb') as f:
        for start in range(0, len(data), WRITE_PIECE_BYTES):
            f.write(data[start:start + WRITE_PIECE_BYTES])


def _box(points: np.ndarray) -> list[float]:
    """Axis-aligned [cx, cy, cz, dx, dy, dz] of float32 points, computed in float32."""
    lo, hi = _xyz_min_max(points)
    return np.concatenate([(lo + hi) / 2, hi - lo]).tolist()


@dataclass
class _RoomPoints:
    points: np.ndarray  # float64 (N, 6), the annotation files one after the other
    classes: list[str]  # class of each annotation file kept
    paths: list[Path]  # each annotation file kept
    counts: list[int]  # its number of points
    skipped: list[SkippedInput]
    unknown: dict[str, list[str]]
    repaired: list[str] = field(default_factory=list)


def _read_room(room_dir: Path, skip: bool) -> _RoomPoints:
    ann_dir = room_dir / 'Annotations'
    files = annotation_files(ann_dir)
    if not files:
        raise S3DISLayoutError(f'{ann_dir}: no Annotations/<class>_<k>.txt files')
    broken = [path for path in files if not path.is_file()]  # a dangling symbolic link
    if broken and not skip:
        raise S3DISLayoutError(f'{broken[0]}: annotation file not found (a broken symbolic '
                               'link)')
    files = [path for path in files if path not in broken]
    sizes = [path.stat().st_size for path in files]
    # one array for the room (no concatenation); only the rows parsed into are touched
    buffer = _SCRATCH.take('text points', (sum(max_rows(size) for size in sizes), 6), np.float64)
    room = _RoomPoints(buffer, [], [], [], [], {})
    room.skipped += [
        SkippedInput(str(path), None, 'file left out: a broken symbolic link') for path in broken
    ]
    for path in files:
        class_name = annotation_class(path)
        if class_name is None:
            reason = 'annotation file name is not <class>_<index>.txt'
            if not skip:
                raise S3DISLayoutError(f'{path}: {reason}')
            room.skipped.append(SkippedInput(str(path), None, f'file left out: {reason}'))
            continue
        if class_name not in _SEMANTIC_ID:
            room.unknown.setdefault(class_name, []).append(str(path))
            class_name = FALLBACK_CLASS
        offset = sum(room.counts)
        repaired = repaired_point_text(path)
        if repaired is not None:
            room.repaired.append(str(path))
        try:
            points, bad_lines = read_point_file(
                path, skip_bad_lines=skip, out=buffer[offset:], data=repaired)
        except PointFileError as error:
            if not skip:
                raise
            room.skipped.append(SkippedInput(str(path), None, f'file left out: {error.reason}'))
            continue
        room.skipped += [SkippedInput(str(b.path), b.line, b.reason) for b in bad_lines]
        room.classes.append(class_name)
        room.paths.append(path)
        room.counts.append(len(points))
    room.points = buffer[:sum(room.counts)]
    return room


def convert_room(room_dir: Path, name: str, out_dir: Path, skip: bool) -> RoomResult:
    """Convert one room, writing its three .bin files under ``.partial`` names.

    Returns the room's detection instances (``bbox_3d``, ``bbox_label_3d``) in instance order.
    """
    try:
        room = _read_room(room_dir, skip)
    except S3DISLayoutError as error:
        if not skip:
            raise
        return RoomResult(name, 0, [], [SkippedInput(str(room_dir), None, str(error))], {})
    if not room.counts:
        room.skipped.append(
            SkippedInput(str(room_dir), None, 'room left out: no valid annotation file'))
        return RoomResult(name, 0, [], room.skipped, room.unknown)
    num_points = len(room.points)
    points = _SCRATCH.take('points', (num_points, 6), np.float32)
    low, high = _shift_to_float32(room.points, points)
    semantic = _SCRATCH.take('semantic', (num_points, ), np.int64)
    instance = _SCRATCH.take('instance', (num_points, ), np.int64)
    starts = np.concatenate([[0], np.cumsum(room.counts)])
    for k, (class_name, start, end) in enumerate(zip(room.classes, starts[:-1], starts[1:])):
        semantic[start:end] = _SEMANTIC_ID[class_name]
        instance[start:end] = k + 1  # annotation files numbered from 1
    instances = [{
        'bbox_3d': _box(points[start:end]),
        'bbox_label_3d': _DETECTION_LABEL[c]
    } for c, start, end in zip(room.classes, starts[:-1], starts[1:]) if c in _DETECTION_LABEL]
    try:
        _check_float32(points, instances, room, high - low)
    except OutputOverflowError as error:
        if not skip:
            raise
        room.skipped.append(SkippedInput(str(room_dir), None, f'room left out: {error}'))
        return RoomResult(name, 0, [], room.skipped, room.unknown)
    for array, path in zip((points, instance, semantic), _partial_paths(out_dir, name)):
        write_bin(array, path)
    return RoomResult(name, num_points, instances, room.skipped, room.unknown, room.repaired)


def _check_float32(points: np.ndarray, instances: list[dict], room: _RoomPoints,
                   span: np.ndarray) -> None:
    """Raise :class:`OutputOverflowError` naming the file of the first non-finite point or box.

    ``span`` is the float64 extent of the room's xyz: below 1e38 on every axis, every shifted
    point is finite in float32 (up to 3.4e38) and only the boxes are checked."""
    ends = np.cumsum(room.counts)
    shifted_fit = bool((span < 1e38).all())
    bad = [] if shifted_fit else np.flatnonzero(~np.isfinite(points[:, :3]).all(axis=1))
    if len(bad):
        k = int(np.searchsorted(ends, bad[0], side='right'))
        raise OutputOverflowError(
            f'{room.paths[k]}: point {int(bad[0] - ends[k] + room.counts[k]) + 1} overflows '
            'float32 once the room is shifted to its minimum (|value| > 3.4e38)')
    detection_files = [p for p, c in zip(room.paths, room.classes) if c in _DETECTION_LABEL]
    for path, inst in zip(detection_files, instances):
        if not np.isfinite(inst['bbox_3d']).all():
            raise OutputOverflowError(f'{path}: its box overflows float32 (the points span more '
                                      'than 3.4e38)')


def _convert_room_task(task: tuple[Path, str, Path, bool]) -> RoomResult:
    return convert_room(*task)


def _info(sample_idx: int, result: RoomResult) -> dict:
    file_name = f'{result.name}.bin'
    return {
        'sample_idx': sample_idx,
        'lidar_points': {
            'num_pts_feats': 6,
            'lidar_path': file_name
        },
        'instances': [{  # new dicts: the pickle's bytes must not depend on the worker count
            'bbox_3d': list(inst['bbox_3d']),
            'bbox_label_3d': inst['bbox_label_3d']
        } for inst in result.instances],
        'pts_semantic_mask_path': file_name,
        'pts_instance_mask_path': file_name
    }


def info_metainfo() -> dict:
    """The ``metainfo`` block of every info pickle written here."""
    return {'categories': dict(_DETECTION_LABEL), 'dataset': 's3dis', 'info_version': '1.1'}


def _write_pickle_atomic(obj: object, path: Path) -> None:
    write_bytes(path, pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))


def _run(tasks: list, pool: ProcessPoolExecutor | None) -> Iterator[RoomResult]:
    if pool is None:
        return map(_convert_room_task, tasks)
    return pool.map(_convert_room_task, tasks)


def _convert_area(area: int,
                  rooms: list[str],
                  data_dir: Path,
                  out_dir: Path,
                  skip: bool,
                  pool: ProcessPoolExecutor | None,
                  progress: tqdm,
                  info_prefix: str = 's3dis') -> list[RoomResult]:
    names = [f'Area_{area}_{room}' for room in rooms]
    tasks = [(data_dir / f'Area_{area}' / room, name, out_dir, skip)
             for room, name in zip(rooms, names)]
    results = []
    try:
        for result in _run(tasks, pool):
            results.append(result)
            progress.update(1)
    except BaseException:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        _remove_partials(out_dir, names)
        raise
    converted = [r for r in results if r.num_points > 0]
    for result in converted:
        for partial in _partial_paths(out_dir, result.name):
            os.replace(partial, partial.with_name(partial.name[:-len(PARTIAL_SUFFIX)]))
    data_list = [_info(i, result) for i, result in enumerate(converted)]
    _write_pickle_atomic({
        'metainfo': info_metainfo(),
        'data_list': data_list
    }, out_dir / f'{info_prefix}_infos_Area_{area}.pkl')
    return results


def _remove_partials_of_areas(out_dir: Path, areas: Iterable[int]) -> None:
    for area in areas:
        for sub in OUTPUT_DIRS:
            for partial in (out_dir / sub).glob(f'Area_{area}_*.bin{PARTIAL_SUFFIX}'):
                partial.unlink(missing_ok=True)


def _remove_partials(out_dir: Path, names: Iterable[str]) -> None:
    for name in names:
        for partial in _partial_paths(out_dir, name):
            partial.unlink(missing_ok=True)


def convert_s3dis(root_path: str | Path,
                  out_dir: str | Path,
                  areas: Sequence[int] | None = None,
                  workers: int = 1,
                  on_error: str = 'raise',
                  info_prefix: str = 's3dis') -> ConversionSummary:
    """Convert the S3DIS-format areas under ``root_path`` to .bin files and info pickles.

    Args:
        root_path: folder holding ``Stanford3dDataset_v1.2_Aligned_Version``.
        out_dir: output folder (``points/``, ``instance_mask/``, ``semantic_mask/``, pickles).
        areas: area numbers to convert; default: every ``Area_N`` found.
        workers: processes converting rooms in parallel.
        on_error: ``'raise'`` stops at the first bad input with an error naming file and line;
            ``'skip'`` leaves out bad lines, empty files and unreadable rooms and lists them in
            the summary. Either way an area's outputs appear only once the area is complete.
        info_prefix: the info pickles are ``<info_prefix>_infos_Area_N.pkl`` (mmdet3d's
            ``--extra-tag``).

    Annotation files of unknown classes are converted as clutter, with one
    :class:`UnknownClassWarning` for the whole run.
    """
    if on_error not in ON_ERROR_CHOICES:
        raise ValueError(f'on_error must be one of {ON_ERROR_CHOICES}, got {on_error!r}')
    if workers < 1:
        raise ValueError(f'workers must be >= 1, got {workers}')
    data_dir, out_dir = Path(root_path) / S3DIS_DIR, Path(out_dir)
    found = find_areas(root_path)
    areas = found if areas is None else list(areas)
    missing = [a for a in areas if a not in found]
    if missing:
        raise S3DISLayoutError(f'{data_dir}: no folder for area(s) {missing} (found {found})')
    if not areas:
        raise S3DISLayoutError(f'{data_dir}: no Area_N folder found')
    rooms = {area: list_rooms(data_dir / f'Area_{area}') for area in areas}
    for sub in OUTPUT_DIRS:
        (out_dir / sub).mkdir(parents=True, exist_ok=True)
    summary = ConversionSummary()
    _compile_kernels()  # once here rather than in every worker
    _remove_partials_of_areas(out_dir, areas)  # leftovers of a killed run
    pool = ProcessPoolExecutor(
        workers, initializer=die_with_parent, initargs=(os.getpid(), )) if workers > 1 else None
    try:
        with tqdm(
                total=sum(map(len, rooms.values())), desc='convert S3DIS rooms',
                unit='room') as progress:
            for area in areas:
                results = _convert_area(area, rooms[area], data_dir, out_dir, on_error == 'skip',
                                        pool, progress, info_prefix)
                summary.rooms_per_area[area] = sum(r.num_points > 0 for r in results)
                for result in results:
                    summary.num_points += result.num_points
                    summary.instances_per_class.update(DETECTION_CLASSES[inst['bbox_label_3d']]
                                                       for inst in result.instances)
                    summary.skipped += result.skipped
                    summary.repaired += result.repaired
                    for name, files in result.unknown.items():
                        summary.unknown_classes.setdefault(name, []).extend(files)
    finally:
        if pool is not None:
            pool.shutdown()
        _SCRATCH.clear()
    if summary.unknown_classes:
        warnings.warn(
            'annotation files of unknown classes were converted as '
            f'{FALLBACK_CLASS}: ' +
            ', '.join(f'{name} ({len(files)} files)'
                      for name, files in sorted(summary.unknown_classes.items())),
            UnknownClassWarning,
            stacklevel=2)
    return summary
