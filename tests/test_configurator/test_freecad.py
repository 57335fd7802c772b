"""The FreeCAD document: schema checks, the ``freecad`` CLI and the macro, with real freecadcmd.

FreeCAD processes are few and shared (module fixtures): one makes a STEP file, the CLI builds
three documents (full, empty predictions, corners computed from a generated scan), the macro
runs once on its own with a bad file, and one inspection process reopens the documents,
records them, edits parameters, recomputes and records the new geometry.
"""
import argparse
import json
import math
import os
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest

from configurator import freecad_cli
from configurator.freecad_cli import MACRO, build_document
from synthdet.contracts import SchemaError, load_json, validate_corners, validate_predictions
from synthdet.outputs import OutputRefused
from synthdet.scan_io import write_scan
from tests.freecad_gui import RUN_MACRO_ANSWERING, WRITE_REPORT, run_gui_driver
from tests.room_scans import make_room

FREECADCMD = 'freecadcmd'
L_ROOM = [[0.0, 0.0], [0.0, 5.0], [6.0, 5.0], [6.0, 2.0], [3.0, 2.0], [3.0, 0.0]]
FLOOR_Z, CEILING_Z = 0.2, 3.1
STEP_CENTRE = (30.0, 40.0, 100.0)  # mm, the STEP cylinder's bounding-box centre (off origin)


def hostile_names(marker: Path) -> list[str]:
    """Class names that would run code, break quoting or expressions if spliced anywhere."""
    return [
        f"x'); __import__('os').system('touch {marker}') #",
        f'"""\n__import__("os").system("touch {marker}")\n"""',
        '<<Table>>.Length + Table_Parameters.length',
        f"=__import__('os').system('touch {marker}')",
        'Stühl 椅子 🪑\t\\ / <tag> & ; %s {0}',
        'L' * 200,
    ]


def detection(class_name: str, score: float, center, size, yaw: float = 0.0) -> dict:
    return {
        'class': class_name,
        'score': score,
        'center': list(center),
        'size': list(size),
        'yaw': yaw
    }


MAIN_DETECTIONS = [
    detection('table', 0.93, (1.2, 3.0, 0.6), (1.6, 0.8, 0.75), 0.5),
    detection('chair', 0.90, (2.2, 3.5, 0.65), (0.5, 0.55, 0.9), -2.0),
    detection('bookcase', 0.80, (0.5, 4.5, 1.2), (1.0, 0.4, 2.0)),
    detection('sofa', 0.85, (4.5, 4.0, 0.6), (2.0, 0.9, 0.85), math.pi / 2),  # STEP model
    detection('yumi', 0.75, (4.0, 3.0, 0.95), (0.6, 0.5, 0.6), 1.0),
    detection('3dprinter', 0.70, (5.2, 2.6, 0.5), (0.5, 0.45, 0.6)),
    detection('forklift', 0.60, (1.5, 1.0, 1.2), (1.5, 1.0, 2.0), 0.3),
    detection('chair', 0.10, (2.0, 1.0, 0.65), (0.5, 0.5, 0.9)),  # below --min-score
]

