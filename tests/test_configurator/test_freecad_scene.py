"""The FreeCAD document as a user opens it, with real freecadcmd and the real GUI.

One room is built through ``python -m configurator freecad``: objects on the floor and on
tables, an axis-aligned chair, sofa and YuMi (orientation rules), a yawed chair, a floating
chair, a table crossing a wall, and a table and a sofa detected on the same box. A plain
``freecadcmd`` reopens it and measures every part; the FreeCAD GUI under Xvfb opens it and
saves a screenshot (``python -m configurator screenshot``).
"""
import contextlib
import io
import json
import math
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from configurator.__main__ import main as configurator_main
from configurator.freecad_cli import MACRO

FLOOR_Z, CEILING_Z = 0.1, 3.0
L_ROOM = [[0.0, 0.0], [0.0, 6.0], [7.0, 6.0], [7.0, 2.5], [3.5, 2.5], [3.5, 0.0]]


def detection(class_name, score, center, size, yaw=0.0):
    return {'class': class_name, 'score': score, 'center': center, 'size': size, 'yaw': yaw}


# name -> detection; boxes as a detector reports them (centres off the floor, a box in a wall)
SCENE = {
    'work_table': detection('table', 0.95, [2.0, 4.5, 0.38], [1.6, 0.8, 0.72]),
    'printer': detection('3dprinter', 0.9, [1.6, 4.5, 1.0], [0.45, 0.45, 0.5]),
    'robot_table': detection('table', 0.93, [5.5, 5.4, 0.36], [1.4, 0.7, 0.75]),
    'yumi': detection('yumi', 0.88, [5.5, 5.4, 1.05], [0.65, 0.5, 0.57]),
    'chair_facing': detection('chair', 0.9, [2.0, 3.5, 0.45], [0.5, 0.5, 0.9]),
    'chair_yawed': detection('chair', 0.85, [4.5, 3.5, 0.45], [0.5, 0.55, 0.9], 0.7),
    'chair_floating': detection('chair', 0.8, [1.0, 1.5, 0.64], [0.5, 0.5, 0.9]),
    'chair_under': detection('chair', 0.8, [2.1, 4.45, 0.45], [0.5, 0.5, 0.9]),  # deep under
    'wall_table': detection('table', 0.9, [0.3, 2.5, 0.4], [1.2, 0.6, 0.75]),
    'sofa': detection('sofa', 0.87, [6.3, 4.0, 0.40], [0.9, 2.0, 0.85]),
    'merged_table': detection('table', 0.7, [5.0, 3.2, 0.38], [1.2, 0.6, 0.75]),
    'merged_sofa': detection('sofa', 0.6, [5.0, 3.2, 0.39], [1.2, 0.62, 0.75]),
}

INSPECT = textwrap.dedent('''\
    import json, os, sys
    import FreeCAD as App
    import Part

    params = json.load(open(os.environ['SYNTHDET_TEST_PARAMS'], encoding='utf-8'))
    sys.path.insert(0, params['package_dir'])
    import synthdet_freecad.library  # the parts' proxy class, loaded before the document opens
    doc = App.openDocument(params['document'])
    walls = doc.getObject('Walls').Shape
    parts = {}
    for obj in doc.Objects:
        if not hasattr(obj, 'DetectedClass'):
            continue
        shape = Part.getShape(obj)
        bound = shape.optimalBoundingBox()
        rotation = obj.Placement.Rotation
        parts[obj.Label] = {
            'class': obj.DetectedClass, 'score': obj.Score,
            'groups': [parent.Name for parent in obj.InList],
            'visible': obj.Visibility, 'stands_on': obj.StandsOn,
            'orientation': obj.Orientation,
            'yaw': rotation.Angle * (1 if rotation.Axis.z >= 0 else -1),
            'base': list(obj.Placement.Base),
            'bounds': [bound.XMin, bound.YMin, bound.ZMin, bound.XMax, bound.YMax, bound.ZMax],
            'in_walls': shape.common(walls).Volume,
            'alternatives': [other.Label for other in getattr(obj, 'Alternatives', [])],
            'type': obj.TypeId, 'solids': len(shape.Solids),
        }
    def part(label):
        return Part.getShape([o for o in doc.Objects if o.Label == label][0])

    report = {'clash': part(params['clash'][0]).common(part(params['clash'][1])).Volume,
              'parts': parts, 'objects': len(doc.Objects),
              'invalid': [o.Name for o in doc.Objects if not o.isValid()]}
    chair = [o for o in doc.Objects if getattr(o, 'Label', '') == params['chair']][0]
    chair.Height = 1500.0
    table = [o for o in doc.Objects if getattr(o, 'Label', '') == params['table']][0]
    table.Height = 1000.0
    doc.recompute()
    report['chair_after'] = Part.getShape(chair).optimalBoundingBox().ZMin
    report['on_table_after'] = {
        label: Part.getShape([o for o in doc.Objects if o.Label == label][0])
        .optimalBoundingBox().ZMin for label in params['on_table']}
    report['table_top_after'] = Part.getShape(table).optimalBoundingBox().ZMax
    json.dump(report, open(params['report'], 'w', encoding='utf-8'))
''')


