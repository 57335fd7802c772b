"""The light core ``synthdet/``: what it imports, the file contracts' rules, scan and PLY I/O,
the text parser's x y z files and the 2D geometry."""
import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from synthdet import contracts, scan_io
from synthdet.classes import (CLASS_COLORS, DETECTION_CLASSES, DETECTION_SEMANTIC_IDS,
                              GENERATED_CLASSES, SEMANTIC_CLASSES, STRUCTURE_CLASSES)
from synthdet.cli import InputFileError
from synthdet.contracts import SchemaError
from synthdet.geometry import (box_corners_xy, clockwise, distance_to_polygon, edges_cross,
                               first_self_crossing, grid_cells, points_in_polygon, rotation2d,
                               segments_touch, signed_area)
from synthdet.ply import read_ply_vertices, write_ply
from synthdet.point_text import PointFileError, format_lines, read_point_file
from synthdet.scan_io import ScanFormatError, read_scan, write_scan

REPO = Path(__file__).resolve().parents[2]
HEAVY = ('torch', 'mmcv', 'mmdet', 'mmdet3d', 'mmengine', 'MinkowskiEngine', 'bpy', 'open3d')
L_ROOM = [[0.0, 0.0], [0.0, 5.0], [6.0, 5.0], [6.0, 2.0], [3.0, 2.0], [3.0, 0.0]]  # clockwise