INSPECT_SCRIPT = textwrap.dedent('''\
    import json, os, sys
    import FreeCAD as App
    import Part

    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    sys.path.insert(0, params['package_dir'])
    # the parts' proxy class, loaded before the documents open (the macro loads it so)
    import synthdet_freecad.library

    def box(shape):  # exact bounds: BoundBox is loose on non-uniformly scaled curved faces
        bound = shape.optimalBoundingBox()
        return [bound.XMin, bound.YMin, bound.ZMin, bound.XMax, bound.YMax, bound.ZMax]

    def describe(doc):
        objects = {}
        for obj in doc.Objects:
            entry = {'type': obj.TypeId, 'label': obj.Label, 'valid': obj.isValid(),
                     'proxy': hasattr(obj, 'Proxy')}
            if obj.TypeId == 'App::DocumentObjectGroup':
                entry['group'] = [child.Name for child in obj.Group]
            if hasattr(obj, 'DetectedClass'):
                entry.update({'class': obj.DetectedClass, 'score': obj.Score,
                              'scan': obj.SourceScan, 'cad': obj.CadModel,
                              'base': list(obj.Placement.Base),
                              'angle': obj.Placement.Rotation.Angle,
                              'axis': list(obj.Placement.Rotation.Axis),
                              'world': box(Part.getShape(obj)),
                              'local': box(Part.getShape(obj, transform=False))})
            if obj.Name in ('Walls', 'Floor'):
                entry.update({'world': box(obj.Shape), 'area': obj.Shape.Area,
                              'volume': obj.Shape.Volume})
            objects[obj.Name] = entry
        return objects

    def by_class(doc, name):
        return [o for o in doc.Objects if getattr(o, 'DetectedClass', None) == name][0]

    def set_cell(sheet, alias, value):
        sheet.set(sheet.getCellFromAlias(alias), value)

    doc = App.openDocument(params['main'])
    report = {'main': describe(doc)}
    table, sofa, yumi = by_class(doc, 'table'), by_class(doc, 'sofa'), by_class(doc, 'yumi')
    # the YuMi's solids: base plate, 3 body wedges, then per arm 7 links and a gripper
    arms = {'Right': slice(4, 11), 'Left': slice(12, 19)}
    def arm(side):
        return box(Part.makeCompound(yumi.Shape.Solids[arms[side]]))

    report['arms_before'] = [arm('Right'), arm('Left')]
    table.Length = 2000.0
    sofa.Length = 3000.0
    yumi.RightJoint2 = 90.0
    set_cell(doc.RoomParameters, 'wall_thickness', '=300 mm')
    set_cell(doc.RoomParameters, 'height', '=4000 mm')
    doc.recompute()
    report['edited'] = {
        'table': box(Part.getShape(table, transform=False)),
        'sofa': box(Part.getShape(sofa, transform=False)),
        'arms': [arm('Right'), arm('Left')],
        'walls': box(doc.Walls.Shape),
        'invalid': [o.Name for o in doc.Objects if not o.isValid()],
    }
    for key in ('empty', 'scanned'):
        report[key] = describe(App.openDocument(params[key]))
    with open(params['report'], 'w', encoding='utf-8') as stream:
        json.dump(report, stream)
''')


def configurator_main(argv: list[str]) -> int:
    """``python -m configurator freecad ...`` through the sub-command's own parser."""
    assert argv[0] == 'freecad'
    parser = argparse.ArgumentParser(prog='python -m configurator freecad')
    freecad_cli.add_arguments(parser)
    return freecad_cli.run(parser.parse_args(argv[1:]))


GUI_DRIVER = textwrap.dedent('''\
    # Runs in the FreeCAD GUI: answers the macro's dialogs like a user would, then reports.
    import json, os
    import FreeCAD as App
    from PySide import QtCore, QtGui

    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    answers, seen = list(params['answers']), {'dialogs': [], 'messages': []}

    def answer():
        widget = QtGui.QApplication.activeModalWidget()
        if isinstance(widget, QtGui.QFileDialog) and answers:
            seen['dialogs'].append(widget.windowTitle())
            widget.findChild(QtGui.QLineEdit).setText(answers.pop(0))
            widget.accept()
        elif isinstance(widget, QtGui.QMessageBox):
            seen['messages'].append(widget.text())
            widget.accept()

''') + RUN_MACRO_ANSWERING + textwrap.dedent('''\
    doc = App.ActiveDocument
    seen['gui'] = App.GuiUp
    seen['classes'] = sorted(o.DetectedClass for o in doc.Objects if hasattr(o, 'DetectedClass'))
    seen['floor_area'] = doc.getObject('Floor').Shape.Area if doc.getObject('Floor') else None
    table = [o for o in doc.Objects if getattr(o, 'DetectedClass', None) == 'table'][0]
    seen['table_color'] = list(table.ViewObject.ShapeColor)[:3]
    sofa = [o for o in doc.Objects if getattr(o, 'DetectedClass', None) == 'sofa'][0]
    seen['sofa_model'] = sofa.CadModel
    seen['sofa_color'] = list(sofa.ViewObject.ShapeColor)[:3]
    parts = [o for o in doc.Objects if hasattr(o, 'DetectedClass')]
    seen['hidden_parts'] = [o.Label for o in parts if not o.ViewObject.Visibility
                            and 'Alternatives' not in [p.Name for p in o.InList]]
''') + WRITE_REPORT


