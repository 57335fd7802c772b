"""The evaluation of labelled scans: the labels contract, the counting rule on rotated boxes, and
``tools/eval_scans.py`` end to end on generated rooms written as labelled scans.

The end-to-end tests use the tiny config's model with freshly initialised weights saved as a
checkpoint (its detections are arbitrary but real, and land in the scan's own frame): labels
made from its own detections of a scan, turned boxes included, must then all be found.
"""
import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Polygon

from projects.synthdet.evaluation.real_scans import (
    PHANTOM_CLASSES, REAL_SCANS_FORMAT, LabelsError, count_scan, evaluate_detections,
    find_labelled_scans, match_greedy, rotated_iou_3d, summary_line)
from synthdet.contracts import (LABELS_FORMAT, SchemaError, read_labels, validate_labels,
                                write_labels)
from synthdet.geometry import box_corners_xy
from synthdet.scan_io import read_scan, write_scan
from tests.checkpoints import initial_checkpoint
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from tests.test_repository.test_makefile import exp2_dry_run

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']


def labels(boxes: list[dict], classes: list[str] = CLASSES, scan: str = 'room.ply') -> dict:
    return {'format': LABELS_FORMAT, 'scan': scan, 'classes': classes, 'boxes': boxes}


def box(cls: str, center, size, yaw: float = 0.0, score: float | None = None) -> dict:
    item = {'class': cls, 'center': list(center), 'size': list(size), 'yaw': yaw}
    return item if score is None else {**item, 'score': score}


# --------------------------------------------------------------------------- labels contract


def test_labels_round_trip_keeps_other_keys(tmp_path: Path) -> None:
    document = labels([box('table', [1.0, 2.0, 0.4], [1.6, 0.8, 0.8], 0.3)])
    document['source'] = 'a person'
    path = tmp_path / 'room.labels.json'
    write_labels(path, document)
    read = read_labels(path)
    assert read['boxes'] == document['boxes'] and read['source'] == 'a person'
    assert read['classes'] == CLASSES and read['format'] == LABELS_FORMAT
    # yaw may be left out: 0
    del document['boxes'][0]['yaw']
    assert validate_labels(document)['boxes'][0]['yaw'] == 0.0


@pytest.mark.parametrize('change, message', [
    (lambda d: d.update(format='synthdet.labels/0'), 'format: unsupported format'),
    (lambda d: d.pop('classes'), 'missing key "classes"'),
    (lambda d: d.update(classes=[]), 'classes: expected a non-empty list'),
    (lambda d: d.update(classes=['table', 'table']), "classes[1]: class 'table' is listed twice"),
    (lambda d: d['boxes'].append(box('sofa', [0, 0, 0], [1, 1, 1])),
     "boxes[1].class: class 'sofa' is not in \"classes\""),
    (lambda d: d['boxes'][0].update(size=[1.0, float('nan'), 1.0]),
     'boxes[0].size[1]: expected a finite number'),
    (lambda d: d['boxes'][0].update(size=[1.0, 0.0, 1.0]), 'boxes[0].size[1]: expected positive'),
    (lambda d: d['boxes'][0].pop('center'), 'boxes[0]: missing key "center"'),
    (lambda d: d.update(boxes={}), 'boxes: expected a list'),
])
def test_labels_validation_names_the_bad_value(change, message: str) -> None:
    document = labels([box('table', [1.0, 2.0, 0.4], [1.6, 0.8, 0.8])], classes=['table'])
    change(document)
    with pytest.raises(SchemaError) as error:
        validate_labels(document, 'room.labels.json')
    assert str(error.value).startswith('room.labels.json: ') and message in str(error.value)


def test_labels_file_with_bad_json_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / 'room.labels.json'
    path.write_text('{"format": "synthdet.labels/1",\n "classes": [,]}\n')
    with pytest.raises(SchemaError, match=r'room\.labels\.json:2:\d+: invalid JSON'):
        read_labels(path)


