"""A corrected FreeCAD document as training data: ``python -m configurator labels``, the
editing helpers run in real freecadcmd, and the round trip generated room -> predictions ->
FCStd -> edited like a user would -> labels and S3DIS room -> create_data -> fine-tune.

The predictions are the generated room's true boxes with three faults a user corrects: a
phantom sofa (deleted), a chair left out (added with ``editing.add_part``) and a chair detected
0.3 m off (moved back). The labels must then equal the generator's truth.
"""
import json
import math
import os
import subprocess
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from configurator import labels as labels_module
from configurator.__main__ import main as configurator_main
from configurator.freecad_cli import build_document
from configurator.labels import BOX_MARGIN
from generator.__main__ import main as generator_main
from synthdet.classes import GENERATED_CLASSES, class_color
from synthdet.contracts import read_labels, write_corners, write_predictions
from synthdet.geometry import box_corners_xy
from synthdet.scan_io import read_scan, write_scan
from tests.freecad_gui import RUN_MACRO_ANSWERING, WRITE_REPORT, run_gui_driver
from tests.tool_process import run_tool, train_tiny

REPO = Path(__file__).resolve().parents[2]
FREECAD_DIR = REPO / 'configurator' / 'freecad'
ADDED, MOVED = 'chair_3', 'chair_1'  # generator instances: left out, detected off
SHIFT = (0.3, -0.2)

EDIT_SCRIPT = textwrap.dedent('''\
    # Runs in freecadcmd: corrects the document like a user (delete, add, move), then saves.
    import json, os, sys
    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    sys.path[:0] = [params['freecad_dir'], params['repo']]
    import FreeCAD as App
    from synthdet_freecad import editing, labels

    doc = App.openDocument(params['document'])
    parts = {part.Label: part for part in labels.synthdet_parts(doc)}
    for label, change in params['edits'].items():
        part = parts[label]
        if change == 'delete':
            for child in labels.part_children(part):
                doc.removeObject(child.Name)
            doc.removeObject(part.Name)
        else:
            part.Placement.Base = App.Vector(1000.0 * change[0], 1000.0 * change[1],
                                             part.Placement.Base.z)
    for added in params['added']:
        editing.add_part(doc, added['class'], *added['center'][:2], added['yaw'],
                         tuple(added['size']))
    editing.set_reviewed(doc)
    doc.recompute()
    doc.saveAs(params['out'])
    with open(params['report'], 'w', encoding='utf-8') as stream:
        json.dump({'reviewed': editing.is_reviewed(doc),
                   'invalid': [o.Name for o in doc.Objects if not o.isValid()]}, stream)
''')


def run_freecad_script(folder: Path, script: str, params: dict) -> dict:
    """Run ``script`` in real freecadcmd with ``params``; returns the JSON it reports."""
    path, report = folder / 'script.py', folder / 'report.json'
    path.write_text(script, encoding='utf-8')
    params_path = folder / 'params.json'
    params_path.write_text(json.dumps(dict(params, report=str(report))), encoding='utf-8')
    process = subprocess.run(['freecadcmd', str(path)],
                             env={
                                 **os.environ, 'SYNTHDET_TEST_PARAMS': str(params_path)
                             },
                             cwd=folder,
                             capture_output=True,
                             text=True,
                             timeout=300)
    assert report.is_file(), process.stdout[-2000:] + process.stderr[-2000:]
    return json.loads(report.read_text(encoding='utf-8'))


def labels_cli(*args) -> int:
    return configurator_main(['labels', *map(str, args)])


def truth_box(item: dict) -> dict:
    return {'class': item['class'], 'label': item['instance'], **item['box']}


def box_shape(box: dict) -> tuple[np.ndarray, float, float]:
    """Footprint corners (sorted, so a box turned by 180 degrees compares equal), bottom, top."""
    corners = box_corners_xy(box['center'], box['size'], box['yaw'])
    corners = corners[np.lexsort((corners[:, 1].round(4), corners[:, 0].round(4)))]
    half = box['size'][2] / 2.0
    return corners, box['center'][2] - half, box['center'][2] + half