def run_python(code: str) -> list[str]:
    """Run ``code`` in a fresh interpreter from the repository root; its printed lines."""
    result = subprocess.run([sys.executable, '-c', code],
                            cwd=REPO,
                            capture_output=True,
                            text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout.split()


# ----------------------------------------------------------------------------- imports


def test_core_and_light_stages_import_no_ml_stack_and_no_stage():
    loaded = run_python(
        'import sys, synthdet.contracts, synthdet.scan_io, synthdet.geometry, '
        'synthdet.classes, synthdet.topview, synthdet.room_data, synthdet.point_text, '
        'synthdet.ply, generator.layout, configurator.corners; print(*sys.modules)')
    assert not set(HEAVY) & set(loaded)
    core_only = run_python('import sys, synthdet.topview, synthdet.scan_io; print(*sys.modules)')
    assert not {'generator', 'configurator', 'projects', 'tools'} & set(core_only)


def test_contracts_need_the_standard_library_only_and_the_package_imports_nothing():
    loaded = set(run_python('import sys, synthdet.contracts; print(*sys.modules)'))
    assert 'numpy' not in loaded  # FreeCAD's own Python loads contracts.py
    assert {name
            for name in loaded if name.startswith('synthdet')
            } == {'synthdet', 'synthdet.contracts', 'synthdet.classes', 'synthdet.geometry',
                  'synthdet.outputs', 'synthdet.processes'}  # writing through synthdet.outputs
    loaded = set(run_python('import sys, synthdet; print(*sys.modules)'))
    assert {name for name in loaded if name.startswith('synthdet')} == {'synthdet'}


# ----------------------------------------------------------------------------- classes


def test_class_lists_have_one_meaning_each():
    assert DETECTION_CLASSES == ('table', 'chair', 'sofa', 'bookcase', 'board', 'yumi',
                                 '3dprinter')
    assert DETECTION_SEMANTIC_IDS == (7, 8, 9, 10, 11, 13, 14)
    assert set(GENERATED_CLASSES) < set(DETECTION_CLASSES)
    assert not set(DETECTION_CLASSES) & set(STRUCTURE_CLASSES)
    assert set(SEMANTIC_CLASSES) == set(DETECTION_CLASSES) | set(STRUCTURE_CLASSES)
    assert set(CLASS_COLORS) == set(SEMANTIC_CLASSES)
    assert len(set(CLASS_COLORS.values())) == len(CLASS_COLORS)  # every class distinguishable


# ----------------------------------------------------------------------------- contracts


def predictions() -> dict:
    return {
        'format':
        'synthdet.predictions/1',
        'scan':
        'Area_9/lab_3/lab_3.txt',
        'model':
        'exp2',
        'classes': ['table', 'chair'],
        'detections': [{
            'class': 'table',
            'score': 0.9,
            'center': [1.0, 2.0, 0.4],
            'size': [1.6, 0.8, 0.75],
            'yaw': 0.5
        }]
    }


def corners() -> dict:
    return {
        'format': 'synthdet.corners/1',
        'scan': 'Area_9/lab_3/lab_3.txt',
        'corners': copy.deepcopy(L_ROOM),
        'floor_z': 0.0,
        'ceiling_z': 3.0,
        'quality': {
            'wall_points_on_polygon': 0.97
        }
    }


def room_object(instance: str, cls: str, center: list, size: list, on: str | None) -> dict:
    return {'instance': instance, 'class': cls, 'box': {'center': center, 'size': size}, 'on': on}


def room() -> dict:
    return {
        'format': 'synthdet.room/1',
        'seed': 1,
        'room': {'polygon': copy.deepcopy(L_ROOM), 'height': 3.0, 'shape': 'L'},
        'objects': [
            room_object('table_1', 'table', [1.0, 4.0, 0.375], [1.6, 0.8, 0.75], None),
            room_object('yumi_1', 'yumi', [1.0, 4.0, 1.0], [0.5, 0.5, 0.5], 'table_1'),
        ]
    }  # yapf: disable


def _set(path: str, value):
    """A mutation setting the value at a dotted/indexed JSON path (``a.b[1]``)."""
    keys = [
        int(k) if k.isdigit() else k for k in path.replace('[', '.').replace(']', '').split('.')
    ]

    def mutate(data):
        for key in keys[:-1]:
            data = data[key]
        data[keys[-1]] = value

    return mutate


def _drop(path: str):
    keys = path.split('.')

    def mutate(data):
        for key in keys[:-1]:
            data = data[int(key) if key.isdigit() else key]
        del data[keys[-1]]

    return mutate


NAN, INF = float('nan'), float('inf')
RULES = [
    # (document, mutation, expected "file: path: message" after the file name)
    (predictions, _set('format', 'synthdet.predictions/2'), 'format: unsupported format'),
    (predictions, _drop('detections'), 'missing key "detections"'),
    (predictions, _set('detections', {}), 'detections: expected a list'),
    (predictions, _drop('detections.0.size'), 'detections[0]: missing key "size"'),
    (predictions, _set('detections[0].score', NAN), 'detections[0].score: expected a finite'),
    (predictions, _set('detections[0].score', 1.5), 'detections[0].score: expected a score in'),
    (predictions, _set('detections[0].score', True), 'detections[0].score: expected a number'),
    (predictions, _set('detections[0].center[1]', INF), 'detections[0].center[1]: expected a '
     'finite number, got Infinity'),
    (predictions, _set('detections[0].center',
                       [1, 2]), 'detections[0].center: expected a list of'),
    (predictions, _set('detections[0].size[1]', 0.0), 'detections[0].size[1]: expected positive'),
    (predictions, _set('detections[0].size[2]', 1e4), 'detections[0].size[2]: expected positive '
     'sizes up to 1000 m'),
    (predictions, _set('detections[0].yaw', NAN), 'detections[0].yaw: expected a finite'),
    (predictions, _set('detections[0].class', 'x' * 201), 'detections[0].class: name longer'),
    (predictions, _set('detections[0].class', ' '), 'detections[0].class: expected a non-empty'),
    (predictions, _set('classes[1]', 7), 'classes[1]: expected a string'),
    (predictions, _set('scan', 'a\x00b'), 'scan: text contains a NUL'),
    (corners, _set('format', 'synthdet.corners/9'), 'format: unsupported format'),
    (corners, _drop('quality'), 'missing key "quality"'),
    (corners, _drop('scan'), 'missing key "scan"'),
    (corners, _set('quality', {'wall_points_on_polygon': NAN}), 'quality.wall_points_on_polygon: '
     'expected a finite'),
    (corners, _set('corners', L_ROOM[::-1]), 'corners: the corners run counter-clockwise'),
    (corners, _set('corners', [[0, 0], [1, 1], [1, 0], [0, 1]]), 'corners: the polygon crosses '
     'itself (edges 0 and 2)'),
    (corners, _set('corners', [[0, 0], [0, 1]]), 'corners: expected a list of 3'),
    (corners, _set('corners', [[0, 0], [0, 1], [0, 1], [1, 0]]), 'corners[1]: repeats the next'),
    (corners, _set('corners', [[0, 0], [0, 1], [0, 2]]), 'corners: the polygon has no area'),
    (corners, _set('corners[2][0]', NAN), 'corners[2][0]: expected a finite number, got NaN'),
    (corners, _set('ceiling_z', 0.0), 'ceiling_z: ceiling_z 0.0 is not above floor_z 0.0'),
    (room, _set('format', 'synthdet.room/0'), 'format: unsupported format'),
    (room, _drop('room.height'), 'room: missing key "height"'),
    (room, _set('room.height', -3.0), 'room.height: expected positive sizes'),
    (room, _set('room.polygon', L_ROOM[::-1]), 'room.polygon: the corners run counter-clockwise'),
    (room, _set('objects[0].class', 'forklift'), "objects[0].class: unknown class 'forklift'"),
    (room, _set('objects[1].instance', 'table_1'), "objects[1].instance: instance 'table_1' "
     'appears twice'),
    (room, _set('objects[1].on', 'table_9'), "objects[1].on: 'table_9' is not another object"),
    (room, _set('objects[0].on', 'table_1'), "objects[0].on: 'table_1' is not another object"),
    (room, _set('objects[0].box.size', [1, -1, 1]), 'objects[0].box.size[1]: expected positive'),
    (room, _drop('objects.1.box'), 'objects[1]: missing key "box"'),
]


@pytest.mark.parametrize('make, mutate, message', RULES)
def test_each_contract_rule_rejects_a_bad_file_naming_file_and_json_path(
        tmp_path, make, mutate, message):
    reader = {
        predictions: contracts.read_predictions,
        corners: contracts.read_corners,
        room: contracts.read_room
    }[make]
    path = tmp_path / 'doc.json'
    path.write_text(json.dumps(make()))
    reader(path)  # the untouched document is valid
    document = make()
    mutate(document)
    path.write_text(json.dumps(document))
    with pytest.raises(SchemaError) as error:
        reader(path)
    text = str(error.value)
    assert text.startswith(f'{path}: ') and '\n' not in text
    assert message in text, text


def test_json_errors_name_file_line_and_column(tmp_path):
    path = tmp_path / 'bad.json'
    path.write_text('{\n  "format": "synthdet.predictions/1",\n  "detections": [,]\n}\n')
    with pytest.raises(SchemaError, match=r'bad\.json:3:18: invalid JSON'):
        contracts.read_predictions(path)
    path.write_text('  \n')
    with pytest.raises(SchemaError, match=r'bad\.json: the file is empty'):
        contracts.read_corners(path)
    with pytest.raises(SchemaError, match=r'missing\.json: cannot read'):
        contracts.read_room(tmp_path / 'missing.json')
    path.write_text('[1, 2]')
    with pytest.raises(SchemaError, match=r'bad\.json: expected a JSON object, got list'):
        contracts.read_room(path)


def test_writers_validate_and_round_trip_atomically(tmp_path):
    out = tmp_path / 'room.corners.json'
    contracts.write_corners(out, corners())
    assert contracts.read_corners(out) == corners()
    assert len(out.read_text().splitlines()) == len(corners()) + 2  # one line per key
    contracts.write_predictions(tmp_path / 'p.json', predictions())
    assert contracts.read_predictions(tmp_path / 'p.json') == predictions()
    contracts.write_room(tmp_path / 'meta.json', room())
    assert contracts.read_room(tmp_path / 'meta.json') == room()
    bad = dict(corners(), corners=L_ROOM[::-1])
    with pytest.raises(SchemaError, match='bad.json: corners: the corners run counter-clockwise'):
        contracts.write_corners(tmp_path / 'bad.json', bad)
    assert sorted(p.name
                  for p in tmp_path.iterdir()) == ['meta.json', 'p.json', 'room.corners.json']


def test_optional_fields_get_their_defaults():
    document = {'format': 'synthdet.predictions/1', 'detections': [predictions()['detections'][0]]}
    del document['detections'][0]['yaw']
    checked = contracts.validate_predictions(document, 'p.json')
    assert checked['detections'][0]['yaw'] == 0.0
    assert (checked['scan'], checked['model'], checked['classes']) == ('', '', [])
    unknown = predictions()
    unknown['detections'][0]['class'] = 'forklift'  # a model may know classes we do not
    assert contracts.validate_predictions(unknown)['detections'][0]['class'] == 'forklift'


# ----------------------------------------------------------------------------- scans


@pytest.mark.parametrize('suffix,tolerance', [('.txt', 1e-6), ('.bin', 1e-5), ('.ply', 1e-5)])
def test_scan_round_trip(tmp_path, suffix, tolerance):
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-10, 10, (500, 3)),
                              rng.integers(0, 256, (500, 3))]).astype(np.float64)
    path = tmp_path / f'scan{suffix}'
    write_scan(path, points)
    loaded = read_scan(path)
    assert loaded.shape == (500, 6) and loaded.dtype == np.float64
    np.testing.assert_allclose(loaded[:, :3], points[:, :3], atol=tolerance)
    np.testing.assert_array_equal(loaded[:, 3:], points[:, 3:])
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_read_ply_without_colors_and_with_float_colors(tmp_path):
    write_ply(tmp_path / 'bare.ply', {
        'x': np.array([0.0, 3.0]),
        'y': np.array([1.0, 4.0]),
        'z': np.array([2.0, 5.0])
    })
    np.testing.assert_array_equal(
        read_scan(tmp_path / 'bare.ply'), [[0, 1, 2, 0, 0, 0], [3, 4, 5, 0, 0, 0]])
    columns = {
        name: np.array([value], np.float32)
        for name, value in zip(('x', 'y', 'z', 'red', 'green', 'blue'), (0.0, 1.0, 2.0, 1.0, 0.5,
                                                                         0.0))
    }
    write_ply(tmp_path / 'float.ply', columns)
    np.testing.assert_allclose(read_scan(tmp_path / 'float.ply'), [[0, 1, 2, 255, 127.5, 0]])