def run_freecad(script: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([FREECADCMD, str(script)],
                          env=dict(os.environ, **(env or {})),
                          cwd=script.parent,
                          stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE,
                          text=True,
                          errors='replace',
                          timeout=300)


def write_json(path: Path, data: object) -> Path:
    path.write_text(json.dumps(data, ensure_ascii=False), encoding='utf-8')
    return path


def predictions(detections: list[dict], scan: str = 'Area_9/lab_3/lab_3.txt') -> dict:
    return {
        'format': 'synthdet.predictions/1',
        'scan': scan,
        'model': 'exp2',
        'classes': ['table', 'chair', 'sofa', 'yumi', '3dprinter'],
        'detections': detections
    }


def corners(points=L_ROOM, floor_z=FLOOR_Z, ceiling_z=CEILING_Z) -> dict:
    return {
        'format': 'synthdet.corners/1',
        'scan': 'Area_9/lab_3/lab_3.txt',
        'corners': points,
        'floor_z': floor_z,
        'ceiling_z': ceiling_z,
        'quality': {}
    }


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> dict:
    """Inputs on disk: scan, predictions (with hostile strings), corners, a STEP library."""
    root = tmp_path_factory.mktemp('freecad')
    marker = root / 'INJECTED'
    scan = root / 'scan.txt'
    scan.write_text('0 0 0 1 2 3\n1 1 1 4 5 6\n', encoding='utf-8')
    hostile = hostile_names(marker)
    detections = MAIN_DETECTIONS + [
        detection(name, 0.9, (0.5 + 0.45 * index, 0.4, 0.5), (0.3, 0.3, 0.3))
        for index, name in enumerate(hostile)
    ]
    hostile_scan = f"$(touch {marker}); ' \" \n {{0}} <<x>>"
    library = root / 'my library'
    library.mkdir()
    make_step = root / 'make_step_file.py'
    make_step.write_text(
        textwrap.dedent(f'''\
        import FreeCAD as App, Part
        cylinder = Part.makeCylinder(50, 200, App.Vector({STEP_CENTRE[0]}, {STEP_CENTRE[1]}, 0))
        cylinder.exportStep({str(library / 'sofa.step')!r})
    '''),
        encoding='utf-8')
    run_freecad(make_step)
    assert (library / 'sofa.step').stat().st_size > 0
    return {
        'root': root,
        'marker': marker,
        'scan': scan,
        'hostile': hostile,
        'hostile_scan': hostile_scan,
        'library': library,
        'predictions': write_json(root / 'lab_3.pred.json', predictions(detections, hostile_scan)),
        'corners': write_json(root / 'lab_3.corners.json', corners()),
        'out': root / 'out dir \'ü"' / 'room.FCStd',
    }


@pytest.fixture(scope='module')
def built(workspace) -> dict:
    """Run the CLI's document builder (real freecadcmd) on the main inputs."""
    return build_document(
        workspace['scan'],
        workspace['predictions'],
        workspace['out'],
        workspace['corners'],
        workspace['library'],
        min_score=0.3,
        wall_thickness=0.15)


@pytest.fixture(scope='module')
def empty_build(workspace) -> tuple[int, Path]:
    """The CLI on valid predictions without detections: a room-only document."""
    root = workspace['root']
    out = root / 'empty.FCStd'
    code = configurator_main([
        'freecad', '--scan',
        str(workspace['scan']), '--predictions',
        str(write_json(root / 'empty.pred.json', predictions([]))), '--corners',
        str(workspace['corners']), '--out',
        str(out)
    ])
    return code, out


@pytest.fixture(scope='module')
def scanned_build(workspace) -> dict:
    """The CLI without --corners: the corners come from a generated L-shaped room scan."""
    root = workspace['root']
    room = make_room('L', n_points=60_000, seed=3)
    scan = root / 'room.bin'
    write_scan(scan, room.points)
    centre = room.polygon.mean(axis=0)
    pred = write_json(
        root / 'room.pred.json',
        predictions(
            [detection('table', 0.9, (centre[0], centre[1], room.floor_z + 0.4), (1.2, 0.6, 0.8))],
            str(scan)))
    out = root / 'scanned.FCStd'
    code = configurator_main(
        ['freecad', '--scan',
         str(scan), '--predictions',
         str(pred), '--out',
         str(out)])
    return {'code': code, 'out': out, 'room': room}


@pytest.fixture(scope='module')
def inspection(workspace, built, empty_build, scanned_build) -> dict:
    """Reopen the documents in a second FreeCAD process, then edit parameters and recompute."""
    root = workspace['root']
    script = root / 'inspect_documents.py'
    script.write_text(INSPECT_SCRIPT, encoding='utf-8')
    report = root / 'inspection.json'
    params = write_json(
        root / 'inspect_params.json', {
            'main': built['document'],
            'empty': str(empty_build[1]),
            'scanned': str(scanned_build['out']),
            'report': str(report),
            'package_dir': str(Path(MACRO).parent),
        })
    process = run_freecad(script, {'SYNTHDET_TEST_PARAMS': str(params)})
    assert report.is_file(), (process.stdout + process.stderr)[-3000:]
    return json.loads(report.read_text(encoding='utf-8'))


def rotated_aabb(center, size, yaw) -> np.ndarray:
    """World axis-aligned bounds (mm) of a yawed box given in metres."""
    half = np.array(size[:2]) / 2
    corners_xy = np.array([[sx * half[0], sy * half[1]] for sx in (-1, 1) for sy in (-1, 1)])
    c, s = math.cos(yaw), math.sin(yaw)
    xy = corners_xy @ np.array([[c, -s], [s, c]]).T + np.array(center[:2])
    low = [xy[:, 0].min(), xy[:, 1].min(), center[2] - size[2] / 2]
    high = [xy[:, 0].max(), xy[:, 1].max(), center[2] + size[2] / 2]
    return 1000.0 * np.array(low + high)


def detections_in(objects: dict) -> dict:
    return {name: entry for name, entry in objects.items() if 'class' in entry}


# ----------------------------------------------------------------------------- schema (no FreeCAD)


@pytest.mark.parametrize('mutate, message', [
    (lambda p: p.update(format='synthdet.predictions/2'), 'unsupported format'),
    (lambda p: p['detections'][0].update(score=float('nan')), 'detections[0].score: expected a '
     'finite number, got NaN'),
    (lambda p: p['detections'][0].update(center=[1.0, float('inf'), 0.0]),
     'detections[0].center[1]'),
    (lambda p: p['detections'][0].update(size=[1.0, 0.0, 1.0]), 'expected positive sizes'),
    (lambda p: p['detections'][0].update({'class': 'x' * 201}), 'longer than 200'),
    (lambda p: p['detections'][0].update({'class': 7}), 'detections[0].class: expected a string'),
    (lambda p: p['detections'][0].pop('size'), 'missing key "size"'),
    (lambda p: p['detections'][0].update(score=1.5), 'expected a score in [0, 1]'),
    (lambda p: p.update(detections={}), 'detections: expected a list'),
])
def test_predictions_schema_rejects(mutate, message):
    data = predictions([detection('table', 0.9, (1, 2, 0.4), (1, 1, 0.8))])
    validate_predictions(data, 'p.json')
    mutate(data)
    with pytest.raises(SchemaError, match='^p.json: ') as error:
        validate_predictions(data, 'p.json')
    assert message in str(error.value)


@pytest.mark.parametrize('points, floor_z, ceiling_z, message', [
    (L_ROOM[::-1], 0.0, 3.0, 'counter-clockwise'),
    ([[0, 0], [1, 1], [1, 0], [0, 1]], 0.0, 3.0, 'crosses itself'),
    ([[0, 0], [0, 1]], 0.0, 3.0, 'expected a list of 3'),
    ([[0, 0], [0, 1], [0, 1], [1, 0]], 0.0, 3.0, 'repeats the next corner'),
    (L_ROOM, 3.0, 3.0, 'not above floor_z'),
    ([[0, 0], [0, float('nan')], [1, 0]], 0.0, 3.0, 'corners[1][1]: expected a finite number'),
])
def test_corners_schema_rejects(points, floor_z, ceiling_z, message):
    validate_corners(corners(), 'c.json')
    with pytest.raises(SchemaError, match=r'^c\.json: ') as error:
        validate_corners(corners(points, floor_z, ceiling_z), 'c.json')
    assert message in str(error.value)


def test_json_syntax_error_names_file_and_line(tmp_path):
    bad = tmp_path / 'bad.json'
    bad.write_text('{\n  "format": "synthdet.predictions/1",\n  "detections": [,]\n}\n')
    with pytest.raises(SchemaError, match=r'bad\.json:3:\d+: invalid JSON'):
        load_json(str(bad))


# --------------------------------------------------------------- CLI input errors (before FreeCAD)


def cli(*args) -> list[str]:
    return ['freecad', *map(str, args)]


def test_cli_rejects_bad_inputs_with_clear_errors(workspace, tmp_path, capsys):
    root = workspace['root']
    empty_scan = tmp_path / 'empty.txt'
    empty_scan.write_text('')
    nan = tmp_path / 'nan.pred.json'
    nan.write_text(
        json.dumps(predictions([detection('chair', float('nan'), (1, 1, 1), (1, 1, 1))])))
    future = write_json(tmp_path / 'future.pred.json',
                        dict(predictions([]), format='synthdet.predictions/9'))
    cases = [
        (cli('--scan', empty_scan, '--predictions', workspace['predictions'], '--corners',
             workspace['corners'], '--out', tmp_path / 'a.FCStd'), 'the scan is empty'),
        (cli('--scan', workspace['scan'], '--predictions', nan, '--corners', workspace['corners'],
             '--out', tmp_path / 'a.FCStd'), 'detections[0].score: expected a finite number'),
        (cli('--scan', workspace['scan'], '--predictions', future, '--corners',
             workspace['corners'], '--out',
             tmp_path / 'a.FCStd'), 'unsupported format \'synthdet.predictions/9\''),
        (cli('--scan', workspace['scan'], '--predictions', workspace['predictions'], '--corners',
             workspace['corners'], '--out', tmp_path / 'a.step'), 'must end with .FCStd'),
        (cli('--scan', workspace['scan'], '--predictions', workspace['predictions'], '--corners',
             workspace['corners'], '--library', root / 'missing', '--out',
             tmp_path / 'a.FCStd'), 'library folder not found'),
        (cli('--scan', workspace['scan'], '--predictions', workspace['predictions'], '--corners',
             workspace['corners'], '--out', tmp_path / 'a.FCStd', '--freecadcmd',
             tmp_path / 'no-freecad'), 'not found: install FreeCAD'),
    ]
    for index, (argv, message) in enumerate(cases):
        # bad input exits 2; a missing FreeCAD (the last case) is a run-time failure: 1
        assert configurator_main(argv) == (1 if index == len(cases) - 1 else 2)
        assert message in capsys.readouterr().err
    assert not list(tmp_path.glob('*.FCStd'))


# ------------------------------------------------------------------------ documents (real FreeCAD)


def test_macro_alone_validates_its_input_and_fails_headless(workspace, tmp_path):
    bad = tmp_path / 'bad.pred.json'
    bad.write_text(
        json.dumps(predictions([detection('table', 0.9, (1, float('nan'), 0), (1, 1, 1))])))
    result, out = tmp_path / 'result.json', tmp_path / 'bad.FCStd'
    process = run_freecad(MACRO, {
        'SYNTHDET_PREDICTIONS': str(bad),
        'SYNTHDET_OUT': str(out),
        'SYNTHDET_RESULT': str(result)
    })
    assert process.returncode == 1
    report = json.loads(result.read_text())
    assert report['format'] == 'synthdet.freecad-result/1' and report['status'] == 'error'
    assert f'{bad}: detections[0].center[1]: expected a finite number, got NaN' in report['error']
    assert not out.exists()


def test_cli_result_lists_objects_groups_and_warnings(workspace, built):
    assert built['status'] == 'ok' and Path(built['document']) == workspace['out']
    assert workspace['out'].is_file()
    assert built['skipped_low_score'] == 1
    classes = [obj['class'] for obj in built['objects']]
    assert classes == [d['class'] for d in MAIN_DETECTIONS[:-1]] + workspace['hostile']
    models = {obj['class']: obj['model'] for obj in built['objects']}
    assert models['sofa'] == 'step' and models['table'] == 'builtin'
    assert models['forklift'] == 'box'
    assert "no CAD model for class 'forklift'" in ' '.join(built['warnings'])
    assert len(built['warnings']) == 1 + len(workspace['hostile'])


def test_reopened_document_has_groups_placements_and_properties(workspace, inspection):
    objects = inspection['main']
    assert all(entry['valid'] for entry in objects.values())
    # each detection is one object, whose proxy rebuilds its shape; nothing else has one
    assert {name for name, entry in objects.items() if entry['proxy']} == \
        {name for name, entry in objects.items() if 'class' in entry}
    assert {entry['type'] for entry in objects.values() if 'class' in entry} == \
        {'Part::FeaturePython'}
    room = objects['Room']['group']
    assert {'RoomParameters', 'FloorSketch', 'Floor', 'Walls'} <= set(room)
    detected = detections_in(objects)
    furniture, equipment = set(objects['Furniture']['group']), set(objects['Equipment']['group'])
    assert furniture | equipment == set(detected) and not furniture & equipment
    for name, entry in detected.items():
        expected_group = furniture if entry['class'] in ('table', 'chair', 'sofa', 'bookcase') \
            else equipment
        assert name in expected_group
    expected = {d['class']: d for d in MAIN_DETECTIONS if d['score'] >= 0.3}
    for entry in detected.values():
        if entry['class'] not in expected:
            continue
        source = expected[entry['class']]
        assert entry['score'] == pytest.approx(source['score'])
        assert entry['scan'] == workspace['hostile_scan']
        bottom = [source['center'][0], source['center'][1], FLOOR_Z]  # each stands on the floor
        np.testing.assert_allclose(entry['base'], np.array(bottom) * 1000, atol=1e-6)
        yaw = math.atan2(math.sin(source['yaw']), math.cos(source['yaw']))
        signed = entry['angle'] * np.sign(entry['axis'][2]) if entry['angle'] else 0.0
        assert math.isclose(math.remainder(signed - yaw, 2 * math.pi), 0.0, abs_tol=1e-9)
        half = np.array(source['size']) * 500
        box = np.array([-half[0], -half[1], 0, half[0], half[1], 2 * half[2]])
        standing = bottom[:2] + [FLOOR_Z + source['size'][2] / 2]
        aabb = rotated_aabb(standing, source['size'], source['yaw'])
        if entry['class'] == 'yumi':  # the real robot's proportions, scaled to fit the box
            assert np.all(entry['local'][:3] >= box[:3] - 0.5)
            assert np.all(entry['local'][3:] <= box[3:] + 0.5)
            assert np.isclose(
                np.subtract(entry['local'][3:], entry['local'][:3]), 2 * half, atol=1.0).any()
        else:
            np.testing.assert_allclose(entry['local'], box, atol=1e-3, err_msg=entry['class'])
        if entry['class'] == 'yumi':  # round arm links do not reach the box's vertical edges
            assert np.all(entry['world'][:3] >= aabb[:3] - 0.5)
            assert np.all(entry['world'][3:] <= aabb[3:] + 0.5)
        else:
            np.testing.assert_allclose(entry['world'], aabb, atol=0.5, err_msg=entry['class'])
    assert {entry['cad'] for entry in detected.values() if entry['class'] == 'sofa'} == {'step'}


def test_room_floor_and_walls(inspection):
    objects = inspection['main']
    area = 6 * 5 - 3 * 2
    assert objects['Floor']['area'] == pytest.approx(area * 1e6)
    assert objects['Floor']['world'][2] == pytest.approx(FLOOR_Z * 1000)
    thickness = 150.0
    np.testing.assert_allclose(
        objects['Walls']['world'], [
            -thickness, -thickness, FLOOR_Z * 1000, 6000 + thickness, 5000 + thickness,
            CEILING_Z * 1000
        ],
        atol=1e-6)
    height = (CEILING_Z - FLOOR_Z) * 1000
    outer_area = (6000 + 2 * thickness) * (5000 + 2 * thickness) - (3000 - 0) * (2000 - 0)
    assert objects['Walls']['volume'] == pytest.approx(
        (outer_area - area * 1e6) * height, rel=1e-6)


def test_editing_parameters_recomputes_geometry(inspection):
    edited = inspection['edited']
    assert edited['invalid'] == []
    table_y, sofa_y = 400.0, 450.0
    np.testing.assert_allclose(
        edited['table'], [-1000, -table_y, 0, 1000, table_y, 750], atol=1e-3)
    np.testing.assert_allclose(edited['sofa'], [-1500, -sofa_y, 0, 1500, sofa_y, 850], atol=1e-3)
    np.testing.assert_allclose(
        edited['walls'], [-300, -300, FLOOR_Z * 1000, 6300, 5300, FLOOR_Z * 1000 + 4000],
        atol=1e-6)
    (right_before, left_before), (right_after, left_after) = (inspection['arms_before'],
                                                              edited['arms'])
    # right joint 2 from the folded rest pose (-129 deg) to 90 deg swings the right arm only
    assert np.abs(np.subtract(right_after, right_before)).max() > 100.0
    np.testing.assert_allclose(left_after, left_before, atol=1e-6)


def test_hostile_strings_are_data_never_code(workspace, inspection):
    assert not workspace['marker'].exists()
    detected = detections_in(inspection['main'])
    by_class = {entry['class']: entry for entry in detected.values()}
    for name in workspace['hostile']:
        entry = by_class[name]
        assert entry['cad'] == 'box' and entry['scan'] == workspace['hostile_scan']
        assert entry['label'] == f'{name} 1'
        np.testing.assert_allclose(entry['local'], [-150, -150, 0, 150, 150, 300], atol=1e-3)


def test_empty_predictions_give_a_room_only_document(empty_build, inspection):
    code, out = empty_build
    assert code == 0 and out.is_file()
    objects = inspection['empty']
    assert not detections_in(objects)
    assert objects['Furniture']['group'] == [] and objects['Equipment']['group'] == []
    assert objects['Walls']['valid'] and objects['Floor']['area'] == pytest.approx(24e6)


def test_corners_from_the_scan_when_not_given(scanned_build, inspection):
    assert scanned_build['code'] == 0
    room = scanned_build['room']
    x, y = room.polygon[:, 0], room.polygon[:, 1]
    true_area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) * 1e6
    objects = inspection['scanned']
    assert objects['Floor']['area'] == pytest.approx(true_area, rel=0.03)
    assert objects['Floor']['world'][2] == pytest.approx(room.floor_z * 1000, abs=30)
    assert objects['Walls']['world'][5] == pytest.approx(room.ceiling_z * 1000, abs=30)
    assert len(detections_in(objects)) == 1


