"""tools/predict.py on the prepared, windowed path and tools/scan2cad.py, with a real model.

A module fixture writes two small rooms (tests/s3dis_fixtures.py), converts them and trains the
tiny config for one epoch (2 iterations) with tools/train.py, as
tests/test_tools/test_tr3d_tools.py does. Such a model is weak, so the tests keep every detection
scoring at least 0.01 (TR3D's own threshold) and compare outputs, never their quality. FreeCAD is
the real ``freecadcmd``.
"""
import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from mmdet3d.apis import inference_detector
from mmdet3d.structures import DepthInstance3DBoxes
from mmengine.runner import set_random_seed

from configurator.__main__ import main as configurator_main
from configurator.corners import SCAN_VOXEL
from configurator.freecad_cli import build_document
from projects.synthdet.bootstrap import load_config
from projects.synthdet.core.box_ops import pairwise_bev_iou
from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.inference.detector import ModelDetector, load_model
from projects.synthdet.inference.fragments import fragment_rule_from_config, merge_fragments
from projects.synthdet.inference.windows import (Detections, density_from_config,
                                                 detect_in_windows, window_spec_from_config)
from synthdet.contracts import read_corners, read_predictions
from synthdet.geometry import rotation_z
from synthdet.prepare import floor_density, prepare_scan
from synthdet.scan_io import load_scan, read_scan, write_scan
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from tests.test_tools.test_tr3d_tools import data_options, load_tool, run_tool

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
SCORE = '0.01'
OFFSET = np.array([500000.0, 5400000.0, 300.0])