def test_read_text_with_xyz_only(tmp_path):
    path = tmp_path / 'xyz.txt'
    path.write_text('\n1.5 2 3\n\n4 5 6.25\n')  # blank lines are skipped
    np.testing.assert_array_equal(read_scan(path), [[1.5, 2, 3, 0, 0, 0], [4, 5, 6.25, 0, 0, 0]])
    points, bad = read_point_file(path, columns=3)
    assert points.shape == (2, 3) and not bad
    path.write_text('1 2 3\n1 2 3 4 5 6\n')
    with pytest.raises(PointFileError, match=r'xyz.txt:2: expected 3 columns \(x y z\), found 6'):
        read_point_file(path, columns=3)


@pytest.mark.parametrize('text,message', [
    ('', r'bad.txt: the scan holds no points'),
    ('1 2 3 4 5 6\n1 2 3 4 5 6 7\n', r'bad.txt:2: expected 6 columns \(x y z r g b\), found 7'),
    ('1 2 3 4 5 6\n1 2 3 4 5\n', r'bad.txt:2: expected 6 columns \(x y z r g b\), found 5'),
    ('1 2 3 4 5 6\n1 2 x 4 5 6\n', r"bad.txt:2: cannot parse 'x' as a number"),
    ('\n1 2 3 4\n', r'bad.txt:2: expected 6 numbers per line \(x y z r g b\) or 3'),
    ('1 2 3 4 5 6\n1 2 3 4 5 6\nnan 2 3 4 5 6\n', r"bad.txt:3: non-finite value 'nan'"),
    ('1 2 3 4 5 256\n', r'bad.txt:1: color value 256 outside 0-255'),
])
def test_bad_text_scans_name_file_and_line(tmp_path, text, message):
    path = tmp_path / 'bad.txt'
    path.write_text(text)
    with pytest.raises(ScanFormatError, match=message):
        read_scan(path)