# --------------------------------------------------------------------------- the counting rule


def shapely_iou(a: list[float], b: list[float]) -> float:
    """3D IoU of two (x, y, z, dx, dy, dz, yaw) boxes from their footprint polygons."""
    pa, pb = (Polygon(box_corners_xy(x[:3], x[3:6], x[6])) for x in (a, b))
    low = max(a[2] - a[5] / 2, b[2] - b[5] / 2)
    high = min(a[2] + a[5] / 2, b[2] + b[5] / 2)
    inter = pa.intersection(pb).area * max(0.0, high - low)
    return inter / (pa.area * a[5] + pb.area * b[5] - inter)


def test_rotated_iou_matches_the_footprint_polygons() -> None:
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.uniform(0, 1, (40, 3)), rng.uniform(0.3, 2.0, (40, 3)),
                         rng.uniform(-math.pi, math.pi, 40)])
    b = a[rng.permutation(40)] + np.r_[rng.normal(0, 0.2, 3), [0, 0, 0, 0]]
    ious = rotated_iou_3d(a, b)
    expected = np.array([[shapely_iou(x, y) for y in b] for x in a])
    assert (expected > 0.05).sum() > 40  # many real overlaps among them
    np.testing.assert_allclose(ious, expected, atol=2e-3)
    # yaw turns counter-clockwise: a long box and its copy shifted along its own axis
    long = [0.0, 0.0, 0.5, 2.0, 0.4, 1.0, 0.5]
    along = [0.8 * math.cos(0.5), 0.8 * math.sin(0.5), 0.5, 2.0, 0.4, 1.0, 0.5]
    assert rotated_iou_3d(np.array([long]), np.array([along]))[0, 0] == pytest.approx(
        1.2 / 2.8, abs=2e-3)


def test_rotated_iou_of_boxes_moved_along_their_own_axis() -> None:
    """Long edges on one line (mmcv's box_iou_rotated loses overlap there): still exact."""
    rng = np.random.default_rng(0)
    yaws, shifts = rng.uniform(-3, 3, 100), rng.uniform(-0.9, 0.9, 100)
    a = np.column_stack([np.zeros((100, 2)), np.full(100, 0.5), np.tile([2.0, 0.4, 1.0], (100, 1)),
                         yaws])
    b = a.copy()
    b[:, 0], b[:, 1] = shifts * np.cos(yaws), shifts * np.sin(yaws)
    expected = (2 - np.abs(shifts)) / (2 + np.abs(shifts))  # overlap (2 - s) x 0.4 of 0.8 each
    np.testing.assert_allclose(np.diag(rotated_iou_3d(a, b)), expected, atol=1e-9)


def test_detection_equal_to_truth_is_found_and_45_degrees_off_is_not() -> None:
    truth = box('table', [3.0, -2.0, 0.4], [2.0, 0.5, 0.8], yaw=0.7)
    same = box('table', truth['center'], truth['size'], yaw=0.7, score=0.9)
    turned = box('table', truth['center'], truth['size'], yaw=0.7 + math.pi / 4, score=0.9)
    # thin boxes crossing at 45 degrees: 0.25 / sin 45 m^2 shared of 1 m^2 each
    iou = rotated_iou_3d(np.array([[3.0, -2.0, 0.4, 2.0, 0.5, 0.8, 0.7]]),
                         np.array([[3.0, -2.0, 0.4, 2.0, 0.5, 0.8, 0.7 + math.pi / 4]]))[0, 0]
    assert iou == pytest.approx(0.3536 / (2 - 0.3536), abs=2e-3) and iou < 0.25
    found = count_scan(labels([truth]), [same], CLASSES, 0.3)['cells']['table']
    assert found == {'truth': 1, 'found': 1, 'false': 0}
    missed = count_scan(labels([truth]), [turned], CLASSES, 0.3)['cells']['table']
    assert missed == {'truth': 1, 'found': 0, 'false': 1}


