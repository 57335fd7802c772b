"""The end-to-end demo at its tiny size (real generator, converter, TR3D, FreeCAD), and the
drawing library of tools/visualize.py."""
from __future__ import annotations

import json
import math
import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from plyfile import PlyData

from synthdet.room_data import (Box, Scan, boxes_from_info, boxes_from_meta,
                                boxes_from_predictions, load_scan)
from synthdet.room_data import write_labelled_ply as write_ply
from synthdet.topview import class_colors, draw_top_view
from tests.tool_process import run_tool
from tools.demo import SIZES

REPO = Path(__file__).resolve().parents[2]
CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
TINY = SIZES['tiny']

# Runs inside FreeCAD: reopen a document and describe its groups and detection parts.
REOPEN_SCRIPT = '''
import json, os
import FreeCAD
doc = FreeCAD.openDocument(os.environ['DEMO_FCSTD'])
groups = {o.Label: [c.Name for c in o.Group] for o in doc.Objects
          if o.TypeId == 'App::DocumentObjectGroup'}
parts = [{'class': o.DetectedClass, 'score': o.Score}
         for o in doc.Objects if hasattr(o, 'DetectedClass')]
walls = doc.getObjectsByLabel('Walls')
json.dump({'objects': len(doc.Objects), 'groups': groups, 'parts': parts,
           'walls_volume': walls[0].Shape.Volume if walls else None},
          open(os.environ['DEMO_RESULT'], 'w'))
'''


