"""S3DIS raw-format writer: room text files, per-instance annotations, meta.json, PLY and preview.

Layout of one room (exactly as the Stanford S3DIS release)::

    Area_N/<room>/<room>.txt                 all points, lines 'x y z r g b'
    Area_N/<room>/Annotations/<class>_<i>.txt the points of one element
    Area_N/<room>/meta.json                   synthdet ground truth ("synthdet.room/1")

The room file is the concatenation of the annotation files. Coordinates carry a fixed number of
decimals (3, like S3DIS), colors are integers. Lines are formatted by the core's vectorised
``synthdet.point_text.format_lines`` (no per-line Python formatting). A room is built in a
temporary folder next to its final place and renamed at the end, so a room folder either exists
complete or not at all.
"""
import json
import os
import shutil
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from synthdet import contracts
from synthdet.ply import write_ply
from synthdet.point_text import format_lines

TMP_PREFIX = '.tmp.'


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
    contracts.write_room(tmp / 'meta.json', meta)
    classes = [name.rsplit('_', 1)[0] for name in part_names]
    if ply:
        class_names = sorted(set(classes))
        class_index = np.array([class_names.index(c) for c in classes], dtype=np.int32)[part]
        write_ply(
            tmp / f'{room}.ply', {
                'x': xyz[:, 0],
                'y': xyz[:, 1],
                'z': xyz[:, 2],
                'red': rgb[:, 0].astype(np.uint8),
                'green': rgb[:, 1].astype(np.uint8),
                'blue': rgb[:, 2].astype(np.uint8),
                'class': class_index,
                'instance': part.astype(np.int32),
            })
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
        _write_preview(tmp / f'{room}.png', room, xyz, rgb, np.array(classes, dtype=object)[part],
                       meta)
    for name, path in (extra_files or {}).items():
        shutil.move(str(path), str(tmp / name))
    os.rename(tmp, final)
    return final


def _write_preview(path: Path, room: str, xyz: np.ndarray, rgb: np.ndarray, labels: np.ndarray,
                   meta: dict[str, Any]) -> None:
    """Top view of the room: points colored by class, object boxes, the floor polygon."""
    from synthdet.room_data import Scan, boxes_from_room
    from synthdet.topview import draw_top_view
    draw_top_view(
        path,
        Scan(np.hstack([xyz, rgb]), labels, room),
        boxes_from_room(meta),
        corners=np.asarray(meta['room']['polygon'], dtype=np.float64),
        title=f'{room}: {len(meta["objects"])} objects',
        corners_label='floor polygon')


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