@pytest.fixture(scope='module')
def scene(tmp_path_factory) -> dict:
    """The room built by the CLI, then measured in a second, plain FreeCAD process."""
    root = tmp_path_factory.mktemp('scene')
    scan = root / 'scan.txt'
    scan.write_text('0 0 0 1 2 3\n1 1 1 4 5 6\n', encoding='utf-8')
    predictions = root / 'room.pred.json'
    predictions.write_text(
        json.dumps({
            'format': 'synthdet.predictions/1',
            'scan': 'Area_9/factory_1/factory_1.txt',
            'model': 'exp2',
            'classes': [],
            'detections': list(SCENE.values())
        }),
        encoding='utf-8')
    corners = root / 'room.corners.json'
    corners.write_text(
        json.dumps({
            'format': 'synthdet.corners/1',
            'scan': 'Area_9/factory_1/factory_1.txt',
            'corners': L_ROOM,
            'floor_z': FLOOR_Z,
            'ceiling_z': CEILING_Z,
            'quality': {}
        }),
        encoding='utf-8')
    document = root / 'room.FCStd'
    with contextlib.redirect_stderr(io.StringIO()) as stderr:
        code = configurator_main([
            'freecad', '--scan',
            str(scan), '--predictions',
            str(predictions), '--corners',
            str(corners), '--out',
            str(document)
        ])
    assert code == 0
    labels = label_of(SCENE)
    script, report = root / 'measure_scene.py', root / 'report.json'
    script.write_text(INSPECT, encoding='utf-8')
    params = root / 'params.json'
    params.write_text(
        json.dumps({
            'document': str(document),
            'report': str(report),
            'package_dir': str(MACRO.parent),
            'chair': labels['chair_floating'],
            'table': labels['work_table'],
            'on_table': [labels['printer']],
            'clash': [labels['chair_under'], labels['work_table']]
        }),
        encoding='utf-8')
    process = subprocess.run(['freecadcmd', str(script)],
                             cwd=root,
                             timeout=300,
                             env={
                                 'SYNTHDET_TEST_PARAMS': str(params),
                                 'PATH': '/usr/bin:/bin',
                                 'HOME': str(root)
                             },
                             stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT,
                             text=True,
                             errors='replace')
    assert report.is_file(), process.stdout[-3000:]
    return {
        'document': document,
        'labels': labels,
        'root': root,
        'warnings': stderr.getvalue(),
        **json.loads(report.read_text(encoding='utf-8'))
    }


def label_of(scene: dict) -> dict:
    """The label each winning detection gets: ``<class> <n>`` in input order per class."""
    counts, labels = {}, {}
    for name, entry in scene.items():
        if name == 'merged_sofa':
            continue
        counts[entry['class']] = counts.get(entry['class'], 0) + 1
        labels[name] = f'{entry["class"]} {counts[entry["class"]]}'
    return labels


def test_every_object_stands_on_the_floor_or_its_table(scene):
    parts, labels = scene['parts'], scene['labels']
    assert scene['invalid'] == []
    on_tables = {'printer': 'work_table', 'yumi': 'robot_table'}
    for name, label in labels.items():
        part = parts[label]
        if name in on_tables:
            table = parts[labels[on_tables[name]]]
            assert part['stands_on'] == labels[on_tables[name]]
            assert part['bounds'][2] == pytest.approx(table['bounds'][5], abs=10.0), name
        else:
            assert part['stands_on'] == 'floor'
            assert part['bounds'][2] == pytest.approx(FLOOR_Z * 1000, abs=10.0), name
    # the floating chair (box bottom 190 mm above the floor) came down to the floor
    assert parts[labels['chair_floating']]['base'][2] == pytest.approx(FLOOR_Z * 1000)


