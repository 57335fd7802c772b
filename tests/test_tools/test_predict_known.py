"""``tools/predict.py --known`` and ``tools/scan2cad.py --known``: a later scan of a room detected
with an earlier scan's corrected labels (an untrained model, so what comes out is what the known
objects give), and the one-line refusals of a missing labels file and of a scan of another
room."""
from __future__ import annotations

import json

import numpy as np
import pytest

from synthdet.contracts import LABELS_FORMAT, write_labels
from synthdet.scan_io import write_scan
from tests.checkpoints import initial_checkpoint
from tests.room_scans import make_room
from tests.test_plugin.test_known_objects import room_boxes, scene, turned
from tests.test_repository.test_faults import TINY, TINY_CLASSES, assert_clean_error, run


@pytest.fixture(scope='module')
def rooms(tmp_path_factory) -> dict:
    """earlier.ply (a table and a chair, labelled), later.ply (the same room a quarter turn
    away, the chair gone) and other.ply (another room), and an untrained checkpoint."""
    root = tmp_path_factory.mktemp('known')
    table, chair = room_boxes(scene([], seed=0))
    earlier = scene([table, chair], seed=1)
    later, matrix = turned(scene([table], seed=2), 1, (1.0, -2.0))
    other = make_room('T', n_points=60_000, seed=8, furniture=0, openings=False, rotate=False)
    for name, points in (('earlier', earlier), ('later', later), ('other', other.points[:, :3])):
        write_scan(root / f'{name}.ply', np.column_stack([points, np.full((len(points), 3), 128)]))
    write_labels(root / 'earlier.labels.json', {
        'format': LABELS_FORMAT, 'scan': 'earlier.ply', 'classes': TINY_CLASSES,
        'boxes': [table, chair]})
    table_later = matrix[:3, :3] @ np.asarray(table['center']) + matrix[:3, 3]
    return {'root': root, 'table_later': table_later,
            'checkpoint': initial_checkpoint(TINY, root / 'untrained.pth', TINY_CLASSES)}


def test_the_objects_still_there_are_found_again(rooms, tmp_path):
    root = rooms['root']
    proc = run('tools/predict.py', TINY, rooms['checkpoint'], root / 'later.ply', '--known',
               root / 'earlier.ply', '--out', tmp_path, '--score-thr', '0.99')
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert 'registered on earlier.ply' in proc.stdout
    assert '1 of its 2 objects found again' in proc.stdout
    detections = json.loads((tmp_path / 'later.pred.json').read_text())['detections']
    assert [box['class'] for box in detections] == ['table']
    np.testing.assert_allclose(detections[0]['center'], rooms['table_later'], atol=0.03)
    assert detections[0]['yaw'] == pytest.approx(np.pi / 2, abs=0.02)


def test_a_known_scan_without_labels_is_one_line(rooms, tmp_path):
    root = rooms['root']
    proc = run('tools/predict.py', TINY, rooms['checkpoint'], root / 'later.ply', '--known',
               root / 'other.ply', '--out', tmp_path)
    assert_clean_error(proc, 2, 'other.labels.json')
    assert not list(tmp_path.iterdir())


def test_a_scan_of_another_room_is_refused(rooms, tmp_path):
    root = rooms['root']
    (root / 'other.labels.json').unlink(missing_ok=True)
    scan = root / 'other.ply'
    proc = run('tools/predict.py', TINY, rooms['checkpoint'], scan, '--known',
               root / 'earlier.ply', '--out', tmp_path)
    assert_clean_error(proc, 2, 'not two scans of the same room')
    assert str(scan) in proc.stderr and not list(tmp_path.iterdir())


def test_scan2cad_builds_the_later_scan_from_the_known_objects(rooms, tmp_path):
    root = rooms['root']
    out = tmp_path / 'later.FCStd'
    proc = run('tools/scan2cad.py', root / 'later.ply', '--config', TINY, '--checkpoint',
               rooms['checkpoint'], '--known', root / 'earlier.ply', '--out', out,
               '--score-thr', '0.99')
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert 'known objects: later.ply: registered on earlier.ply' in proc.stdout
    detections = json.loads(out.with_suffix('.pred.json').read_text())['detections']
    assert [box['class'] for box in detections] == ['table']
    np.testing.assert_allclose(detections[0]['center'], rooms['table_later'], atol=0.03)
    assert out.is_file()