def test_greedy_by_score_and_duplicates_are_false() -> None:
    truth = np.array([[0, 0, 0.5, 1, 1, 1, 0], [3, 0, 0.5, 1, 1, 1, 0]], dtype=float)
    # the best detection sits between both boxes' match: the higher score takes box 0 first
    detections = np.array([[0.1, 0, 0.5, 1, 1, 1, 0], [0, 0, 0.5, 1, 1, 1, 0],
                           [3.05, 0, 0.5, 1, 1, 1, 0]], dtype=float)
    assert match_greedy(truth, detections).tolist() == [True, False, True]


def test_unknown_class_is_neither_found_nor_false() -> None:
    scan = labels([box('table', [0, 0, 0.4], [1, 1, 0.8])], classes=['table', 'chair'])
    detections = [
        box('sofa', [5, 5, 0.4], [2, 1, 0.8], score=0.9),
        box('yumi', [2, 2, 0.5], [0.6, 0.6, 1.0], score=0.8),
        box('chair', [4, 4, 0.4], [0.5, 0.5, 0.8], score=0.7),
    ]
    row = count_scan(scan, detections, CLASSES, 0.3)
    assert row['cells']['sofa'] is None and row['cells']['yumi'] is None
    assert row['cells']['chair'] == {'truth': 0, 'found': 0, 'false': 1}
    assert row['cells']['table'] == {'truth': 1, 'found': 0, 'false': 0}
    assert row['false_positives'] == 1 and row['phantoms'] == 0


def test_phantoms_are_false_yumis_and_printers_of_listed_classes() -> None:
    scan = labels([box('yumi', [0, 0, 0.5], [0.6, 0.6, 1.0])])
    detections = [
        box('yumi', [0, 0, 0.5], [0.6, 0.6, 1.0], score=0.9),  # the true one: found
        box('yumi', [3, 0, 0.5], [0.6, 0.6, 1.0], score=0.8),
        box('3dprinter', [1, 2, 0.9], [0.5, 0.5, 0.5], score=0.5),
        box('3dprinter', [2, 2, 0.9], [0.5, 0.5, 0.5], score=0.2),  # below the threshold
    ]
    row = count_scan(scan, detections, CLASSES, 0.3)
    assert row['cells']['yumi'] == {'truth': 1, 'found': 1, 'false': 1}
    assert row['cells']['3dprinter'] == {'truth': 0, 'found': 0, 'false': 1}
    assert row['phantoms'] == 2 and row['false_positives'] == 2


def test_figures_over_a_folder() -> None:
    room_a = labels([box('table', [0, 0, 0.4], [1.2, 0.8, 0.8], 0.2),
                     box('chair', [2, 0, 0.4], [0.5, 0.5, 0.8])])
    room_b = labels([box('table', [0, 0, 0.4], [1.2, 0.8, 0.8])], classes=['table'])
    entries = [
        ('a.ply', room_a, [box('table', [0, 0, 0.4], [1.2, 0.8, 0.8], 0.2, 0.9),
                           box('3dprinter', [5, 5, 1], [0.5, 0.5, 0.5], score=0.6),
                           box('chair', [2, 0, 0.4], [0.5, 0.5, 0.8], score=0.1)]),
        ('b.pcd', room_b, [box('table', [4, 0, 0.4], [1.2, 0.8, 0.8], score=0.8),
                           box('yumi', [1, 1, 0.5], [0.6, 0.6, 1.0], score=0.9)]),
    ]
    result = evaluate_detections(entries, ['table', 'chair', 'sofa'], score_thr=0.3)
    assert result['format'] == REAL_SCANS_FORMAT and result['rooms'] == 2
    assert result['classes'] == ['table', 'chair', 'sofa', *PHANTOM_CLASSES]
    assert result['total']['table'] == {'truth': 2, 'found': 1, 'false': 1}
    assert result['total']['chair'] == {'truth': 1, 'found': 0, 'false': 0}
    assert result['total']['yumi'] == {'truth': 0, 'found': 0, 'false': 0}  # b: unknown
    assert result['recall'] == {'table': 0.5, 'chair': 0.0, 'sofa': None, 'yumi': None,
                                '3dprinter': None}
    assert result['overall_recall'] == pytest.approx(1 / 3)
    assert result['false_positives'] == 2 and result['false_positives_per_room'] == 1.0
    assert result['phantoms'] == 1
    # AP over all scores: the table's detection in b is ranked below the true one in a
    assert result['ap']['0.25']['table'] == pytest.approx(0.5)
    assert result['ap']['0.25']['chair'] == pytest.approx(1.0)  # its score 0.1 still ranks
    assert set(result['ap']['0.5']) == {'table', 'chair'}
    assert result['map']['0.25'] == pytest.approx(0.75)
    assert summary_line(result) == ('real scans: recall 0.333 at IoU 0.25, 1.00 false positives '
                                    'per room, 1 phantom yumi/3d printer (2 rooms)')