def test_bad_binary_and_other_files(tmp_path):
    path = tmp_path / 'bad.bin'
    np.zeros(7, dtype=np.float32).tofile(path)
    with pytest.raises(ScanFormatError, match='bad.bin: 28 bytes'):
        read_scan(path)
    np.full(6, np.nan, dtype=np.float32).tofile(path)
    with pytest.raises(ScanFormatError, match=r'bad.bin \(point 0\): non-finite'):
        read_scan(path)
    path = tmp_path / 'bad.ply'
    path.write_bytes(b'not a ply file')
    with pytest.raises(ScanFormatError, match='bad.ply: not a readable PLY'):
        read_scan(path)
    path = tmp_path / 'scan.obj'
    path.write_bytes(b'\0')
    with pytest.raises(ScanFormatError, match="unknown scan type '.obj'"):
        read_scan(path)
    with pytest.raises(InputFileError, match='missing.txt: scan file not found'):
        read_scan(tmp_path / 'missing.txt')


def test_a_new_format_is_one_table_entry(tmp_path, monkeypatch):
    monkeypatch.setitem(
        scan_io.READERS, '.tsv', lambda path, chunk_points, columns, notes: iter(
            [np.loadtxt(path, ndmin=2, delimiter='\t', usecols=range(6))]))
    path = tmp_path / 'scan.tsv'
    path.write_text('1\t2\t3\t10\t20\t30\n')
    np.testing.assert_array_equal(read_scan(path), [[1, 2, 3, 10, 20, 30]])


