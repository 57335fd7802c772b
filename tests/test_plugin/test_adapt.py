"""Self-training on unlabelled scans (tools/adapt.py, projects/synthdet/self_training.py): the
pseudo-label filters, the pseudo-labelled rooms, and whole runs of the tool on tiny generated
data with ``adapt_selftrain.py``'s model untrained (a written checkpoint that loads, the mean
teacher carried from round to round, a rerun that continues, bad input refused)."""
from __future__ import annotations

import json
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.inference.windows import Detections
from projects.synthdet.datasets.synthdet_s3dis import SynthdetS3DISDataset
from projects.synthdet.self_training import (UNSURE_THR, add_ignored_regions, agreeing_detections,
                                             ignored_regions, room_offset, write_pseudo_room)
from synthdet.classes import IGNORED_REGION_LABEL
from synthdet.info_files import load_info_pickle
from synthdet.scan_io import read_scan, write_scan
from tests.checkpoints import initial_checkpoint
from tests.room_scans import make_room
from tests.s3dis_fixtures import write_synthetic_area

REPO = Path(__file__).resolve().parents[2]
CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
# adapt_selftrain.py on one generated area of the test's data root, batch 1, 2 iterations a round
TEST_CONFIG = """_base_ = ['{base}']
from projects.synthdet.config_helpers import areas_once  # noqa: E402

refresh_iters = 2
train_dataloader = dict(
    areas_once(dict(_base_.train_area_dataset, data_root='{data}/'), _base_.train_pipeline,
               [7, _base_.adapt_area], _base_.metainfo),
    batch_size=1, num_workers=0, persistent_workers=False)
default_hooks = dict(logger=dict(interval=1))
"""
SCORE_THR, AGREE_IOU = 0.5, 0.25


def detections(rows: list[tuple]) -> Detections:
    """Detections of ``(label, score, x)`` rows: 1 m boxes on a line."""
    boxes = np.array([[x, 0.0, 0.5, 1.0, 1.0, 1.0, 0.0] for _, _, x in rows]).reshape(-1, 7)
    return Detections(boxes, np.array([row[1] for row in rows], dtype=np.float64),
                      np.array([row[0] for row in rows], dtype=np.int64))


def test_pseudo_labels_are_the_boxes_every_run_finds_above_the_threshold():
    first = detections([(1, 0.8, 0.0), (0, 0.9, 3.0), (1, 0.4, 6.0), (2, 0.9, 9.0)])
    second = detections([
        (1, 0.7, 0.1),  # the same chair: IoU 0.82
        (1, 0.9, 3.0),  # the table's place, another class
        (1, 0.9, 6.0),  # agrees with a chair scoring below the threshold
        (2, 0.9, 9.6),  # the sofa 0.6 m off: IoU 0.25
    ])
    kept = agreeing_detections([first, second], 0.5, 0.5)
    assert kept.labels.tolist() == [1] and kept.scores.tolist() == [0.8]
    assert kept.boxes[0, 0] == 0.0  # the first run's box
    assert agreeing_detections([first, second], 0.5, 0.2).labels.tolist() == [1, 2]
    assert agreeing_detections([first], 0.5, 0.5).labels.tolist() == [1, 0, 2]  # one run
    weak = detections([(1, 0.45, 0.0)])  # finds the chair, below the threshold
    assert len(agreeing_detections([first, weak], 0.5, 0.5).scores) == 0
    assert len(agreeing_detections([first, Detections.empty()], 0.5, 0.5).scores) == 0