def assert_same_box(found: dict, expected: dict) -> None:
    found_corners, found_bottom, found_top = box_shape(found)
    corners, bottom, top = box_shape(expected)
    assert found['class'] == expected['class']
    assert np.abs(found_corners - corners).max() < 1e-3, (found, expected)
    assert abs(found_bottom - bottom) < 1e-3 and abs(found_top - top) < 1e-3, (found, expected)


@pytest.fixture(scope='module')
def round_trip(tmp_path_factory) -> dict:
    """A generated room, its predictions with three faults, the document built from them, the
    document corrected in freecadcmd, and ``labels`` run on it."""
    root = tmp_path_factory.mktemp('labels')
    config = root / 'paper.json'  # the paper sensor: exact geometry, annotations by the hit
    config.write_text(json.dumps({'scanner': {'sensors': {'paper': 1.0}}}))
    assert generator_main([
        '--out',
        str(root / 'generated'), '--areas', '7', '--rooms-per-area', '1', '--points', '30000',
        '--seed', '3', '--asset-cache',
        str(root / 'assets'), '--config',
        str(config), '--quiet', '--workers', '1'
    ]) == 0
    room = root / 'generated' / 'Area_7' / 'factory_1'
    meta = json.loads((room / 'meta.json').read_text())
    truth = [truth_box(item) for item in meta['objects'] if item['class'] in GENERATED_CLASSES]
    by_label = {box['label']: box for box in truth}
    detections = []
    for box in truth:
        if box['label'] == ADDED:
            continue
        center = list(box['center'])
        if box['label'] == MOVED:
            center[0] += SHIFT[0]
            center[1] += SHIFT[1]
        detections.append({
            'class': box['class'],
            'score': 0.9,
            'center': center,
            'size': box['size'],
            'yaw': box['yaw']
        })
    # a phantom in an empty stretch of floor, as a detector invents one
    detections.append({
        'class': 'sofa',
        'score': 0.5,
        'center': [6.0, 4.2, 0.4],
        'size': [1.8, 0.8, 0.8],
        'yaw': 0.0
    })
    write_predictions(
        root / 'pred.json', {
            'format': 'synthdet.predictions/1',
            'scan': 'factory_1.txt',
            'model': 'truth',
            'classes': list(GENERATED_CLASSES),
            'detections': detections
        })
    write_corners(
        root / 'corners.json', {
            'format': 'synthdet.corners/1',
            'scan': 'factory_1.txt',
            'corners': meta['room']['polygon'],
            'floor_z': 0.0,
            'ceiling_z': meta['room']['height'],
            'quality': {}
        })
    scan = room / 'factory_1.txt'
    document = root / 'room.FCStd'
    result = build_document(
        scan, root / 'pred.json', document, root / 'corners.json', timeout=300.0)
    assert {item['label'] for item in result['objects']} >= {'sofa 1', 'chair 1'}
    # the document's 'chair 1' is the moved chair_1 (the chairs in the predictions' order)
    edits = {'sofa 1': 'delete', 'chair 1': by_label[MOVED]['center'][:2]}
    corrected = root / 'corrected.FCStd'
    report = run_freecad_script(
        root, EDIT_SCRIPT, {
            'freecad_dir': str(FREECAD_DIR),
            'repo': str(REPO),
            'document': str(document),
            'out': str(corrected),
            'edits': edits,
            'added': [by_label[ADDED]]
        })
    out = root / 'out'
    code = labels_cli(corrected, '--scan', scan, '--out', out, '--area', 1, '--room', 'factory_1',
                      '--timeout', 300)
    return {
        'root': root,
        'room': room,
        'truth': truth,
        'out': out,
        'code': code,
        'report': report,
        'scan': scan,
        'document': document,
        'corrected': corrected
    }