def run_demo(work: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([
        sys.executable, 'tools/demo.py', '--size', 'tiny', '--threads', '1', '--work-dir',
        str(work), *extra
    ],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=900)


@pytest.fixture(scope='module')
def demo(tmp_path_factory) -> Path:
    work = tmp_path_factory.mktemp('demo')
    proc = run_demo(work)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return work


def rooms(work: Path) -> list[str]:
    return sorted(p.name[:-len('.pred.json')] for p in (work / 'predictions').glob('*.pred.json'))


def test_tables_hold_numbers(demo):
    table1 = (demo / 'table1.txt').read_text()
    header = next(line for line in table1.splitlines() if 'chair' in line)
    assert header.split() == ['chair', 'table', 'sofa', 'bookcase', 'board', 'yumi', '3dprinter']
    area_rows = {
        int(m.group(1)): line.split()[2:]
        for line in table1.splitlines() if (m := re.match(r'Area (\d+)\s', line))
    }
    assert sorted(area_rows) == [7, 8, 9]
    # area 9's counts equal the converted pickle's instances
    with open(demo / 'data/s3dis_infos_Area_9.pkl', 'rb') as handle:
        infos = pickle.load(handle)
    labels = [i['bbox_label_3d'] for room in infos['data_list'] for i in room['instances']]
    chair = infos['metainfo']['categories']['chair']
    assert area_rows[9][0] == (str(labels.count(chair)) if chair in labels else '-')

    table3 = json.loads((demo / 'table3.json').read_text())
    assert table3['format'] == 'synthdet.table3/1' and table3['classes'] == CLASSES
    for row in ('mAP@0.25', 'mAP@0.5'):
        values = table3['rows'][row]
        assert set(values) == set(CLASSES) | {'mean'}
        assert all(v is None or 0.0 <= v <= 1.0 for v in values.values())
        assert isinstance(values['mean'], float)
    text3 = (demo / 'table3.txt').read_text()
    assert text3.startswith('Table 3') and re.search(r'^mAP@0\.25 +\d\.\d{3}', text3, re.M)
    assert 'mmengine' not in text3 and 'model = dict' not in text3  # the table only, no log

    table4 = json.loads((demo / 'table4.json').read_text())
    assert table4['format'] == 'synthdet.table4/1'
    text4 = (demo / 'table4.txt').read_text()
    assert text4.startswith('Table 4') and re.search(r'truth\s+\d', text4)
    assert (demo / 'table1.txt').read_text().startswith('Table 1')


def test_table3_precision_agrees_with_recall_and_ground_truth(demo):
    """mAP beyond "in [0, 1]": every class of area 9's ground truth is evaluated, the mean is the
    mean of the class APs, and each AP (the area under a precision-recall curve) is at most the
    class's recall and positive exactly when the recall is."""
    table3 = json.loads((demo / 'table3.json').read_text())
    with open(demo / 'data/s3dis_infos_Area_9.pkl', 'rb') as handle:
        infos = pickle.load(handle)
    names = {index: name for name, index in infos['metainfo']['categories'].items()}
    present = {
        names[instance['bbox_label_3d']]
        for room in infos['data_list']
        for instance in room['instances']
    } & set(CLASSES)
    assert present
    for row, key in (('mAP@0.25', '0.25'), ('mAP@0.5', '0.50')):
        values = table3['rows'][row]
        evaluated = [cls for cls in CLASSES if values[cls] is not None]
        assert present <= set(evaluated), (row, present, evaluated)
        assert values['mean'] == pytest.approx(np.mean([values[cls] for cls in evaluated]))
        for cls in evaluated:
            recall = table3['metrics'][f'{cls}_rec_{key}']
            assert values[cls] <= recall + 1e-6, (row, cls, values[cls], recall)
            assert (values[cls] > 0) == (recall > 0), (row, cls, values[cls], recall)
    # the test step keeps the model's 1000 best locations: some boxes overlap true objects
    assert table3['rows']['mAP@0.25']['mean'] > 0


def aligned_box(box: dict) -> np.ndarray:
    """(min xyz, max xyz) of the axis-aligned box enclosing a centre/size/yaw box."""
    c, s = abs(math.cos(box.get('yaw', 0.0))), abs(math.sin(box.get('yaw', 0.0)))
    dx, dy, dz = box['size']
    half = np.array([c * dx + s * dy, s * dx + c * dy, dz]) / 2
    return np.stack([np.asarray(box['center']) - half, np.asarray(box['center']) + half])


def iou_3d(a: np.ndarray, b: np.ndarray) -> float:
    inter = np.prod(np.clip(np.minimum(a[1], b[1]) - np.maximum(a[0], b[0]), 0, None))
    return float(inter / (np.prod(a[1] - a[0]) + np.prod(b[1] - b[0]) - inter))


def test_table4_counts_the_predicted_detections(demo):
    """Table 4 recounted from the predictions JSON and meta.json: detections by decreasing
    score, each matched to the unmatched true box of its class with the highest IoU, correct
    from IoU 0.25 (true boxes enclosed axis-aligned, as the detector's ground truth)."""
    table4 = json.loads((demo / 'table4.json').read_text())
    assert table4['score_thr'] == TINY.score_thr and table4['iou_thr'] == 0.25
    counted = 0
    for name in rooms(demo):
        meta = json.loads(next((demo / 'data').rglob(f'Area_9/{name}/meta.json')).read_text())
        detections = json.loads((demo / f'predictions/{name}.pred.json').read_text())['detections']
        [scan] = [s for s in table4['scans'] if Path(s['scan']).name == f'{name}.txt']
        [model] = scan['models'].values()
        for cls in CLASSES:
            truth = [aligned_box(o['box']) for o in meta['objects'] if o['class'] == cls]
            assert scan['truth'][cls] == len(truth)
            unmatched, correct, incorrect = list(range(len(truth))), 0, 0
            for detection in detections:  # already in decreasing score order
                if detection['class'] != cls or detection['score'] < table4['score_thr']:
                    continue
                box = aligned_box(detection)
                ious = [iou_3d(box, truth[k]) for k in unmatched]
                if ious and max(ious) >= 0.25:
                    unmatched.pop(int(np.argmax(ious)))
                    correct += 1
                else:
                    incorrect += 1
            assert model[cls] == {'correct': correct, 'incorrect': incorrect}, (name, cls)
            counted += correct + incorrect
    assert counted > 0  # the real detections reach Table 4


def test_pictures_decode(demo):
    names = rooms(demo)
    assert names
    for name in names:
        for png in (demo / f'rooms/{name}.png', demo / f'rooms/{name}.corners.png'):
            with Image.open(png) as image:
                pixels = np.asarray(image.convert('RGB'), dtype=float)
            assert pixels.shape[0] > 300 and pixels.shape[1] > 300
            assert pixels.std() > 10, f'{png} is blank'
        ply = PlyData.read(str(demo / f'rooms/{name}.ply'))
        assert ply['vertex'].count > 1000


def test_predictions_corners_in_scan_frame(demo):
    for name in rooms(demo):
        meta = json.loads(next((demo / 'data').rglob(f'Area_9/{name}/meta.json')).read_text())
        corners = json.loads((demo / f'rooms/{name}.corners.json').read_text())
        truth = np.array(meta['room']['polygon'])
        found = np.array(corners['corners'])
        assert len(found) == len(truth)
        # every true corner has a detected corner within 5 cm
        distances = np.linalg.norm(truth[:, None] - found[None], axis=2).min(axis=1)
        assert distances.max() < 0.05
        predictions = json.loads((demo / f'predictions/{name}.pred.json').read_text())
        assert predictions['format'] == 'synthdet.predictions/1'
        detections = predictions['detections']
        # the barely trained model's boxes do reach the JSON (scores just above its 1 % prior)
        assert detections, f'{name}: no detection reached the predictions JSON'
        assert len(detections) <= len(CLASSES) * TINY.predict_candidates
        scores = [detection['score'] for detection in detections]
        assert scores == sorted(scores, reverse=True)
        for detection in detections:
            assert detection['class'] in CLASSES and detection['score'] >= TINY.score_thr
            assert len(detection['center']) == 3 and min(detection['size']) > 0


def test_freecad_documents_reopen(demo, tmp_path):
    script = tmp_path / 'reopen.py'
    script.write_text(REOPEN_SCRIPT)
    for name in rooms(demo):
        result = tmp_path / f'{name}.json'
        env = dict(
            os.environ, DEMO_FCSTD=str(demo / f'rooms/{name}.FCStd'), DEMO_RESULT=str(result))
        subprocess.run(['freecadcmd', str(script)], env=env, capture_output=True, timeout=300)
        assert result.is_file(), 'FreeCAD could not reopen the document'
        found = json.loads(result.read_text())
        assert {'Room', 'Furniture', 'Equipment'} <= set(found['groups'])
        assert len(found['groups']['Room']) >= 3 and found['walls_volume'] > 0
        predictions = json.loads((demo / f'predictions/{name}.pred.json').read_text())
        # every detection is one part of its class with its score (where it stands is up to
        # the FreeCAD side: on the floor or a table, inside the walls)
        parts = sorted((part['class'], round(part['score'], 6)) for part in found['parts'])
        expected = sorted((d['class'], d['score']) for d in predictions['detections'])
        assert parts and parts == expected


def test_report_links_every_artefact(demo):
    report = (demo / 'REPORT.md').read_text()
    for heading in ('Table 1', 'Table 3', 'Table 4'):
        assert f'## {heading}' in report
    assert re.search(r'\| mAP@0\.25 \| (\d\.\d{3}|-) \|', report)
    assert 'Checkpoint `train/epoch_1.pth` (the final epoch)' in report  # tiny trains 1 epoch
    links = re.findall(r'\]\(([^)]+)\)', report)
    for name in rooms(demo):
        for suffix in ('.png', '.corners.png', '.FCStd', '.ply'):
            assert f'rooms/{name}{suffix}' in links
        assert f'predictions/{name}.pred.json' in links
        assert str(demo / f'rooms/{name}.FCStd') in report
    assert all((demo / link).is_file() for link in links)


def test_the_shipped_model_turns_the_demo_scan_into_a_document_first(demo):
    document = demo / 'scan' / 'factory_1.FCStd'
    detections = json.loads(document.with_suffix('.pred.json').read_text())['detections']
    assert detections and {d['class'] for d in detections} <= set(CLASSES)
    with Image.open(document.with_suffix('.FCStd.png')) as image:
        assert np.asarray(image.convert('RGB'), dtype=float).std() > 10
    report = (demo / 'REPORT.md').read_text()
    first = report.index('## A scan to a FreeCAD document with the shipped model')
    assert first < report.index('## Table 1')
    assert '](scan/factory_1.FCStd.png)' in report


def test_second_run_skips_every_step_and_guards_the_work_dir(demo):
    proc = run_demo(demo)
    assert proc.returncode == 0, proc.stderr[-2000:]
    skipped = re.findall(r'\[demo \d+/\d+\] (\w+): outputs exist, skipped', proc.stdout)
    assert skipped == [
        'scan2cad', 'generate', 'convert', 'table1', 'train', 'test', 'predict', 'table4', 'corners',
        'freecad', 'pictures'
    ]
    other = subprocess.run(
        [sys.executable, 'tools/demo.py', '--size', 'demo', '--work-dir',
         str(demo)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120)
    assert other.returncode == 1 and 'choose another --work-dir' in other.stderr


# ---------------------------------------------------------------- the drawing library
def test_footprint_rotates_about_the_centre():
    box = Box('table', (1.0, 2.0, 0.4), (2.0, 1.0, 0.8), yaw=math.pi / 2)
    corners = box.footprint()
    assert np.allclose(corners.mean(axis=0), [1.0, 2.0])
    assert np.allclose(np.sort(corners[:, 0]), [0.5, 0.5, 1.5, 1.5])  # length now along y
    assert np.allclose(np.sort(corners[:, 1]), [1.0, 1.0, 3.0, 3.0])


def write_room(root: Path) -> Path:
    """A small S3DIS room: a floor and one chair, 'x y z r g b' lines, with a meta.json."""
    rng = np.random.default_rng(0)
    annotations = root / 'Area_9/lab_1/Annotations'
    annotations.mkdir(parents=True)
    floor = np.c_[rng.uniform(0, 4, (500, 2)), np.zeros(500), np.full((500, 3), 128)]
    chair = np.c_[rng.uniform(1, 1.5, (200, 2)),
                  rng.uniform(0, 0.9, 200),
                  np.tile([200, 50, 50], (200, 1))]
    for name, points in (('floor_1', floor), ('chair_1', chair)):
        np.savetxt(annotations / f'{name}.txt', points, fmt='%.3f %.3f %.3f %d %d %d')
    room = annotations.parent / 'lab_1.txt'
    np.savetxt(room, np.vstack([floor, chair]), fmt='%.3f %.3f %.3f %d %d %d')
    (annotations.parent / 'meta.json').write_text(
        json.dumps({
            'format':
            'synthdet.room/1',
            'room': {
                'polygon': [[0, 0], [0, 4], [4, 4], [4, 0]],
                'height': 3.0
            },
            'objects': [{
                'instance': 'chair_1',
                'class': 'chair',
                'box': {
                    'center': [1.25, 1.25, 0.45],
                    'size': [0.5, 0.5, 0.9],
                    'yaw': 0.3
                }
            }]
        }))
    return room


def test_scan_classes_from_annotations_and_ply(tmp_path):
    room = write_room(tmp_path)
    scan = load_scan(room)
    assert len(scan.points) == 700
    assert (scan.labels == 'chair').sum() == 200 and (scan.labels == 'floor').sum() == 500
    write_ply(tmp_path / 'room.ply', scan)
    vertex = PlyData.read(str(tmp_path / 'room.ply'))['vertex']
    assert np.allclose(vertex['x'], scan.points[:, 0], atol=1e-6)
    assert (np.asarray(vertex['class']) == 8).sum() == 200  # chair's semantic id
    assert set(np.asarray(vertex['red'])) == {128, 200}


def test_boxes_from_meta_info_and_predictions(tmp_path):
    room = write_room(tmp_path)
    [box] = boxes_from_meta(room.parent / 'meta.json')
    assert box.label == 'chair' and box.yaw == pytest.approx(0.3)
    info = {
        'metainfo': {
            'categories': {
                'table': 0,
                'chair': 1
            }
        },
        'data_list': [{
            'lidar_points': {
                'lidar_path': 'Area_9_lab_1.bin'
            },
            'instances': [{
                'bbox_3d': [1, 2, 0.4, 2, 1, 0.8],
                'bbox_label_3d': 0
            }]
        }]
    }
    with open(tmp_path / 'infos.pkl', 'wb') as handle:
        pickle.dump(info, handle)
    [box] = boxes_from_info(tmp_path / 'infos.pkl', 'Area_9_lab_1.bin')
    assert box.label == 'table' and box.size == (2.0, 1.0, 0.8) and box.yaw == 0.0
    with pytest.raises(ValueError, match='no room with lidar_path'):
        boxes_from_info(tmp_path / 'infos.pkl', 'Area_9_lab_2.bin')
    predictions = tmp_path / 'p.json'
    predictions.write_text(
        json.dumps({
            'format':
            'synthdet.predictions/1',
            'detections': [{
                'class': 'chair',
                'score': 0.9,
                'center': [1, 1, 0.4],
                'size': [0.5, 0.5, 0.8]
            }, {
                'class': 'chair',
                'score': 0.1,
                'center': [3, 3, 0.4],
                'size': [0.5, 0.5, 0.8]
            }]
        }))
    assert len(boxes_from_predictions(predictions, 0.3)) == 1
    predictions.write_text('{"format": "synthdet.predictions/2"}')
    with pytest.raises(ValueError, match='p.json: format: unsupported format'):
        boxes_from_predictions(predictions)


def test_top_view_draws_class_colors_and_boxes(tmp_path):
    room = write_room(tmp_path)
    scan = load_scan(room)
    out = tmp_path / 'view.png'
    draw_top_view(out, scan, boxes_from_meta(room.parent / 'meta.json'),
                  [Box('table', (3.0, 3.0, 0.4), (0.6, 0.6, 0.8), score=0.8)])
    with Image.open(out) as image:
        pixels = np.asarray(image.convert('RGB')).reshape(-1, 3)
    chair = np.round(class_colors(np.array(['chair']))[0] * 255)
    table = np.round(class_colors(np.array(['table']))[0] * 255)
    assert (np.abs(pixels - chair).max(axis=1) <= 2).sum() > 200  # chair points and GT box
    assert (np.abs(pixels - table).max(axis=1) <= 2).sum() > 20  # the predicted box outline
    unlabelled = Scan(scan.points, None, 'raw')  # no annotations: colored by RGB
    draw_top_view(tmp_path / 'rgb.png', unlabelled)
    with Image.open(tmp_path / 'rgb.png') as image:
        pixels = np.asarray(image.convert('RGB')).reshape(-1, 3)
    assert (np.abs(pixels - [200, 50, 50]).max(axis=1) <= 2).sum() > 50


def test_visualize_cli_writes_png_and_ply_and_names_bad_files(tmp_path):
    room = write_room(tmp_path)
    proc = run_tool('tools/visualize.py', room, '--gt', room.parent / 'meta.json', '--out',
                    tmp_path / 'v.png', '--ply', tmp_path / 'v.ply', timeout=120)
    assert '700 points, 1 ground-truth' in proc.stdout
    with Image.open(tmp_path / 'v.png') as image:
        assert image.size[0] > 300
    assert PlyData.read(str(tmp_path / 'v.ply'))['vertex'].count == 700
    bad = tmp_path / 'bad.pred.json'
    bad.write_text('{"format": "synthdet.predictions/1", "detections": [{"class": "chair"}]}')
    proc = subprocess.run([
        sys.executable, 'tools/visualize.py',
        str(room), '--pred',
        str(bad), '--out',
        str(tmp_path / 'w.png')
    ],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=120)
    assert proc.returncode == 2 and 'bad.pred.json: detections[0]: missing key' in proc.stderr