def test_a_pseudo_labelled_room_has_its_boxes_floor_and_clutter(tmp_path):
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 4, (500, 2)), rng.uniform(-0.01, 0.0, 500)])
    chair = rng.uniform([1.0, 1.0, 0.1], [1.5, 1.5, 0.9], (200, 3))
    lamp = rng.uniform([3.0, 3.0, 1.5], [3.2, 3.2, 2.0], (50, 3))
    xyz = np.concatenate([floor, chair, lamp])
    points = np.column_stack([xyz, np.full((len(xyz), 3), 128.0)])
    boxes = [{'class': 'chair', 'label': 'chair 1', 'center': [1.25, 1.25, 0.45],
              'size': [0.6, 0.6, 0.9], 'yaw': 0.0, 'score': 0.8},
             {'class': 'table', 'label': 'table 1', 'center': [2.5, 0.5, 2.0],
              'size': [0.5, 0.5, 0.5], 'yaw': 0.0, 'score': 0.7}]  # holds no point: dropped
    room = tmp_path / 'Area_11' / 'scan_1'
    assert write_pseudo_room(room, points, boxes) == boxes[:1]
    annotations = room / 'Annotations'
    assert sorted(path.stem for path in annotations.glob('*.txt')) == [
        'chair_1', 'clutter_1', 'floor_1']
    assert len(read_scan(annotations / 'chair_1.txt')) == 200
    assert len(read_scan(annotations / 'floor_1.txt')) == 500
    assert len(read_scan(annotations / 'clutter_1.txt')) == 50


def test_an_unsure_box_becomes_an_ignored_region_of_the_converted_room(tmp_path):
    """The teacher's unsure sofa is neither a label nor background: its box, grown by the
    margin, is an ignored region of the room's info, in the converted room's frame, and the
    dataset hands it to the head labelled ``IGNORED_REGION_LABEL`` beside the pseudo-label."""
    rng = np.random.default_rng(1)
    floor = np.column_stack([rng.uniform(-2, 2, (400, 2)), rng.uniform(-0.01, 0.0, 400)])
    chair = rng.uniform([-1.0, -1.0, 0.1], [-0.5, -0.5, 0.9], (200, 3))
    sofa = rng.uniform([0.5, 0.5, 0.12], [1.5, 1.2, 0.8], (300, 3))
    xyz = np.concatenate([floor, chair, sofa])
    points = np.column_stack([xyz, np.full((len(xyz), 3), 128.0)])
    chair_box = [-0.75, -0.75, 0.5, 0.6, 0.6, 0.9, 0.0]
    labels = Detections(np.array([chair_box]), np.array([0.8]), np.array([1]))
    unsure = Detections(np.array([chair_box,  # the label itself, found by every run: no region
                                  [1.0, 0.85, 0.45, 0.9, 0.6, 0.7, 0.0]]),
                        np.array([0.8, 0.3]), np.array([1, 2]))
    regions = ignored_regions(unsure, labels, agree_iou=0.5)
    assert np.allclose(regions, [[1.0, 0.85, 0.45, 1.0, 0.7, 0.8]])  # grown 5 cm a side
    raw = tmp_path / 'raw' / 'Stanford3dDataset_v1.2_Aligned_Version'
    held = write_pseudo_room(raw / 'Area_11' / 'scan_1', points,
                             [{'class': 'chair', 'label': 'chair 1', 'center': chair_box[:3],
                               'size': chair_box[3:6], 'yaw': 0.0, 'score': 0.8}])
    assert len(held) == 1
    assert len(read_scan(raw / 'Area_11' / 'scan_1' / 'scan_1.txt')) == len(xyz)  # none cut
    convert_s3dis(tmp_path / 'raw', tmp_path / 'data', areas=[11])
    info_file = tmp_path / 'data' / 's3dis_infos_Area_11.pkl'
    offset = room_offset(points)
    add_ignored_regions(info_file, {'Area_11_scan_1.bin': regions - np.r_[offset, 0, 0, 0]})
    dataset = SynthdetS3DISDataset(data_root=str(tmp_path / 'data'), ann_file=info_file.name,
                                   metainfo=dict(classes=CLASSES), pipeline=[],
                                   test_mode=False)
    ann = dataset.get_data_info(0)['ann_info']
    assert ann['gt_labels_3d'].tolist() == [1, IGNORED_REGION_LABEL]
    boxes = ann['gt_bboxes_3d']
    # the converted room's frame: the chair's instance box and the region keep their places
    sofa_region = np.concatenate([boxes.gravity_center[1].numpy() + offset, boxes.dims[1]])
    assert np.allclose(sofa_region, regions[0], atol=1e-3)
    chair_points = chair - offset
    assert np.allclose(boxes.gravity_center[0].numpy(),
                       (chair_points.min(0) + chair_points.max(0)) / 2, atol=1e-3)