def test_labels_of_the_corrected_document_equal_the_truth(round_trip):
    assert round_trip['code'] == 0
    assert round_trip['report'] == {'reviewed': True, 'invalid': []}
    labels = read_labels(round_trip['out'] / 'factory_1.labels.json')
    assert labels['scan'] == 'factory_1.txt' and labels['source'].endswith('reviewed')
    assert set(GENERATED_CLASSES) <= set(labels['classes'])
    found = sorted(labels['boxes'], key=lambda box: (box['class'], box['center']))
    truth = sorted(round_trip['truth'], key=lambda box: (box['class'], box['center']))
    assert len(found) == len(truth)  # the phantom deleted, the missed chair added
    for found_box, true_box in zip(found, truth):
        assert_same_box(found_box, true_box)


def on_a_foot_plane(xyz: np.ndarray, boxes: list[dict]) -> np.ndarray:
    """Points on the plane where a part stands on another, under that part: a YuMi's foot and
    the table top around it there are one plane, and the documented rule gives both to the
    table, the generator each to what its ray hit."""
    ambiguous = np.zeros(len(xyz), dtype=bool)
    for box in boxes:
        bottom = box['center'][2] - box['size'][2] / 2.0
        if bottom < 0.01:
            continue  # on the floor: the floor is nobody's
        grown = dict(
            box,
            size=[
                box['size'][0] + 2 * BOX_MARGIN, box['size'][1] + 2 * BOX_MARGIN, box['size'][2]
            ])
        inside = inside_outline(box_corners_xy(grown['center'], grown['size'], box['yaw']), xyz)
        ambiguous |= inside & (np.abs(xyz[:, 2] - bottom) <= 1e-3)
    return ambiguous


def in_the_margin(xyz: np.ndarray, box: dict) -> np.ndarray:
    """Points outside ``box`` but within ``BOX_MARGIN`` of it (above its bottom): the documented
    rule gives them to the box whoever's they are, e.g. a shelf's side 2 mm from a table."""
    top = box['center'][2] + box['size'][2] / 2.0
    grown_size = [box['size'][0] + 2 * BOX_MARGIN, box['size'][1] + 2 * BOX_MARGIN, 0.0]
    exact = inside_outline(box_corners_xy(box['center'], box['size'], box['yaw']), xyz)
    grown = inside_outline(box_corners_xy(box['center'], grown_size, box['yaw']), xyz)
    below_top = xyz[:, 2] <= top
    just_above = (xyz[:, 2] > top) & (xyz[:, 2] <= top + BOX_MARGIN)
    return (grown & ~exact & (below_top | just_above)) | (exact & just_above)