@pytest.fixture(scope='module')
def tiny(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Two converted 6 m x 5 m rooms and a checkpoint trained for one epoch by tools/train.py."""
    root = tmp_path_factory.mktemp('scan2cad')
    write_synthetic_area(
        root / 'raw', area=1, n_rooms=2, seed=11, points_per_object=300, room_size=(6.0, 5.0, 3.0))
    convert_s3dis(root / 'raw', root / 'data', areas=[1])
    run_tool('tools/train.py', TINY, '--work-dir', root / 'work', '--cfg-options',
             *data_options(root / 'data'), 'train_cfg.max_epochs=1', 'train_cfg.val_interval=1')
    rooms = sorted((root / 'raw' / S3DIS_DIR / 'Area_1').glob('*/*.txt'))
    return {'root': root, 'checkpoint': root / 'work' / 'epoch_1.pth', 'rooms': rooms}


def predict_scan(tiny: dict, scan: Path, out: Path, *options: str) -> dict:
    """tools/predict.py's document of ``scan`` with the tiny model, written into ``out``."""
    [written] = load_tool('predict').main([
        str(TINY),
        str(tiny['checkpoint']),
        str(scan), '--out',
        str(out), '--score-thr', SCORE, '--device', 'cpu', *options
    ])
    return read_predictions(str(written))


def test_room_sized_scan_is_one_window_as_before(tiny, tmp_path):
    """A room-sized scan: one window, the model's single inference on the prepared scan."""
    scan = tiny['rooms'][0]
    document = predict_scan(tiny, scan, tmp_path)
    assert document['detections'], 'the tiny model found nothing to compare'
    prepared = prepare_scan(load_scan(scan))
    cfg = load_config(TINY)
    spec = window_spec_from_config(cfg)
    model = load_model(cfg, str(tiny['checkpoint']), 'cpu')
    detector = ModelDetector(model, float(SCORE))
    _, windows = detect_in_windows(prepared.points, detector, spec, 0.5, progress=False)
    assert len(windows) == 1
    # the single inference of the previous predict.py: shift to the minimum, sample, shift back
    shift = prepared.points[:, :3].min(axis=0)
    shifted = prepared.points.astype(np.float32)
    shifted[:, :3] = prepared.points[:, :3] - shift
    set_random_seed(0)
    result, _ = inference_detector(model, shifted)
    pred = result.pred_instances_3d
    keep = pred.scores_3d >= float(SCORE)
    boxes = pred.bboxes_3d[keep]
    single = Detections(
        np.hstack([boxes.gravity_center.numpy().astype(np.float64) + shift,
                   boxes.dims.numpy().astype(np.float64),
                   boxes.yaw.numpy().astype(np.float64)[:, None]]),
        pred.scores_3d[keep].numpy().astype(np.float64), pred.labels_3d[keep].numpy())
    # then the fragments of one object merged, as the config says
    single = merge_fragments(single, detector.classes, fragment_rule_from_config(cfg),
                             float(SCORE))
    centres, sizes, yaws = prepared.boxes_to_scan(single.boxes[:, :3], single.boxes[:, 3:6],
                                                  single.boxes[:, 6])
    found = document['detections']
    assert len(found) == len(single.scores)
    assert np.allclose([d['center'] for d in found], centres, atol=2e-6)
    assert np.allclose([d['size'] for d in found], sizes, atol=2e-6)
    assert np.allclose([d['yaw'] for d in found], yaws, atol=2e-6)
    assert np.allclose([d['score'] for d in found], single.scores, atol=2e-6)


def test_scan_density_is_brought_to_the_training_density(tiny, tmp_path, capsys):
    """A scan 10x denser than training is thinned to about the training density; every 5th
    point of a room (3x sparser than training) is detected with a warning printed; the fixture
    rooms, at training density (163 points per m^2 for 169), are kept as they are."""
    target = density_from_config(load_config(TINY))
    kept = prepare_scan(load_scan(tiny['rooms'][0]), target_density=target)
    assert np.array_equal(kept.points, prepare_scan(load_scan(tiny['rooms'][0])).points)
    assert kept.report[-1].startswith('density: ') and 'resampled' not in kept.report[-1]
    room = read_scan(tiny['rooms'][0])
    rng = np.random.default_rng(0)
    dense = np.concatenate([room + np.r_[rng.normal(0, 0.005, 3), 0, 0, 0] for _ in range(10)])
    write_scan(tmp_path / 'dense.ply', dense)
    write_scan(tmp_path / 'sparse.ply', room[::5])
    out = tmp_path / 'out'
    load_tool('predict').main([
        str(TINY),
        str(tiny['checkpoint']),
        str(tmp_path / 'dense.ply'),
        str(tmp_path / 'sparse.ply'), '--out',
        str(out), '--score-thr', SCORE, '--device', 'cpu'
    ])
    printed = capsys.readouterr().out
    prepared = prepare_scan(load_scan(tmp_path / 'dense.ply'), target_density=target)
    assert prepared.density > 9 * target
    assert floor_density(prepared.points[:, :3]) == pytest.approx(target, rel=0.1)
    density_lines = [line for line in printed.splitlines() if 'points per m^2 of floor' in line]
    [dense_line] = [line for line in density_lines if line.startswith('dense.ply: ')]
    assert dense_line == f'dense.ply: {prepared.report[-1]}'
    assert f'resampled to {len(prepared.points):,} points' in dense_line
    [sparse_line] = [line for line in density_lines if line.startswith('sparse.ply: ')]
    assert sparse_line.startswith('sparse.ply: warning: density: ')
    assert 'sparser than training, expect weaker detections' in sparse_line
    assert read_predictions(str(out / 'dense.pred.json'))['detections']


def test_scan2cad_detects_at_training_density_and_traces_corners_on_every_point(tiny, tmp_path):
    """scan2cad on a scan denser than training: detection gets it resampled, the corners get
    every point, as ``python -m configurator corners``."""
    room = read_scan(tiny['rooms'][0])
    rng = np.random.default_rng(1)
    dense = np.concatenate([room + np.r_[rng.normal(0, 0.005, 3), 0, 0, 0] for _ in range(10)])
    scan, out = tmp_path / 'dense.ply', tmp_path / 'dense.FCStd'
    write_scan(scan, dense)
    scan2cad = load_tool('scan2cad')
    lines = []
    scan2cad.scan_to_cad(
        scan2cad.parse_args([
            str(scan), '--config',
            str(TINY), '--checkpoint',
            str(tiny['checkpoint']), '--out',
            str(out), '--score-thr', '1.0', '--device', 'cpu'
        ]), lines.append)
    [density] = [line for line in lines if 'points per m^2 of floor' in line]
    assert 'resampled to' in density
    corners = tmp_path / 'corners.json'
    assert configurator_main(['corners', str(scan), '--out', str(corners)]) == 0
    assert read_corners(str(corners)) == read_corners(str(out.with_suffix('.corners.json')))


@pytest.fixture(scope='module')
def overfit(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Three 4 m x 4 m rooms learnt by heart: the tiny config's 24 epochs, as
    tests/test_models/test_tr3d_overfit.py (mAP@0.25 >= 0.9 there), so its boxes are the rooms'
    objects."""
    root = tmp_path_factory.mktemp('overfit')
    write_synthetic_area(root / 'raw', area=1, n_rooms=3, seed=7, points_per_object=300)
    convert_s3dis(root / 'raw', root / 'data', areas=[1])
    run_tool('tools/train.py', TINY, '--work-dir', root / 'work', '--cfg-options',
             *data_options(root / 'data'), 'val_cfg=None', 'val_dataloader=None',
             'val_evaluator=None')
    rooms = sorted((root / 'raw' / S3DIS_DIR / 'Area_1').glob('*/*.txt'))
    return {'checkpoint': root / 'work' / 'epoch_24.pth', 'rooms': rooms}


@pytest.mark.slow
def test_rotated_and_tilted_copy_gives_the_same_objects(overfit, tmp_path):
    """A copy turned 30 deg about z and tilted 3 deg: its boxes, turned back into the
    original's frame, match every box of the original with a 3D IoU of at least 0.5.

    The model knows the room (``overfit``): the 2-iteration ``tiny`` model's boxes are noise
    near its score threshold, which moves with any sub-millimetre change of the points (a
    0.01 degree turn of the prepared points alone leaves 23 of its 699 boxes unmatched)."""
    points = read_scan(overfit['rooms'][0])
    cos, sin = math.cos(math.radians(3.0)), math.sin(math.radians(3.0))
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, cos, -sin], [0.0, sin, cos]])  # about x
    rotation = tilt @ rotation_z(math.radians(30.0))
    turned = points.copy()
    turned[:, :3] = points[:, :3] @ rotation.T
    write_scan(tmp_path / 'original.ply', points)
    write_scan(tmp_path / 'turned.ply', turned)
    threshold = ('--score-thr', '0.3')  # predict's default
    original = predict_scan(overfit, tmp_path / 'original.ply', tmp_path / 'a', *threshold)
    copy = predict_scan(overfit, tmp_path / 'turned.ply', tmp_path / 'b', *threshold)
    original, copy = original['detections'], copy['detections']
    assert len(original) >= 3 and copy
    centres = np.array([d['center'] for d in copy]) @ rotation  # rotation.T applied to each
    directions = np.array([[math.cos(d['yaw']), math.sin(d['yaw']), 0.0] for d in copy])
    directions = directions @ rotation
    yaws = np.arctan2(directions[:, 1], directions[:, 0])
    back = np.column_stack([centres, [d['size'] for d in copy], yaws])
    overlaps = DepthInstance3DBoxes.overlaps(
        _boxes([[*d['center'], *d['size'], d['yaw']] for d in original]), _boxes(back))
    same_class = torch.tensor([[a['class'] == b['class'] for b in copy] for a in original])
    best = (overlaps * same_class).max(dim=1).values
    assert best.min() >= 0.5, f'{int((best < 0.5).sum())} of {len(original)} boxes unmatched'


def _boxes(rows) -> DepthInstance3DBoxes:
    """Gravity-centred boxes (x, y, z, dx, dy, dz, yaw)."""
    return DepthInstance3DBoxes(
        torch.tensor(np.asarray(rows), dtype=torch.float32), origin=(0.5, 0.5, 0.5))


def test_shifted_copy_gives_boxes_shifted_by_exactly_the_offset(tiny, tmp_path):
    points = read_scan(tiny['rooms'][1])
    # off the millimetre grid of the text file, like a real scan: a point exactly on a cell
    # border of the preparation (20 cm cells) may fall either side after the 1e-9 m rounding
    # of georeferenced coordinates, and then one point more or less changes the sampling
    points[:, :3] += np.random.default_rng(0).uniform(1e-5, 4e-4, (len(points), 3))
    local, georeferenced = tmp_path / 'local.ply', tmp_path / 'geo.ply'
    write_scan(local, points)
    shifted = points.copy()
    shifted[:, :3] += OFFSET
    write_scan(georeferenced, shifted)
    near = predict_scan(tiny, local, tmp_path / 'near')['detections']
    far = predict_scan(tiny, georeferenced, tmp_path / 'far')['detections']
    assert near and len(near) == len(far)
    assert [d['class'] for d in near] == [d['class'] for d in far]
    centres = np.array([d['center'] for d in near])
    assert np.abs(np.array([d['center'] for d in far]) - OFFSET - centres).max() < 1e-5
    for key in ('size', 'yaw', 'score'):
        assert np.allclose([d[key] for d in near], [d[key] for d in far], atol=1e-5)


def test_scan2cad_equals_the_stages_one_by_one(tiny, tmp_path):
    scan = tiny['rooms'][0]
    # the untrained model scores hundreds of boxes near 0.01: keep its best 20 for FreeCAD
    voxel = ('--voxel', str(SCAN_VOXEL))  # scan2cad's default, as the corners
    scores = [
        d['score'] for d in predict_scan(tiny, scan, tmp_path / 'scores', *voxel)['detections']
    ]
    threshold = str(sorted(scores, reverse=True)[19])
    out = tmp_path / 'one' / 'room.FCStd'
    out.parent.mkdir()
    assert load_tool('scan2cad').main([
        str(scan), '--config',
        str(TINY), '--checkpoint',
        str(tiny['checkpoint']), '--out',
        str(out), '--score-thr', threshold, '--device', 'cpu'
    ]) == 0
    assert out.is_file()
    stages = tmp_path / 'stages'
    predictions = stages / f'{scan.stem}.pred.json'
    assert predict_scan(tiny, scan, stages, *voxel, '--score-thr', threshold) == read_predictions(
        str(out.with_suffix('.pred.json')))
    assert len(read_predictions(str(predictions))['detections']) >= 10
    corners = stages / 'corners.json'
    assert configurator_main(['corners', str(scan), '--out', str(corners)]) == 0
    assert read_corners(str(corners)) == read_corners(str(out.with_suffix('.corners.json')))
    result = build_document(
        scan, predictions, stages / 'room.FCStd', corners=corners, min_score=float(threshold))
    assert result['objects']
    objects = _document_objects(stages / 'room.FCStd')
    assert len(objects) >= len(result['objects'])
    assert _document_objects(out) == objects


DESCRIBE_SCRIPT = """
import json, os
import FreeCAD
doc = FreeCAD.openDocument(os.environ['DOC'])
rows = []
for o in doc.Objects:
    placement = getattr(o, 'Placement', None)
    shape = getattr(o, 'Shape', None)
    rows.append([o.Name, o.Label, o.TypeId,
                 None if placement is None else [round(v, 6) for v in placement.Base],
                 None if placement is None else round(placement.Rotation.Angle, 9),
                 None if shape is None or shape.isNull() else round(shape.Volume, 6)])
json.dump(rows, open(os.environ['DOC'] + '.json', 'w'))
"""


def _document_objects(path: Path) -> list:
    """The objects of a FreeCAD document (name, label, type, placement, volume), by FreeCAD."""
    script = path.with_suffix('.describe.py')
    script.write_text(DESCRIBE_SCRIPT)
    done = subprocess.run(['freecadcmd', str(script)],
                          env={
                              **os.environ, 'DOC': str(path)
                          },
                          capture_output=True,
                          text=True,
                          timeout=600)
    described = Path(f'{path}.json')
    assert described.is_file(), done.stdout[-2000:] + done.stderr[-2000:]
    return json.loads(described.read_text())


def test_hall_detected_by_windows_with_the_model(tiny):
    """Rooms laid side by side into a 18 m x 10 m hall: the model runs on every window and
    the merged boxes hold no two of one class overlapping more than the NMS threshold."""
    rooms = [read_scan(path) for path in tiny['rooms']]
    tiles = []
    for i in range(3):
        for j in range(2):
            room = rooms[(i + j) % 2].copy()
            room[:, :3] -= room[:, :3].min(axis=0)
            room[:, :2] += [6.0 * i, 5.0 * j]
            tiles.append(room)
    hall = np.concatenate(tiles)
    cfg = load_config(TINY)
    model = load_model(cfg, str(tiny['checkpoint']), 'cpu')
    detector = ModelDetector(model, float(SCORE))
    calls = []

    def counted(points: np.ndarray):
        calls.append(len(points))
        return detector(points)

    found, windows = detect_in_windows(
        hall, counted, window_spec_from_config(cfg), detector.iou_thr, progress=False)
    assert len(windows) == 3 * 2 and len(calls) == 6
    assert len(found.boxes) > 0
    for label in np.unique(found.labels):
        boxes = torch.from_numpy(found.boxes[found.labels == label])
        overlap = pairwise_bev_iou(boxes, boxes).fill_diagonal_(0)
        assert overlap.max() <= detector.iou_thr
    centres = found.boxes[:, :2]
    cores = [np.all((centres >= w.core_low) & (centres < w.core_high), axis=1) for w in windows]
    assert np.all(np.sum(cores, axis=0) == 1)