@pytest.fixture(scope='module')
def adapted(tmp_path_factory) -> dict:
    """One round of tools/adapt.py, then the same command with --rounds 2 (continued)."""
    root = tmp_path_factory.mktemp('adapt')
    generated, data = root / 'generated', root / 'data'
    write_synthetic_area(generated, 7, n_rooms=2, seed=7, points_per_object=300)
    convert_s3dis(generated, data, areas=[7])
    scans = root / 'scans'
    scans.mkdir()
    for index in (1, 2):
        write_scan(scans / f'hall_{index}.ply',
                   make_room('rect', n_points=20_000, seed=index, furniture=3).points)
    (scans / 'notes.md').write_text('not a scan: left alone')
    config = root / 'adapt_tiny.py'
    config.write_text(
        TEST_CONFIG.format(base=REPO / 'configs' / 'tr3d' / 'adapt_selftrain.py', data=data))
    checkpoint = initial_checkpoint(REPO / 'configs' / 'tr3d' / 'exp2_cpu.py',
                                    root / 'synthetic.pth', CLASSES)
    command = [
        scans, '--config', config, '--checkpoint', checkpoint, '--work', root / 'work', '--out',
        root / 'adapted.pth', '--score-thr', SCORE_THR, '--agree-iou', AGREE_IOU, '--device', 'cpu'
    ]
    tool = runpy.run_path(str(REPO / 'tools' / 'adapt.py'), run_name='synthdet_tools_adapt')
    tool['main']([str(item) for item in [*command, '--rounds', 1]])
    first_round = {path: path.stat().st_mtime_ns for path in (root / 'work').rglob('*')}
    tool['main']([str(item) for item in [*command, '--rounds', 2]])
    return {'root': root, 'command': command, 'first_round': first_round, 'tool': tool,
            'config': config, 'checkpoint': checkpoint}


def test_a_run_writes_an_adapted_checkpoint_that_loads(adapted):
    from projects.synthdet.bootstrap import load_config
    from projects.synthdet.inference.detector import load_model
    out = adapted['root'] / 'adapted.pth'
    model = load_model(load_config(adapted['config']), str(out), 'cpu')
    assert list(model.dataset_meta['classes']) == CLASSES
    saved = torch.load(out, map_location='cpu', weights_only=True)
    assert set(saved) == {'meta', 'state_dict'}  # weights and plain meta only
    last = torch.load(adapted['root'] / 'work' / 'round_2' / 'train' / 'iter_2.pth',
                      map_location='cpu', weights_only=False)
    teacher, student = last['state_dict'], last['ema_state_dict']
    assert all(torch.equal(saved['state_dict'][key], teacher[key]) for key in teacher)
    # the teacher averaged over both rounds' 4 iterations (carried, not restarted) ...
    assert int(student['steps']) == 4
    # ... and moved less than the student from the synthetic weights
    initial = torch.load(adapted['checkpoint'], map_location='cpu')['state_dict']
    weights = [key for key in initial if key.endswith('conv_cls.kernel')]
    for key in weights:
        moved = (teacher[key] - initial[key]).abs().sum()
        assert 0 < moved < (student[f'module.{key}'] - initial[key]).abs().sum()