def test_text_writer_is_read_back_exactly(tmp_path):
    xyz = np.array([[-0.0004, 12.3456, -7.0], [1e6 - 0.001, 0.0005, 3.14159]])
    rgb = np.array([[0, 9, 255], [100, 10, 1]])
    text, offsets = format_lines(xyz, rgb, decimals=3)
    path = tmp_path / 'points.txt'
    path.write_bytes(text)
    points, _ = read_point_file(path)
    np.testing.assert_array_equal(points[:, :3], np.rint(xyz * 1000) / 1000)
    np.testing.assert_array_equal(points[:, 3:], rgb)
    assert offsets[-1] == len(text) and text[offsets[1] - 1:offsets[1]] == b'\n'


# ----------------------------------------------------------------------------- PLY


def test_ply_round_trip_keeps_types_values_and_comments(tmp_path):
    rng = np.random.default_rng(1)
    vertex = {
        'x': rng.normal(size=50),
        'y': rng.normal(size=50).astype(np.float32),
        'red': rng.integers(0, 256, 50).astype(np.uint8),
        'class': rng.integers(-1, 15, 50).astype(np.int32),
    }
    path = tmp_path / 'labelled.ply'
    write_ply(path, vertex, comments=['class 0=ceiling 1=floor'])
    header = path.read_bytes().split(b'end_header\n')[0].decode()
    assert 'format binary_little_endian 1.0' in header and 'comment class 0=ceiling' in header
    assert 'property double x' in header and 'property uchar red' in header
    loaded = read_ply_vertices(path)
    assert loaded.dtype.names == tuple(vertex)
    for name, values in vertex.items():
        np.testing.assert_array_equal(loaded[name], values)
    with pytest.raises(ValueError, match='different lengths'):
        write_ply(tmp_path / 'x.ply', {'x': np.zeros(2), 'y': np.zeros(3)})
    assert not (tmp_path / 'x.ply').exists()