def test_an_output_under_a_file_is_refused_before_freecad_starts(workspace, tmp_path):
    out_dir = tmp_path / 'not-a-folder'
    out_dir.write_text('a file where the output folder should be')
    with pytest.raises(OutputRefused, match='cannot be used .Not a directory.'):
        build_document(workspace['scan'], workspace['predictions'], out_dir / 'room.FCStd',
                       workspace['corners'])


def test_macro_in_the_gui_asks_for_the_files_and_imports(workspace, tmp_path):
    answers = [str(workspace['predictions']), str(workspace['corners'])]
    seen = run_gui_driver(tmp_path, GUI_DRIVER, {'answers': answers},
                          SYNTHDET_LIBRARY=str(workspace['library']))
    assert seen['gui'] and len(seen['dialogs']) == 2
    assert 'predictions' in seen['dialogs'][0] and 'corners' in seen['dialogs'][1]
    assert "no CAD model for class 'forklift'" in seen['messages'][0]
    expected = [d['class'] for d in MAIN_DETECTIONS if d['score'] >= 0.3] + workspace['hostile']
    assert seen['classes'] == sorted(expected)
    assert seen['floor_area'] == pytest.approx(24e6)
    assert seen['table_color'] == pytest.approx([31 / 255, 119 / 255, 180 / 255], abs=0.01)
    assert seen['hidden_parts'] == []
    assert seen['sofa_model'] == 'step'  # a scaled STEP model takes the class color too
    assert seen['sofa_color'] == pytest.approx([44 / 255, 160 / 255, 44 / 255], abs=0.01)