# --------------------------------------------------------------------------- scans and folders


def test_folders_skip_unlabelled_scans_and_named_scans_need_labels(tmp_path: Path) -> None:
    points = np.column_stack([np.random.default_rng(0).uniform(0, 3, (100, 3)),
                              np.full((100, 3), 128.0)])
    for name in ('a.ply', 'b.xyz', 'c.pcd'):
        write_scan(tmp_path / name, points)
    write_labels(tmp_path / 'a.labels.json', labels([], scan='a.ply'))
    write_labels(tmp_path / 'b.labels.json', labels([], scan='b.xyz'))
    write_labels(tmp_path / 'd.labels.json', labels([], scan='d.ply'))
    found, skipped = find_labelled_scans([tmp_path])
    assert [item.scan.name for item in found] == ['a.ply', 'b.xyz']
    assert skipped == [f'{tmp_path / "c.pcd"}: no c.labels.json beside it, skipped',
                       f'{tmp_path / "d.labels.json"}: no scan d.* beside it, skipped']
    with pytest.raises(LabelsError, match=r'c\.pcd: no labels file .*c\.labels\.json'):
        find_labelled_scans([tmp_path / 'c.pcd'])
    write_scan(tmp_path / 'a.xyz', points)
    with pytest.raises(LabelsError, match='have the same name'):
        find_labelled_scans([tmp_path])
    (tmp_path / 'empty').mkdir()
    with pytest.raises(LabelsError, match='empty: no scan with a'):
        find_labelled_scans([tmp_path / 'empty'])


# --------------------------------------------------------------------------- end to end