# ----------------------------------------------------------------------------- geometry


def test_signed_area_and_clockwise_order():
    assert signed_area(L_ROOM) == pytest.approx(-24.0)  # 6 x 5 minus the 3 x 2 notch
    assert signed_area(np.array(L_ROOM[::-1])) == pytest.approx(24.0)
    np.testing.assert_array_equal(clockwise(L_ROOM[::-1]), L_ROOM)
    np.testing.assert_array_equal(clockwise(L_ROOM), L_ROOM)


def test_segment_touching_and_self_crossing():
    assert segments_touch((0, 0), (2, 2), (0, 2), (2, 0))  # an X
    assert segments_touch((0, 0), (1, 0), (1, 0), (1, 1))  # sharing an end point
    assert segments_touch((0, 0), (2, 0), (1, 0), (3, 0))  # collinear overlap
    assert not segments_touch((0, 0), (1, 0), (2, 0), (3, 0))  # collinear apart
    assert not segments_touch((0, 0), (1, 1), (0, 1), (0.4, 0.6))  # would cross if longer
    assert first_self_crossing(L_ROOM) is None
    assert first_self_crossing([[0, 0], [1, 1], [1, 0], [0, 1]]) == (0, 2)  # a bow tie
    spike = [[0, 0], [0, 2], [2, 2], [2, 0], [1, 0], [1, 2.5], [0.5, 0]]
    assert first_self_crossing(spike) is not None


def test_points_in_polygon_and_distance_to_it():
    points = np.array([[1, 1], [4, 3], [4, 1], [-1, 1], [2.5, 4.99], [3, 1]])  # (3, 1): on a wall
    np.testing.assert_array_equal(
        points_in_polygon(points[:5], np.array(L_ROOM)), [True, True, False, False, True])
    np.testing.assert_allclose(distance_to_polygon(points, L_ROOM), [1, 1, 1, 1, 0.01, 0])


def test_oriented_box_footprint_and_crossing_edges():
    quad = box_corners_xy((1.0, 2.0, 0.4), (2.0, 1.0, 0.8), math.pi / 2)
    np.testing.assert_allclose(quad, [[1.5, 1.0], [1.5, 3.0], [0.5, 3.0], [0.5, 1.0]], atol=1e-12)
    assert signed_area(quad) > 0  # counter-clockwise
    np.testing.assert_allclose(rotation2d(math.pi / 2) @ [1, 0], [0, 1], atol=1e-12)
    square = box_corners_xy((0, 0), (2, 2), 0.0)
    assert edges_cross(square, box_corners_xy((1, 1), (2, 2), 0.3))
    assert not edges_cross(square, box_corners_xy((0, 0), (1, 1), 0.3))  # inside, no crossing
    assert not edges_cross(square, box_corners_xy((2, 0), (2, 2), 0.0))  # sharing an edge


@pytest.mark.parametrize(
    'polygon, count',
    [
        ([[0, 0], [0, 5], [6, 5], [6, 0]], 1),
        (L_ROOM, 3),
        ([[0, 0], [0, 5], [2, 5], [2, 3], [4, 3], [4, 5], [6, 5], [6, 0]], 5),  # U
    ])
def test_grid_cells_tile_the_room(polygon, count):
    cells = grid_cells(np.array(polygon, float))
    assert len(cells) == count
    assert sum(-signed_area(cell) for cell in cells) == pytest.approx(-signed_area(polygon))
    for cell in cells:
        assert signed_area(cell) < 0 and points_in_polygon(cell.mean(axis=0)[None], polygon)[0]
