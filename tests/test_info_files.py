"""Info pickles are read as plain data everywhere (a pickle that would run code is refused), and
the rooms of one generator sensor are found through their meta.json."""
import json
import pickle
from pathlib import Path

import pytest

from synthdet.contracts import ROOM_FORMAT
from synthdet.info_files import RAW_DIR, InfoFileError, load_info_pickle, rooms_scanned_by
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


def test_rooms_scanned_by_reads_each_rooms_meta_json(tmp_path: Path) -> None:
    names = ['Area_9_factory_1.bin', 'Area_9_factory_2.bin', 'Area_9_big_hall_3.bin']
    info_file = tmp_path / 's3dis_infos_Area_9.pkl'
    info_file.write_bytes(pickle.dumps(_infos(names)))
    room = {'polygon': [[0.0, 0.0], [0.0, 4.0], [4.0, 4.0], [4.0, 0.0]], 'height': 3.0}
    for name, generator in zip(('factory_1', 'factory_2', 'big_hall_3'),
                               ({'sensor': {'model': 'tls'}}, {}, {'sensor': {'model': 'tls'}})):
        folder = tmp_path / RAW_DIR / 'Area_9' / name
        folder.mkdir(parents=True)
        (folder / 'meta.json').write_text(
            json.dumps({'format': ROOM_FORMAT, 'room': room, 'objects': [],
                        'generator': generator}))
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