def test_pseudo_labels_pass_the_filters_and_become_the_rooms(adapted):
    for round_dir in ('round_1', 'round_2'):
        work = adapted['root'] / 'work' / round_dir
        document = json.loads((work / 'pseudo_labels.json').read_text())
        rule = {'score_thr': SCORE_THR, 'agree_iou': AGREE_IOU, 'unsure_thr': UNSURE_THR,
                'seeds': [0, 1]}
        assert document['rule'] == rule
        assert [item['scan'] for item in document['scans']] == ['hall_1.ply', 'hall_2.ply']
        boxes = [box for item in document['scans'] for box in item['boxes']]
        assert boxes and all(box['score'] >= SCORE_THR for box in boxes)
        for item in document['scans']:
            annotations = (work / 'raw' / 'Stanford3dDataset_v1.2_Aligned_Version' / 'Area_11' /
                           item['room'] / 'Annotations')
            names = {path.stem for path in annotations.glob('*.txt')}
            assert {box['label'].replace(' ', '_') for box in item['boxes']} <= names
            room_points = len(read_scan(annotations.parent / f'{item["room"]}.txt'))
            assert room_points == item['points']  # every point kept
        infos = load_info_pickle(work / 'data' / 's3dis_infos_Area_11.pkl')['data_list']
        for item, info in zip(document['scans'], infos):  # the regions, in the room's frame
            assert info['lidar_points']['lidar_path'] == f'Area_11_{item["room"]}.bin'
            assert len(info['ignored_regions']) == len(item['ignored_regions'])
            sizes = [region['bbox_3d'][3:] for region in info['ignored_regions']]
            assert np.allclose(sizes, [box[3:] for box in item['ignored_regions']], atol=1e-4)


def test_a_rerun_continues_after_the_last_finished_round(adapted):
    # the second command kept the first round as it was and added a round
    for path, modified in adapted['first_round'].items():
        if path.name != 'settings.json':
            assert path.stat().st_mtime_ns == modified, path
    work = adapted['root'] / 'work'
    assert (work / 'round_2' / 'train' / 'iter_2.pth').is_file()
    finished = {path: path.stat().st_mtime_ns for path in work.rglob('*')}
    adapted['tool']['main']([str(item) for item in [*adapted['command'], '--rounds', 2]])
    assert all(path.stat().st_mtime_ns == modified for path, modified in finished.items()
               if path.name != 'settings.json')
    # other options with the same --work are refused
    with pytest.raises(ValueError, match=r'--work .*: holds a run with other score_thr'):
        adapted['tool']['main']([str(item) for item in [*adapted['command'], '--score-thr', 0.9]])


def run_adapt(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, 'tools/adapt.py', *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=600)


def test_bad_input_is_refused_with_one_line_before_any_work(adapted, tmp_path):
    main, root = adapted['tool']['main'], adapted['root']
    scans, config, checkpoint = root / 'scans', adapted['config'], adapted['checkpoint']
    work, out = tmp_path / 'work', tmp_path / 'adapted.pth'

    def refused(*args) -> str:
        with pytest.raises(ValueError) as error:
            main([str(item) for item in args])
        assert not work.exists() and not out.exists()
        return str(error.value)

    common = ['--work', work, '--out', out, '--device', 'cpu']
    assert 'no such folder of scans' in refused(tmp_path / 'none', '--config', config,
                                                '--checkpoint', checkpoint, *common)
    bad_scans = tmp_path / 'bad'
    bad_scans.mkdir()
    (bad_scans / 'broken.ply').write_text('ply\nformat nonsense\n')
    assert 'broken.ply' in refused(bad_scans, '--config', config, '--checkpoint', checkpoint,
                                   *common)
    tiny = REPO / 'configs' / 'tr3d' / 'tiny.py'
    assert 'no adapt_area' in refused(scans, '--config', tiny, '--checkpoint', checkpoint, *common)
    text = tmp_path / 'notes.pth'
    text.write_text('not a checkpoint')
    assert 'notes.pth' in refused(scans, '--config', config, '--checkpoint', text, *common)
    assert 'above --score-thr' in refused(scans, '--config', config, '--checkpoint', checkpoint,
                                          *common, '--unsure-thr', 0.6)
    assert 'is the input' in refused(scans, '--config', config, '--checkpoint', checkpoint,
                                     '--work', work, '--out', checkpoint, '--device', 'cpu')
    process = run_adapt(tmp_path / 'none', '--config', config, '--checkpoint', checkpoint, *common)
    assert process.returncode == 2 and process.stderr.count('\n') == 1, process.stderr
    assert process.stderr.startswith('adapt.py: error: ') and 'none' in process.stderr
