"""Info pickles are read as plain data everywhere (a pickle that would run code is refused), and
the rooms of one generator sensor are found through their meta.json."""
import json
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from synthdet.contracts import ROOM_FORMAT
from synthdet.info_files import RAW_DIR, InfoFileError, load_info_pickle, rooms_scanned_by

ROOT = Path(__file__).resolve().parents[2]
from synthdet.room_data import boxes_from_info


class _OpensMarker:
    """Unpickling this object creates the marker file: proof that code ran."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, 'w')


def _infos(names: list[str]) -> dict:
    return {
        'metainfo': {'categories': {'chair': 1}},
        'data_list': [{
            'lidar_points': {'lidar_path': name},
            'instances': [{'bbox_3d': [1.0, 2.0, 0.5, 0.6, 0.6, 1.0], 'bbox_label_3d': 1}]
        } for name in names]
    }


def test_info_readers_refuse_code_and_name_the_file(tmp_path: Path) -> None:
    marker = tmp_path / 'MARKER'
    evil = tmp_path / 'evil.pkl'
    evil.write_bytes(pickle.dumps({'metainfo': {}, 'data_list': [_OpensMarker(marker)]}))
    for read in (load_info_pickle, lambda path: boxes_from_info(path, 'Area_1_office_1.bin')):
        with pytest.raises(InfoFileError, match=f'{evil}: not an info pickle'):
            read(evil)
    assert not marker.exists()
    good = tmp_path / 'good.pkl'
    good.write_bytes(pickle.dumps(_infos(['Area_1_office_1.bin'])))
    [box] = boxes_from_info(good, 'Area_1_office_1.bin')
    assert (box.label, box.center, box.size) == ('chair', (1.0, 2.0, 0.5), (0.6, 0.6, 1.0))


def _write_area(root: Path, area: int, sensors: dict[str, str | None]) -> Path:
    """An info pickle of generated rooms ``{room: sensor model, None for no record}`` with each
    room's meta.json in the raw folder next to it; the pickle's path."""
    info_file = root / f's3dis_infos_Area_{area}.pkl'
    info_file.write_bytes(pickle.dumps(_infos([f'Area_{area}_{name}.bin' for name in sensors])))
    room = {'polygon': [[0.0, 0.0], [0.0, 4.0], [4.0, 4.0], [4.0, 0.0]], 'height': 3.0}
    for name, model in sensors.items():
        folder = root / RAW_DIR / f'Area_{area}' / name
        folder.mkdir(parents=True)
        (folder / 'meta.json').write_text(
            json.dumps({'format': ROOM_FORMAT, 'room': room, 'objects': [],
                        'generator': {'sensor': {'model': model}} if model else {}}))
    return info_file


def test_rooms_scanned_by_reads_each_rooms_meta_json(tmp_path: Path) -> None:
    info_file = _write_area(tmp_path, 9, {'factory_1': 'tls', 'factory_2': None,
                                          'big_hall_3': 'tls'})
    assert rooms_scanned_by(info_file, 'tls') == [0, 2]
    assert rooms_scanned_by(info_file, 'paper') == [1]  # no sensor record: the paper's sensor
    assert rooms_scanned_by(info_file, 'tablet') == []
    broken = tmp_path / RAW_DIR / 'Area_9' / 'factory_2' / 'meta.json'
    broken.write_text('{"format": "synthdet.room/1",\n "room": }')
    with pytest.raises(InfoFileError, match=f'{broken}:2:'):
        rooms_scanned_by(info_file, 'tls')
    broken.unlink()
    with pytest.raises(InfoFileError, match='Area_9_factory_2.bin has no generator meta.json'):
        rooms_scanned_by(info_file, 'tls')


def test_dataset_stats_lists_the_sensors_that_scanned_the_areas(tmp_path: Path) -> None:
    _write_area(tmp_path, 8, {'factory_1': 'reconstruction', 'factory_2': 'tls'})
    _write_area(tmp_path, 9, {'factory_1': 'tablet', 'factory_2': None, 'office_3': 'tablet'})

    def sensors(*areas: str) -> subprocess.CompletedProcess:
        command = [sys.executable, 'tools/dataset_stats.py', str(tmp_path), '--sensors']
        return subprocess.run(command + (['--areas', *areas] if areas else []), cwd=ROOT,
                              capture_output=True, text=True, timeout=120)

    # in the order of SENSOR_MODELS, each once; no sensor record is the paper's sensor
    assert sensors('9').stdout.split() == ['paper', 'tablet']
    assert sensors().stdout.split() == ['paper', 'tls', 'tablet', 'reconstruction']
    missing = sensors('7')
    assert missing.returncode == 2 and 's3dis_infos_Area_7.pkl' in missing.stderr
    (tmp_path / RAW_DIR / 'Area_9' / 'office_3' / 'meta.json').unlink()
    broken = sensors('9')
    assert broken.returncode == 2 and 'Area_9_office_3.bin has no generator meta.json' in \
        broken.stderr