def inside_outline(polygon: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    from matplotlib.path import Path as Outline
    return Outline(polygon).contains_points(xyz[:, :2])


def test_s3dis_room_annotations_equal_the_generators(round_trip):
    """Every untouched object's points are the generator's, but on a foot plane and in the
    margin around its box (above)."""
    written = round_trip['out'] / 'Area_1' / 'factory_1'
    annotations = written / 'Annotations'
    assert read_scan(written / 'factory_1.txt').shape == read_scan(round_trip['scan']).shape
    names = sorted(path.stem for path in annotations.glob('*.txt'))
    assert 'floor_1' in names and 'ceiling_1' in names and 'wall_1' in names
    untouched = [box for box in round_trip['truth'] if box['label'] not in (ADDED, MOVED)]
    assert len(untouched) >= 8
    # the document numbers a class in the predictions' order, which is the truth's
    compared = 0
    for box in untouched:
        ours = read_scan(annotations / f'{box["label"]}.txt')[:, :3]
        theirs = read_scan(round_trip['room'] / 'Annotations' / f'{box["label"]}.txt')[:, :3]
        ours, theirs = (
            rows[~on_a_foot_plane(rows, round_trip['truth'])] for rows in (ours, theirs))
        ours_set, theirs_set = ({tuple(row) for row in rows.round(3)} for rows in (ours, theirs))
        differing = np.array(sorted(ours_set ^ theirs_set)).reshape(-1, 3)
        assert in_the_margin(differing, box).all(), differing[~in_the_margin(differing, box)]
        compared += len(ours_set & theirs_set)
    assert compared > 5000
    total = sum(len(read_scan(path)) for path in annotations.glob('*.txt'))
    assert total == len(read_scan(round_trip['scan']))


@pytest.mark.slow
def test_create_data_converts_the_room_and_a_fine_tune_runs(round_trip, tmp_path):
    out = round_trip['out']
    raw = tmp_path / 'raw' / 'Stanford3dDataset_v1.2_Aligned_Version'
    raw.mkdir(parents=True)
    (raw / 'Area_1').symlink_to(out / 'Area_1', target_is_directory=True)
    data = tmp_path / 'data'
    run_tool('tools/create_data.py', 's3dis', '--root-path', tmp_path / 'raw', '--out-dir', data,
             '--areas', '1')
    assert (data / 's3dis_infos_Area_1.pkl').is_file()
    assert (data / 'points' / 'Area_1_factory_1.bin').is_file()
    records = train_tiny(data, 's3dis_infos_Area_1.pkl', tmp_path / 'work', epochs=2)
    assert [record['iter'] for record in records] == [1, 2]
    assert all(math.isfinite(record['loss']) for record in records)


def test_a_georeferenced_scan_keeps_its_coordinates_to_the_millimetre(round_trip, tmp_path):
    """The same room moved to UTM-like coordinates: the document holds them as they are, and
    the labels come back there."""
    offset = np.array([500000.0, 5400000.0, 300.0])
    points = read_scan(round_trip['scan'])
    points[:, :3] += offset
    scan = tmp_path / 'geo.ply'
    write_scan(scan, points)
    truth = [
        dict(box, center=list(np.asarray(box['center']) + offset)) for box in round_trip['truth']
    ]
    write_predictions(
        tmp_path / 'pred.json', {
            'format':
            'synthdet.predictions/1',
            'scan':
            scan.name,
            'model':
            'truth',
            'detections': [{
                'class': box['class'],
                'score': 0.9,
                'center': box['center'],
                'size': box['size'],
                'yaw': box['yaw']
            } for box in truth]
        })
    corners = json.loads((round_trip['root'] / 'corners.json').read_text())
    corners.update(
        corners=[[x + offset[0], y + offset[1]] for x, y in corners['corners']],
        floor_z=offset[2],
        ceiling_z=corners['ceiling_z'] + offset[2])
    write_corners(tmp_path / 'corners.json', corners)
    document = tmp_path / 'geo.FCStd'
    build_document(
        scan, tmp_path / 'pred.json', document, tmp_path / 'corners.json', timeout=300.0)
    assert labels_cli(document, '--scan', scan, '--out', tmp_path / 'out', '--timeout', 300) == 0
    labels = read_labels(tmp_path / 'out' / 'geo.labels.json')
    found = sorted(labels['boxes'], key=lambda box: (box['class'], box['center']))
    for found_box, true_box in zip(found,
                                   sorted(truth, key=lambda box: (box['class'], box['center']))):
        assert_same_box(found_box, true_box)
    assert len(found) == len(truth)
    room = tmp_path / 'out' / 'Area_10' / 'geo_1'
    assert len(read_scan(room / 'geo_1.txt')) == len(points)
    assert read_scan(room / 'Annotations' / 'table_1.txt')[:, 0].min() > offset[0]


SWITCH_SCRIPT = textwrap.dedent('''\
    # Runs in freecadcmd: switches the table to its sofa alternative, as the guide says.
    import json, os
    import FreeCAD as App
    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    doc = App.openDocument(params['document'])
    table = [o for o in doc.Objects if getattr(o, 'Alternatives', None)][0]
    table.Visibility = False
    table.Alternatives[0].Visibility = True
    doc.saveAs(params['out'])
    json.dump({'switched': [table.Label, table.Alternatives[0].Label]},
              open(params['report'], 'w'))
''')


def _detection(box: dict, name: str, score: float) -> dict:
    """A detection of class ``name`` on the true ``box``."""
    return {'class': name, 'score': score, 'center': box['center'], 'size': box['size'],
            'yaw': box['yaw']}


def _document_of(round_trip: dict, detections: list[dict], document: Path) -> Path:
    """The synthdet document of the round trip's room with ``detections`` as predictions."""
    predictions = document.with_suffix('.pred.json')
    write_predictions(predictions, {'format': 'synthdet.predictions/1', 'scan': 'factory_1.txt',
                                    'model': 'truth', 'detections': detections})
    build_document(round_trip['scan'], predictions, document, round_trip['root'] / 'corners.json',
                   timeout=300.0)
    return document


def test_an_alternative_counts_only_when_switched_in(round_trip, tmp_path):
    table = next(box for box in round_trip['truth'] if box['class'] == 'table')
    document = _document_of(
        round_trip, [_detection(table, name, score) for name, score in (('table', 0.9),
                                                                        ('sofa', 0.6))],
        tmp_path / 'one.FCStd')
    switched = tmp_path / 'switched.FCStd'
    report = run_freecad_script(tmp_path, SWITCH_SCRIPT, {
        'document': str(document),
        'out': str(switched)
    })
    assert report['switched'][0] == 'table 1'
    for path, expected in ((document, 'table'), (switched, 'sofa')):
        out = tmp_path / f'out_{path.stem}'
        assert labels_cli(path, '--scan', round_trip['scan'], '--out', out) == 0
        [found] = read_labels(out / 'factory_1.labels.json')['boxes']
        assert_same_box(found, dict(table, **{'class': expected}))


DELETE_WINNER_SCRIPT = textwrap.dedent('''\
    # Runs in freecadcmd: deletes the table that has alternatives, as a user deletes a false
    # detection (its alternatives stay hidden in the Alternatives group); saves that, then also
    # shows the first alternative and saves that as a second document.
    import json, os
    import FreeCAD as App
    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    doc = App.openDocument(params['document'])
    table = [o for o in doc.Objects if getattr(o, 'Alternatives', None)][0]
    alternatives = list(table.Alternatives)
    report = {'deleted': table.Label, 'alternatives': [o.Label for o in alternatives],
              'hidden': [not o.Visibility for o in alternatives]}
    doc.removeObject(table.Name)
    doc.recompute()
    doc.saveAs(params['deleted'])
    alternatives[0].Visibility = True
    doc.saveAs(params['shown'])
    report['left'] = sorted(o.Label for o in doc.Objects if hasattr(o, 'DetectedClass'))
    json.dump(report, open(params['report'], 'w'))
''')


def test_a_deleted_parts_alternatives_count_only_when_shown(round_trip, tmp_path):
    """Deleting a part leaves its hidden alternatives listed by nobody: they stay out of the
    labels, unless the user shows one (then that one counts)."""
    table = next(box for box in round_trip['truth'] if box['class'] == 'table')
    chair = next(box for box in round_trip['truth'] if box['class'] == 'chair')
    detections = [_detection(table, name, score)
                  for name, score in (('table', 0.9), ('sofa', 0.6), ('bookcase', 0.5))]
    document = _document_of(round_trip, detections + [_detection(chair, 'chair', 0.9)],
                            tmp_path / 'three.FCStd')
    deleted, shown = tmp_path / 'deleted.FCStd', tmp_path / 'shown.FCStd'
    report = run_freecad_script(tmp_path, DELETE_WINNER_SCRIPT, {
        'document': str(document),
        'deleted': str(deleted),
        'shown': str(shown)
    })
    assert report['deleted'] == 'table 1' and report['hidden'] == [True, True]
    assert [label.split()[0] for label in report['alternatives']] == ['sofa', 'bookcase']
    assert report['left'] == sorted(report['alternatives'] + ['chair 1'])
    kept = labels_module.read_document(deleted, timeout=300.0)['boxes']
    assert [box['class'] for box in kept] == ['chair']
    assert_same_box(kept[0], chair)
    found = sorted(labels_module.read_document(shown, timeout=300.0)['boxes'],
                   key=lambda box: box['class'])
    assert [box['class'] for box in found] == ['chair', 'sofa']
    assert_same_box(found[0], chair)
    assert_same_box(found[1], dict(table, **{'class': 'sofa'}))


OLD_LAYOUT_SCRIPT = textwrap.dedent('''\
    # Runs in freecadcmd: a part as synthdet built it before parts had their own dimensions,
    # a link group whose parameter sheet holds the size cells.
    import json, os
    import FreeCAD as App
    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    doc = App.newDocument('Old')
    part = doc.addObject('App::LinkGroup', 'Table001')
    part.Label = 'table 1'
    part.addProperty('App::PropertyString', 'DetectedClass', 'Synthdet', 'class')
    part.DetectedClass = 'table'
    part.Placement = App.Placement(App.Vector(1500, 2500, 100),
                                   App.Rotation(App.Vector(0, 0, 1), 30))
    sheet = doc.addObject('Spreadsheet::Sheet', 'Table001_Parameters')
    for row, (alias, value) in enumerate((('length', '=1600 mm'), ('width', '=800 mm'),
                                          ('height', '=750 mm')), start=1):
        sheet.set(f'B{row}', value)
        sheet.setAlias(f'B{row}', alias)
    part.ElementList = [sheet]
    doc.recompute()
    doc.saveAs(params['out'])
    json.dump({}, open(params['report'], 'w'))
''')


def test_a_document_of_the_former_layout_is_read_from_its_parameter_sheets(tmp_path):
    old = tmp_path / 'old.FCStd'
    run_freecad_script(tmp_path, OLD_LAYOUT_SCRIPT, {'out': str(old)})
    [box] = labels_module.read_document(old)['boxes']
    assert box['class'] == 'table' and box['label'] == 'table 1'
    np.testing.assert_allclose(box['size'], [1.6, 0.8, 0.75], atol=1e-9)
    np.testing.assert_allclose(box['center'], [1.5, 2.5, 0.1 + 0.375], atol=1e-9)
    assert box['yaw'] == pytest.approx(math.radians(30))


def inside_box(xyz: np.ndarray, item: dict) -> np.ndarray:
    """Points inside the box (its footprint, and above its bottom up to its top)."""
    bottom = item['center'][2] - item['size'][2] / 2.0
    footprint = box_corners_xy(item['center'], item['size'], item['yaw'])
    return inside_outline(footprint, xyz) & (xyz[:, 2] > bottom + 0.001) & (
        xyz[:, 2] < bottom + item['size'][2] - 0.001)


def test_a_chair_pushed_under_a_table_is_labelled_with_both_boxes(round_trip, tmp_path, capsys):
    """A user moves a chair half under a table: both boxes are labelled exactly, the points in
    both go to the chair (the smaller box), the table keeps the rest, every point once."""
    labels = read_labels(round_trip['out'] / 'factory_1.labels.json')
    table = next(item for item in labels['boxes'] if item['class'] == 'table')
    along = np.array([math.cos(table['yaw']), math.sin(table['yaw'])])
    under = np.asarray(table['center'][:2]) + (table['size'][0] / 2.0 - 0.15) * along
    pushed = tmp_path / 'pushed.FCStd'
    run_freecad_script(
        tmp_path, EDIT_SCRIPT, {
            'freecad_dir': str(FREECAD_DIR),
            'repo': str(REPO),
            'document': str(round_trip['corrected']),
            'out': str(pushed),
            'edits': {
                'chair 2': under.tolist()
            },
            'added': []
        })
    out = tmp_path / 'out'
    assert labels_cli(pushed, '--scan', round_trip['scan'], '--out', out, '--area', 1, '--room',
                      'factory_1') == 0
    assert capsys.readouterr().err == ''
    written = read_labels(out / 'factory_1.labels.json')['boxes']
    assert len(written) == len(labels['boxes'])
    chair = next(item for item in written if np.allclose(item['center'][:2], under, atol=1e-3))
    assert chair['class'] == 'chair'
    assert any(item['class'] == 'table' and item == table for item in written)
    annotations = out / 'Area_1' / 'factory_1' / 'Annotations'
    files = {path.stem: read_scan(path)[:, :3] for path in annotations.glob('*.txt')}
    chair_name = max((name for name in files if name.startswith('chair_')),
                     key=lambda name: inside_box(files[name], chair).sum())
    scan = read_scan(round_trip['scan'])[:, :3]
    shared = scan[inside_box(scan, chair) & inside_box(scan, table)]
    assert len(shared) > 50  # the table's points where the chair went under it
    assert {tuple(row) for row in shared.round(3)} <= {
        tuple(row) for row in files[chair_name].round(3)}
    table_names = [name for name in files if name.startswith('table_')]
    assert not any(inside_box(files[name], chair).any() for name in table_names)
    assert max(inside_box(files[name], table).sum() for name in table_names) > 500
    assert sum(len(xyz) for xyz in files.values()) == len(scan)


# --------------------------------------------------------------------------- input errors


def test_a_document_that_is_not_synthdets_is_refused(round_trip, tmp_path, capsys):
    plain = tmp_path / 'plain.FCStd'
    script = textwrap.dedent('''\
        import json, os
        import FreeCAD as App
        params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
        doc = App.newDocument('plain')
        doc.addObject('Part::Box', 'Box')
        doc.recompute()
        doc.saveAs(params['out'])
        json.dump({}, open(params['report'], 'w'))
    ''')
    run_freecad_script(tmp_path, script, {'out': str(plain)})
    out = tmp_path / 'out'
    assert labels_cli(plain, '--scan', round_trip['scan'], '--out', out) == 2
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and 'plain.FCStd: not a synthdet document' in error
    text = tmp_path / 'notes.FCStd'
    text.write_text('not a zip')
    assert labels_cli(text, '--scan', round_trip['scan'], '--out', out) == 2
    assert 'notes.FCStd: not a FreeCAD document' in capsys.readouterr().err
    assert not out.exists()


def test_a_document_with_python_objects_or_external_links_is_never_opened(
        round_trip, tmp_path, capsys):
    script = textwrap.dedent('''\
        import json, os
        import FreeCAD as App
        params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))

        class Thing:  # a Python feature: FreeCAD restores it by importing this module
            pass

        doc = App.openDocument(params['document'])
        doc.addObject('App::FeaturePython', 'Extra').Proxy = Thing()
        doc.saveAs(params['out'])
        json.dump({}, open(params['report'], 'w'))
    ''')
    python_doc = tmp_path / 'python.FCStd'
    run_freecad_script(tmp_path, script, {
        'document': str(round_trip['corrected']),
        'out': str(python_doc)
    })
    out = tmp_path / 'out'
    assert labels_cli(python_doc, '--scan', round_trip['scan'], '--out', out) == 2
    error = capsys.readouterr().err
    assert 'python.FCStd: Document.xml line ' in error and error.count('\n') == 1
    assert 'refused a Python object (App::FeaturePython)' in error
    assert not out.exists()
    # a link into another document: FreeCAD would open that file too
    linked = tmp_path / 'linked.FCStd'
    with zipfile.ZipFile(round_trip['corrected']) as source, \
            zipfile.ZipFile(linked, 'w') as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == 'Document.xml':
                data = data.replace(b'</Document>',
                                    b'<XLink file="other.FCStd" name="Box"/></Document>')
            target.writestr(item, data)
    assert labels_cli(linked, '--scan', round_trip['scan'], '--out', out) == 2
    assert "a link to another file ('other.FCStd')" in capsys.readouterr().err


GUI_DRIVER = textwrap.dedent('''\
    # Runs in the FreeCAD GUI: opens the document, picks a floor point, answers the macro's
    # dialog like a user (class 3dprinter, Add, Reviewed, Close), then reports.
    import json, os
    import FreeCAD as App
    import FreeCADGui as Gui
    from PySide import QtCore, QtGui

    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    doc = App.openDocument(params['document'])
    Gui.Selection.addSelection(doc.Name, 'Floor', 'Face1', *params['picked'])
    seen = {'titles': []}

    def answer():
        widget = QtGui.QApplication.activeModalWidget()
        if isinstance(widget, QtGui.QDialog) and not seen['titles']:
            seen['titles'].append(widget.windowTitle())
            widget.findChild(QtGui.QComboBox).setCurrentIndex(
                widget.findChild(QtGui.QComboBox).findText('3dprinter'))
            buttons = {b.text(): b for b in widget.findChildren(QtGui.QPushButton)}
            buttons['Add synthdet object'].click()
            widget.findChild(QtGui.QCheckBox).setChecked(True)
            buttons['Close'].click()

''') + RUN_MACRO_ANSWERING + textwrap.dedent('''\
    added = [o for o in doc.Objects if getattr(o, 'SourceModel', '') == 'added by hand'
             and o.DetectedClass == '3dprinter']
    part = added[0]
    seen.update(
        added=len(added), base=list(part.Placement.Base),
        reviewed=doc.Meta.get('SynthdetReviewed'),
        color=list(part.ViewObject.ShapeColor)[:3],
        z_bound=[e[0] for e in part.ExpressionEngine])
''') + WRITE_REPORT


def test_macro_in_the_gui_adds_a_part_at_the_picked_point_and_marks_reviewed(round_trip, tmp_path):
    seen = run_gui_driver(tmp_path, GUI_DRIVER, {
        'document': str(round_trip['document']),
        'picked': [6100.0, 2500.0, 0.0]
    })
    assert seen['titles'] == ['synthdet: correct the document'] and seen['added'] == 1
    assert seen['base'] == pytest.approx([6100.0, 2500.0, 0.0])  # on the floor, z 0
    assert '.Placement.Base.z' in seen['z_bound']  # follows the room's floor_z
    assert seen['reviewed'] == 'true'
    assert seen['color'] == pytest.approx([v / 255 for v in class_color('3dprinter')], abs=0.01)


def test_teach_finetune_config_mixes_the_user_rooms_with_the_generated_areas():
    from mmengine.config import Config
    cfg = Config.fromfile(REPO / 'configs' / 'tr3d' / 'teach_finetune.py')
    base = Config.fromfile(REPO / 'configs' / 'tr3d' / 'exp2_cpu.py')
    sets = cfg.train_dataloader.dataset.dataset.datasets
    files = [dataset.ann_file for dataset in sets]
    assert files == ['s3dis_infos_Area_7.pkl', 's3dis_infos_Area_8.pkl'
                     ] + ['s3dis_infos_Area_10.pkl'] * 33
    assert all(dataset.pipeline == base.train_pipeline for dataset in sets)
    assert all(dataset.data_root == base.data_root for dataset in sets)
    assert cfg.train_dataloader.dataset.times == 1 and cfg.train_dataloader.batch_size == 4
    assert cfg.load_from == 'work_dirs/exp2_cpu/epoch_12.pth'
    assert cfg.model == base.model and cfg.test_dataloader == base.test_dataloader
    assert cfg.train_cfg.max_epochs == cfg.param_scheduler.end == 6