def rotate_about_z(xyz: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return xyz @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T


@pytest.fixture(scope='module')
def scans(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Two generated rooms as labelled scans (PLY in the room's frame, and XYZ turned by 30
    degrees and moved), and a checkpoint of the tiny model with initialised weights."""
    root = tmp_path_factory.mktemp('eval_scans')
    truth = write_synthetic_area(root / 'raw', area=1, n_rooms=2, seed=5, points_per_object=300)
    folder = root / 'scans'
    folder.mkdir()
    turn, shift = math.radians(30), np.array([7.0, -4.0, 0.0])
    for index, (room, boxes) in enumerate(truth.items()):
        points = read_scan(root / 'raw' / S3DIS_DIR / 'Area_1' / room / f'{room}.txt')
        low, high = (np.array([b[k] for b in boxes]) for k in ('min', 'max'))
        centers, sizes, yaw = (low + high) / 2, high - low, 0.0
        name = f'{room}.ply'
        if index == 1:  # turned and moved: boxes turn with the scan
            points[:, :3] = rotate_about_z(points[:, :3], turn) + shift
            centers, yaw, name = rotate_about_z(centers, turn) + shift, turn, f'{room}.xyz'
        write_scan(folder / name, points)
        write_labels(folder / f'{room}.labels.json', labels(
            [box(b['class'], c, s, yaw) for b, c, s in zip(boxes, centers, sizes)], scan=name))
    write_scan(folder / 'unlabelled.ply', points)

    checkpoint = initial_checkpoint(TINY, root / 'initialised.pth', CLASSES)
    return dict(root=root, folder=folder, checkpoint=checkpoint)


def run_eval(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, 'tools/eval_scans.py', str(TINY), *map(str, args)],
                          cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, 'OMP_NUM_THREADS': '1'})


def eval_in_process(*args) -> dict:
    """tools/eval_scans.py's main in this process (the libraries are loaded once)."""
    spec = importlib.util.spec_from_file_location('synthdet_tools_eval_scans',
                                                  REPO / 'tools' / 'eval_scans.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main([str(TINY), *map(str, args)])


def last_line(proc: subprocess.CompletedProcess) -> str:
    return proc.stderr.strip().splitlines()[-1]


@pytest.mark.slow
def test_cli_evaluates_a_folder_end_to_end(scans: dict) -> None:
    out = scans['root'] / 'out'
    proc = run_eval(scans['checkpoint'], scans['folder'], '--out', out, '--score-thr', '0.05',
                    '--device', 'cpu', '--cfg-options', 'model.test_cfg.score_thr=0.0')
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert f'{scans["folder"] / "unlabelled.ply"}: no unlabelled.labels.json beside it, ' \
        'skipped' in lines
    result = json.loads((out / 'real_scans.json').read_text())
    assert lines[-1] == summary_line(result)
    assert (out / 'real_scans.txt').read_text().splitlines()[-1] == lines[-1]
    assert result['rooms'] == 2 and result['model'] == 'tiny'
    assert [row['scan'] for row in result['scans']] == ['lab_1.xyz', 'office_1.ply']
    assert result['truth'] == sum(len(read_labels(p)['boxes'])
                                  for p in scans['folder'].glob('*.labels.json'))
    # the counts are those of the written detections (>= the threshold) against the labels
    entries = []
    for row in result['scans']:
        stem = Path(row['scan']).stem
        predictions = json.loads((out / f'{stem}.pred.json').read_text())
        assert predictions['detections'] and predictions['classes'] == CLASSES
        assert min(d['score'] for d in predictions['detections']) >= 0.05
        # in the scan's own frame (the XYZ scan lies 3 to 11 m in x, -6 to 0 m in y)
        points = read_scan(scans['folder'] / row['scan'])
        centres = np.array([d['center'] for d in predictions['detections']])
        assert np.all(centres[:, :2] > points[:, :2].min(axis=0) - 1.0)
        assert np.all(centres[:, :2] < points[:, :2].max(axis=0) + 1.0)
        entries.append((row['scan'], read_labels(scans['folder'] / f'{stem}.labels.json'),
                        predictions['detections']))
        picture = out / f'{stem}.png'
        assert picture.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    recount = evaluate_detections(entries, CLASSES, 0.05)
    assert recount['scans'] == result['scans'] and recount['total'] == result['total']
    assert not list(out.glob('.*tmp*')), 'no temporary file left behind'


@pytest.mark.slow
def test_labels_made_from_the_detections_are_all_found(scans: dict, tmp_path: Path) -> None:
    """Each scan's own detections as its labels (the XYZ one turned and moved): all found, no
    false positive; the same labels listing only tables leave every other detection out."""
    first = tmp_path / 'first'
    eval_in_process(scans['checkpoint'], scans['folder'], '--out', first, '--score-thr', '0.05',
                    '--cfg-options', 'model.test_cfg.score_thr=0.0')
    folder = tmp_path / 'scans'
    folder.mkdir()
    detected = {}
    for scan in sorted(scans['folder'].iterdir()):
        if scan.name.startswith('unlabelled') or scan.name.endswith('.labels.json'):
            continue
        (folder / scan.name).symlink_to(scan)
        found = json.loads((first / f'{scan.stem}.pred.json').read_text())['detections']
        detected[scan.name] = found
        write_labels(folder / f'{scan.stem}.labels.json',
                     labels([{k: d[k] for k in ('class', 'center', 'size', 'yaw')}
                             for d in found], scan=scan.name))
    second = tmp_path / 'second'
    result = eval_in_process(scans['checkpoint'], folder, '--out', second, '--score-thr', '0.05',
                             '--cfg-options', 'model.test_cfg.score_thr=0.0')
    assert json.loads((second / 'real_scans.json').read_text()) == result
    total = sum(len(found) for found in detected.values())
    assert total > 0 and result['truth'] == total
    assert result['found'] == total and result['false_positives'] == 0
    assert result['overall_recall'] == 1.0 and result['phantoms'] == 0

    for name in detected:  # only tables labelled: the other classes are unknown
        stem = Path(name).stem
        document = read_labels(folder / f'{stem}.labels.json')
        document['classes'] = ['table']
        document['boxes'] = [b for b in document['boxes'] if b['class'] == 'table']
        write_labels(folder / f'{stem}.labels.json', document)
    result = eval_in_process(scans['checkpoint'], folder, '--out', tmp_path / 'third',
                             '--score-thr', '0.05', '--cfg-options',
                             'model.test_cfg.score_thr=0.0')
    tables = sum(d['class'] == 'table' for found in detected.values() for d in found)
    assert result['truth'] == result['found'] == tables and result['false_positives'] == 0
    assert all(result['total'][c] is None for c in CLASSES if c != 'table')


@pytest.mark.slow
def test_cli_bad_inputs_exit_2_naming_the_file(scans: dict, tmp_path: Path) -> None:
    unlabelled = scans['folder'] / 'unlabelled.ply'
    proc = run_eval(scans['checkpoint'], unlabelled, '--out', tmp_path / 'a')
    assert proc.returncode == 2  # the last line (the libraries may warn while loading)
    assert last_line(proc) == (f'eval_scans.py: error: {unlabelled}: no labels file '
                               f'{scans["folder"] / "unlabelled.labels.json"} beside it')
    folder = tmp_path / 'bad'
    folder.mkdir()
    (folder / 'room.ply').symlink_to(unlabelled)
    (folder / 'room.labels.json').write_text('{"format": "synthdet.labels/1", "scan": }\n')
    proc = run_eval(scans['checkpoint'], folder, '--out', tmp_path / 'b')
    assert proc.returncode == 2
    assert last_line(proc).startswith(f'eval_scans.py: error: {folder / "room.labels.json"}:1:')
    assert 'invalid JSON' in last_line(proc)
    (folder / 'room.labels.json').write_text(json.dumps(labels([], scan='room.ply')))
    (folder / 'broken.ply').write_text('ply\nformat ascii 1.0\nend_header\n')
    (folder / 'broken.labels.json').write_text(json.dumps(labels([], scan='broken.ply')))
    proc = run_eval(scans['checkpoint'], folder, '--out', tmp_path / 'c')
    assert proc.returncode == 2
    assert last_line(proc).startswith(f'eval_scans.py: error: {folder / "broken.ply"}')
    assert not (tmp_path / 'c').exists(), 'nothing written for bad input'


def test_make_exp2_cpu_ends_with_the_evaluation_of_real_scans() -> None:
    def dry_run(*variables: str) -> list[str]:
        proc = exp2_dry_run(*variables)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout.replace('\\\n', ' ').strip().splitlines()

    assert not any('eval_scans.py' in line for line in dry_run())
    one_pass, with_tta = dry_run('REAL_SCANS=labelled/')[-2:]
    for line in (one_pass, with_tta):
        assert line.startswith('.venv/bin/python tools/eval_scans.py configs/tr3d/exp2_cpu.py '
                               '$(cat work_dirs/exp2_cpu/last_checkpoint) labelled/ ')
    assert '--out work_dirs/exp2_cpu/real_scans ' in one_pass and '--tta' not in one_pass
    assert '--tta --out work_dirs/exp2_cpu/real_scans_tta ' in with_tta