def test_height_edits_keep_the_feet_and_carry_what_stands_on_a_table(scene):
    assert scene['chair_after'] == pytest.approx(FLOOR_Z * 1000, abs=1e-3)
    top = scene['table_top_after']
    assert top == pytest.approx(FLOOR_Z * 1000 + 1000, abs=1e-3)
    for z in scene['on_table_after'].values():
        assert z == pytest.approx(top, abs=1e-3)


def test_no_object_crosses_a_wall_and_the_moved_one_is_warned_about(scene):
    parts, labels = scene['parts'], scene['labels']
    for label, part in parts.items():
        if part['visible']:
            assert part['in_walls'] < 1.0, label  # mm^3
    moved = parts[labels['wall_table']]
    assert moved['bounds'][0] >= -1e-3  # was 0.3 m - 0.6 m: reached 0.3 m into the x = 0 wall


def test_yaws_are_the_detections_and_rules_for_axis_aligned_ones(scene):
    parts, labels = scene['parts'], scene['labels']
    yawed = parts[labels['chair_yawed']]
    assert yawed['orientation'] == 'detection yaw'
    assert math.remainder(yawed['yaw'] - 0.7, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    for name in ('printer', 'work_table', 'robot_table'):
        part = parts[labels[name]]
        assert name == 'printer' or part['orientation'] == 'back to the nearest wall'
    chair = parts[labels['chair_facing']]
    table = parts[labels['work_table']]
    assert chair['orientation'] == f'faces {labels["work_table"]}'
    front = (math.sin(chair['yaw']), -math.cos(chair['yaw']))  # local -y in the world
    to_table = np.subtract(table['base'][:2], chair['base'][:2])
    assert np.dot(front, to_table / np.linalg.norm(to_table)) == pytest.approx(1.0, abs=1e-9)
    sofa = parts[labels['sofa']]  # 0.7 m from the x = 7 wall: its back (local +y) faces +x
    back = (-math.sin(sofa['yaw']), math.cos(sofa['yaw']))
    assert back == pytest.approx((1.0, 0.0), abs=1e-9)
    assert sofa['bounds'][3] - sofa['bounds'][0] == pytest.approx(900.0, abs=1e-3)
    yumi = parts[labels['yumi']]  # on a table along the y = 6 wall: it faces the room (-y)
    assert yumi['orientation'] == f'faces the free side of {labels["robot_table"]}'
    assert (math.sin(yumi['yaw']), -math.cos(yumi['yaw'])) == pytest.approx((0.0, -1.0), abs=1e-9)


def test_overlapping_detections_of_two_classes_give_one_object_with_an_alternative(scene):
    parts, labels = scene['parts'], scene['labels']
    winner = parts[labels['merged_table']]
    assert winner['visible'] and winner['class'] == 'table'
    assert winner['alternatives'] == [f'sofa (alternative to {labels["merged_table"]})']
    alternative = parts[winner['alternatives'][0]]
    assert alternative['class'] == 'sofa' and not alternative['visible']
    assert 'Alternatives' in alternative['groups']
    visible_here = [
        label for label, part in parts.items()
        if part['visible'] and abs(part['base'][0] - 5000) < 1 and abs(part['base'][1] - 3200) < 1
    ]
    assert visible_here == [labels['merged_table']]


def test_lean_tree_one_object_per_part(scene):
    parts = scene['parts']
    for label, part in parts.items():
        assert part['type'] == 'Part::FeaturePython' and part['solids'] >= 1, label
    yumi = parts[scene['labels']['yumi']]
    assert yumi['solids'] == 1 + 3 + 2 * 8  # plate, 3 body sections, 2 x (7 links, gripper)
    # besides the parts: the room's 7 objects and the Furniture, Equipment and Alternatives groups
    assert scene['objects'] == len(parts) + 10


def _pixel_shares(path: Path) -> tuple[float, float]:
    """Shares of non-white pixels and of strongly colored ones (the class colors)."""
    rgb = np.asarray(Image.open(path).convert('RGB')).astype(float)
    drawn = (rgb < 245).any(axis=2)
    saturation = rgb.max(axis=2) - rgb.min(axis=2)
    return drawn.mean(), (saturation > 60).mean()


def test_the_gui_opens_the_document_visible_colored_and_fitted(scene, tmp_path):
    picture = tmp_path / 'room.png'
    code = configurator_main([
        'screenshot',
        str(scene['document']), '--out',
        str(picture), '--width', '800', '--height', '600'
    ])
    assert code == 0
    with Image.open(picture) as image:
        assert image.size == (800, 600)
    drawn, colored = _pixel_shares(picture)
    assert drawn > 0.15  # the room fills a good part of the view
    assert colored > 0.005  # and the class-colored objects are drawn


def test_the_screenshot_ignores_the_qt_settings_of_the_calling_process(scene, tmp_path,
                                                                      monkeypatch):
    """OpenCV (imported by mmcv) points Qt at its own plugins; FreeCAD must not load them."""
    import cv2
    plugins = Path(cv2.__file__).parent / 'qt' / 'plugins'
    monkeypatch.setenv('QT_QPA_PLATFORM_PLUGIN_PATH', str(plugins))
    picture = tmp_path / 'room.png'
    assert configurator_main(['screenshot', str(scene['document']), '--out', str(picture)]) == 0
    assert _pixel_shares(picture)[0] > 0.15


# ------------------------------------------------- the placement rules alone (standard library)


def test_an_inner_corner_poking_into_a_footprint_pushes_it_out():
    from configurator.freecad.synthdet_freecad import arrangement

    # a square turned 45 degrees around the L room's inner corner (3.5, 2.5): all four of its
    # corners lie inside the room, but the wall corner lies inside the square
    square = detection('table', 0.9, [3.4, 2.6, 0.4], [0.5 * 2**0.5] * 2 + [0.75], math.pi / 4)
    placed, warnings = arrangement.arrange([square], {'corners': L_ROOM, 'floor_z': FLOOR_Z})
    item = placed[0]
    assert all(arrangement.point_in_polygon(x, y, L_ROOM) for x, y in item.footprint())
    assert not any(item.contains_xy(x, y, 1e-6) for x, y in L_ROOM)
    assert len(warnings) == 1 and 'table 1 crossed a wall by' in warnings[0]
    assert item.base_z == FLOOR_Z


def test_only_strong_overlaps_of_different_classes_merge():
    from configurator.freecad.synthdet_freecad.arrangement import merge_overlapping

    table = detection('table', 0.9, [1.0, 1.0, 0.4], [1.0, 1.0, 0.8])
    same_class = detection('table', 0.8, [1.05, 1.0, 0.4], [1.0, 1.0, 0.8])
    weak = detection('chair', 0.95, [1.6, 1.0, 0.4], [1.0, 1.0, 0.8])  # IoU 0.25
    strong = detection('sofa', 0.95, [1.1, 1.0, 0.4], [1.0, 1.0, 0.8])  # IoU 0.82, wins

    def classes(groups):
        return [(winner['class'], [other['class'] for other in alternatives])
                for winner, alternatives in groups]

    assert classes(merge_overlapping([table, same_class, weak])) == [('table', []), ('table', []),
                                                                     ('chair', [])]
    assert classes(merge_overlapping([table, strong])) == [('sofa', ['table'])]


def test_a_chair_under_a_table_faces_it_and_its_backrest_clears_the_top(scene):
    parts, labels = scene['parts'], scene['labels']
    chair = parts[labels['chair_under']]
    assert chair['orientation'] == f'faces {labels["work_table"]}'
    assert (math.sin(chair['yaw']), -math.cos(chair['yaw'])) == pytest.approx((0.0, 1.0), abs=1e-9)
    assert scene['clash'] < 1.0  # mm^3 shared by the chair and the table
    assert f'{labels["chair_under"]} pulled 0.15 m out from under {labels["work_table"]}' \
        in scene['warnings']


def test_the_screenshot_command_refuses_a_file_that_is_no_document(tmp_path, capsys):
    bad = tmp_path / 'broken.FCStd'
    bad.write_text('not a FreeCAD document', encoding='utf-8')
    picture = tmp_path / 'broken.png'
    assert configurator_main(['screenshot', str(bad), '--out', str(picture)]) == 2
    error = capsys.readouterr().err
    assert error.startswith(f'error: {bad}: not a FreeCAD document') and error.count('\n') == 1
    assert not picture.exists()

