"""Read the info pickles of ``tools/create_data.py`` without running code, and select rooms.

An info pickle is plain data (dicts, lists, strings, numbers): the reader refuses anything
else, so a pickle handed over by someone else cannot run code when it is opened.
"""
from __future__ import annotations

import os
import pickle
import re
from pathlib import Path
from typing import Sequence

from synthdet.contracts import SchemaError, read_room

RAW_DIR = 'Stanford3dDataset_v1.2_Aligned_Version'
_SCAN_NAME = re.compile(r'^(Area_\d+)_(.+)\.bin$')


class InfoFileError(ValueError):
    """An info pickle that is empty, broken or not in the converter's format; names the file."""


class _PlainUnpickler(pickle.Unpickler):
    """Unpickles dicts, lists, tuples, strings, bytes, numbers, booleans and None only: every
    other type is looked up by ``find_class``, which refuses them all, so nothing in the pickle
    is ever called."""

    def find_class(self, module: str, name: str) -> object:
        raise pickle.UnpicklingError(f'{module}.{name} is not plain data')


def load_info_pickle(path: str | os.PathLike) -> dict:
    """Read an info pickle written by ``tools/create_data.py`` (plain data only).

    Raises ``InfoFileError`` naming the file when it cannot be read, is not plain data, or
    lacks the ``metainfo`` dict and the ``data_list`` list of dicts.
    """
    try:
        with open(path, 'rb') as stream:
            infos = _PlainUnpickler(stream).load()
    except OSError as error:
        raise InfoFileError(
            f'{path}: cannot read the info pickle ({error.strerror or error})') from None
    except Exception as error:  # malformed pickles raise many types; none runs code here
        reason = ' '.join(str(error).split())[:200] or type(error).__name__
        raise InfoFileError(
            f'{path}: not an info pickle of tools/create_data.py ({reason})') from None
    if not isinstance(infos, dict) or not {'metainfo', 'data_list'} <= set(infos):
        raise InfoFileError(f'{path}: not an info pickle of tools/create_data.py (no metainfo '
                            'and data_list)')
    if not isinstance(infos['metainfo'], dict) or not isinstance(infos['data_list'], list) or \
            not all(isinstance(info, dict) for info in infos['data_list']):
        raise InfoFileError(f'{path}: not an info pickle of tools/create_data.py (metainfo must '
                            'be a dict and data_list a list of dicts)')
    return infos


def room_sensor(room: dict) -> str:
    """The generator sensor model (``synthdet.contracts.SENSOR_MODELS``) that scanned a validated
    ``synthdet.room/1`` document; rooms from before the sensor models are ``paper``."""
    return room.get('generator', {}).get('sensor', {}).get('model', 'paper')


def raw_room_dir(data_root: str | os.PathLike, scan_name: str) -> Path | None:
    """The raw room folder of a converted scan ``Area_N_<room>.bin`` in the layout
    ``tools/create_data.py --root-path D --out-dir D`` writes
    (``D/Stanford3dDataset_v1.2_Aligned_Version/Area_N/<room>``); None for another name."""
    match = _SCAN_NAME.match(scan_name)
    return Path(data_root) / RAW_DIR / match[1] / match[2] if match else None


def room_sensors(info_file: str | os.PathLike) -> list[str]:
    """The generator sensor model of every room of the info pickle, in its ``data_list`` order.

    Each room's ``meta.json`` is looked up in the raw folder next to the pickle
    (``<data_root>/Stanford3dDataset_v1.2_Aligned_Version/Area_N/<room>/meta.json``); a room
    without one (a real S3DIS room) raises ``InfoFileError`` naming it.
    """
    info_file = Path(info_file)
    sensors = []
    for info in load_info_pickle(info_file)['data_list']:
        name = Path(info['lidar_points']['lidar_path']).name
        room_dir = raw_room_dir(info_file.parent, name)
        meta = room_dir / 'meta.json' if room_dir else None
        if meta is None or not meta.is_file():
            raise InfoFileError(f'{info_file}: room {name} has no generator meta.json '
                                f'({meta or "not an Area_N_<room>.bin name"})')
        try:
            sensors.append(room_sensor(read_room(meta)))
        except SchemaError as error:
            raise InfoFileError(str(error)) from None
    return sensors


def rooms_scanned_by(info_file: str | os.PathLike, sensor: str) -> list[int]:
    """Indices into the info pickle's ``data_list`` of the rooms that ``sensor`` scanned
    (:func:`room_sensors`)."""
    return [index for index, model in enumerate(room_sensors(info_file)) if model == sensor]


def labelled_boxes(
        path: str | os.PathLike,
        default_classes: Sequence[str] | None = None) -> list[tuple[str | None, list]]:
    """``(points file name, [(class name, bbox_3d), ...])`` for every sample of an info
    pickle (the name None for a sample without ``lidar_points``); class names come from its
    ``metainfo['categories']`` (``name -> label``), or from ``default_classes`` (label =
    index) when it has none. Instances labelled -1 (ignored classes) are left out.

    Raises ``InfoFileError`` naming the file (and the sample) for a pickle without categories
    (and no ``default_classes``), a label it does not name, ``lidar_points`` without
    ``lidar_path``, or an instance without ``bbox_label_3d`` or ``bbox_3d``.
    """
    infos = load_info_pickle(path)
    categories = infos['metainfo'].get('categories')
    if categories is None and default_classes is not None:
        categories = {name: label for label, name in enumerate(default_classes)}
    if not isinstance(categories, dict) or not all(
            isinstance(name, str) and isinstance(label, int) for name, label in
            categories.items()):
        raise InfoFileError(f'{path}: not an info pickle of tools/create_data.py (metainfo '
                            'has no "categories" dict of class name -> label)')
    names = {label: name for name, label in categories.items()}
    samples = []
    for index, info in enumerate(infos['data_list']):
        try:
            points = info.get('lidar_points')
            scan = None if points is None else Path(points['lidar_path']).name
            boxes = [(names[inst['bbox_label_3d']], list(inst['bbox_3d']))
                     for inst in info.get('instances', []) if inst['bbox_label_3d'] != -1]
        except KeyError as error:
            key = error.args[0]
            what = (f'label {key} is not in metainfo["categories"]' if isinstance(key, int)
                    else f'no "{key}"')
            raise InfoFileError(f'{path}: data_list[{index}]: {what}') from None
        except TypeError as error:
            raise InfoFileError(f'{path}: data_list[{index}]: malformed sample ({error})') \
                from None
        samples.append((scan, boxes))
    return samples
