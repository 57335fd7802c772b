"""End to end with real bpy, Open3D/Embree and the procedural library: a few small rooms.

Checks the S3DIS files against meta.json (points inside the room, every annotation point inside
its object's box), the object/background ratio, byte-identical output for 1 vs 2 workers and
shards, resume after an interrupted run, and the scanner's geometry on a hand-made scene.
"""
import filecmp
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest

from generator.__main__ import main
from generator.config import DEFAULTS
from generator.layout import offset_polygon
from generator.scanner import Scanner, TriangleScene, random_directions, sensor_path
from generator.writer import TMP_PREFIX
from synthdet.classes import GENERATED_CLASSES, GENERATED_STRUCTURE_CLASSES
from synthdet.geometry import points_in_polygon
from synthdet.point_text import read_point_file
from tests.generator_runs import generate_rooms

POINTS = 20000
TOL = 2e-3  # text rounding (0.5 mm) + float32 ray casting


def parse_lines(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """xyz (N, 3) float64 and rgb (N, 3) int64 of an S3DIS text file."""
    points, _ = read_point_file(path)
    return points[:, :3], points[:, 3:].astype(np.int64)


@pytest.fixture(scope='module')
def asset_cache(tmp_path_factory):
    return tmp_path_factory.mktemp('assets')


@pytest.fixture(scope='module')
def reference_run(tmp_path_factory, asset_cache):
    out = tmp_path_factory.mktemp('run') / 'out'
    # the paper sensor: exact geometry and object ratio
    # (tests/test_generator/test_generator_sensors.py: others)
    config = out.parent / 'paper.json'
    config.write_text(json.dumps({'scanner': {'sensors': {'paper': 1.0}}}))
    args = [
        '--out',
        str(out), '--areas', '7', '8', '--rooms-per-area', '2', '--points',
        str(POINTS), '--seed', '5', '--asset-cache',
        str(asset_cache), '--config',
        str(config), '--quiet'
    ]
    assert main(args + ['--workers', '1']) == 0
    return out, args


def _rooms(out: Path) -> list[Path]:
    return sorted(p for p in out.glob('Area_*/*') if p.is_dir())


def same_tree(a: Path, b: Path) -> None:
    """Assert that the folders ``a`` and ``b`` hold the same files with the same bytes."""
    files_a = sorted(p.relative_to(a) for p in a.rglob('*') if p.is_file())
    files_b = sorted(p.relative_to(b) for p in b.rglob('*') if p.is_file())
    assert files_a == files_b
    for rel in files_a:
        assert filecmp.cmp(a / rel, b / rel, shallow=False), f'{rel} differs'


def test_room_files_match_meta(reference_run):
    out, _ = reference_run
    rooms = _rooms(out)
    assert [r.relative_to(out).as_posix() for r in rooms
            ] == ['Area_7/factory_1', 'Area_7/factory_2', 'Area_8/factory_1', 'Area_8/factory_2']
    for room in rooms:
        _check_room(room, POINTS)


def _check_room(room: Path, points: int) -> None:
    """S3DIS files of one room against its meta.json."""
    meta = json.loads((room / 'meta.json').read_text())
    assert meta['format'] == 'synthdet.room/1'
    assert meta['generator']['points'] == points
    polygon = np.asarray(meta['room']['polygon'])
    height = meta['room']['height']
    xyz, rgb = parse_lines(room / f'{room.name}.txt')
    assert len(xyz) == points and rgb.min() >= 0 and rgb.max() <= 255
    # all points inside the room (polygon shrunk/grown by the tolerance)
    assert xyz[:, 2].min() >= -TOL and xyz[:, 2].max() <= height + TOL
    assert points_in_polygon(xyz[:, :2], offset_polygon(polygon, -TOL)).all()
    # the room file is the concatenation of the annotation files
    annotations = sorted((room / 'Annotations').glob('*.txt'))
    joined = b''.join(p.read_bytes() for p in annotations)
    assert sorted(joined.splitlines()) == sorted(
        (room / f'{room.name}.txt').read_bytes().splitlines())
    objects = {o['instance']: o for o in meta['objects']}
    object_points = 0
    for path in annotations:
        cls, index = path.stem.split('_')
        assert index.isdigit() and cls in GENERATED_CLASSES + GENERATED_STRUCTURE_CLASSES
        pts, _ = parse_lines(path)
        if cls in GENERATED_CLASSES or cls == 'clutter':
            box = objects[path.stem]['box']
            yaw = box['yaw']
            rel = pts[:, :2] - np.asarray(box['center'][:2])
            local = rel @ np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
            half = np.asarray(box['size']) / 2
            assert np.all(np.abs(local) <= half[:2] + TOL), path
            assert np.all(np.abs(pts[:, 2] - box['center'][2]) <= half[2] + TOL), path
            object_points += len(pts) * (cls != 'clutter')
        elif cls == 'floor':
            assert np.abs(pts[:, 2]).max() <= TOL
        elif cls == 'ceiling':
            assert np.abs(pts[:, 2] - height).max() <= TOL
        elif cls in ('wall', 'door', 'window'):
            # on the wall's segment of the polygon
            openings = {o['instance']: o for o in meta['room']['openings']}
            edge = int(index) - 1 if cls == 'wall' else openings[path.stem]['wall']
            p0, p1 = polygon[edge], polygon[(edge + 1) % len(polygon)]
            d = (p1 - p0) / np.linalg.norm(p1 - p0)
            dist = (pts[:, 0] - p0[0]) * d[1] - (pts[:, 1] - p0[1]) * d[0]
            assert np.abs(dist).max() <= TOL, path
    movable = [o for o in meta['objects'] if o['class'] in GENERATED_CLASSES]
    if movable:  # object share of the points, exactly as requested
        assert object_points == round(0.5 * points) == meta['generator']['object_points']


def test_scene_export_matches_the_layout_boxes(asset_cache):
    """The bpy objects are placed exactly where meta.json says (yaw convention included)."""
    from generator.config import load_config
    from generator.layout import catalog_from_library, generate_layout
    from generator.pipeline import RunOptions, open_library
    from generator.scene import RoomScene, export_triangles
    options = RunOptions(
        out='',
        points=1,
        object_ratio=0.5,
        seed=0,
        config=load_config(),
        asset_cache=str(asset_cache))
    library = open_library(options)
    by_name = {i.name: i for c in library.classes() for i in library.instances(c)}
    layout = generate_layout(
        np.random.default_rng(11), catalog_from_library(library), options.config)
    assert layout.objects
    scene = RoomScene(lambda cls, name: by_name[name].mesh_arrays())
    scene.build(layout, np.random.default_rng(0))
    triangles, names, classes = export_triangles()
    for obj in layout.objects:
        part = names.index(obj.instance)
        assert classes[part] == obj.cls
        verts = triangles.vertices[np.unique(triangles.triangles[triangles.part == part])]
        if obj.cls == 'clutter':
            continue
        local, _, colors = by_name[obj.spec.name].mesh_arrays()
        c, s = np.cos(obj.yaw), np.sin(obj.yaw)
        expected = local @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + obj.base
        assert np.allclose(np.sort(verts, axis=0), np.sort(expected, axis=0), atol=1e-5)
        assert np.array_equal(triangles.colors[triangles.part == part], colors)
    assert {'floor', 'ceiling', 'wall'} <= set(classes)


def test_workers_and_shards_give_byte_identical_files(reference_run, tmp_path):
    out, args = reference_run
    parallel = tmp_path / 'parallel'
    assert main([*args, '--out', str(parallel), '--workers', '2']) == 0
    same_tree(out, parallel)
    sharded = tmp_path / 'sharded'
    assert main([*args, '--out', str(sharded), '--shard', '2/3']) == 0
    assert len(_rooms(sharded)) == 1  # rooms 2, 5, 8, ... of the run: Area_7/factory_2
    assert main([*args, '--out', str(sharded), '--shard', '1/3']) == 0
    assert main([*args, '--out', str(sharded), '--shard', '3/3']) == 0
    same_tree(out, sharded)


def test_resume_completes_an_interrupted_run(reference_run, tmp_path):
    out, args = reference_run
    resumed = tmp_path / 'resumed'
    shutil.copytree(out, resumed)
    # an interrupted run: one room never started, one left half-written in its temp folder
    shutil.rmtree(resumed / 'Area_8' / 'factory_2')
    partial = resumed / 'Area_8' / f'{TMP_PREFIX}factory_1.12345'
    shutil.move(str(resumed / 'Area_8' / 'factory_1'), str(partial))
    (partial / 'factory_1.txt').write_bytes(b'1.0 2.0\n')
    (resumed / 'Area_8' / f'{TMP_PREFIX}factory_1.12345.blend').write_bytes(b'partial')
    finished = resumed / 'Area_7' / 'factory_1' / 'factory_1.txt'
    stamp = finished.stat().st_mtime_ns
    os.utime(finished, ns=(stamp - 10**9, stamp - 10**9))
    assert main([*args, '--out', str(resumed), '--workers', '2']) == 0
    same_tree(out, resumed)
    assert not list(resumed.glob(f'Area_*/{TMP_PREFIX}*'))
    assert finished.stat().st_mtime_ns == stamp - 10**9  # finished rooms are not redone


def test_resume_after_a_killed_run(reference_run, tmp_path):
    """SIGKILL a real run once its first room is published, then restart it."""
    out, args = reference_run
    killed = tmp_path / 'killed'
    command = [sys.executable, '-m', 'generator', *args, '--out', str(killed)]
    process = subprocess.Popen(
        command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while (process.poll() is None and time.monotonic() < deadline
           and not (killed / 'Area_7' / 'factory_1').exists()):
        time.sleep(0.02)
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert (killed / 'Area_7' / 'factory_1' / 'meta.json').exists()
    assert main([*args, '--out', str(killed)]) == 0
    same_tree(out, killed)
    assert not list(killed.glob(f'Area_*/{TMP_PREFIX}*'))


def test_optional_outputs_in_l_and_u_rooms(asset_cache, tmp_path):
    out = tmp_path / 'extras'
    config = tmp_path / 'shapes.yaml'
    config.write_text('room:\n  shapes: {L: 0.5, U: 0.5}\n  windows: [2, 3]\n'
                      'scanner:\n  sensors: {paper: 1.0}\n')
    assert main([
        '--out',
        str(out), '--areas', '9', '--rooms-per-area', '2', '--points', '5000', '--asset-cache',
        str(asset_cache), '--config',
        str(config), '--ply', '--preview', '--save-blend', '--quiet'
    ]) == 0
    shapes = set()
    for room in _rooms(out):
        _check_room(room, 5000)
        shapes.add(json.loads((room / 'meta.json').read_text())['room']['shape'])
    assert shapes <= {'L', 'U'} and shapes
    room = out / 'Area_9' / 'factory_1'
    data = (room / 'factory_1.ply').read_bytes()
    header, body = data.split(b'end_header\n', 1)
    assert b'element vertex 5000' in header and len(body) == 5000 * (3 * 8 + 3 + 2 * 4)
    labels = json.loads((room / 'factory_1.ply.json').read_text())
    assert 'floor_1' in labels['instances']
    from PIL import Image
    with Image.open(room / 'factory_1.png') as image:
        pixels = np.asarray(image.convert('RGB')).reshape(-1, 3)
    assert len(pixels) > 100 * 100 and len(np.unique(pixels, axis=0)) > 3
    # the saved scene opens in Blender with one object per annotated element of the room
    meta = json.loads((room / 'meta.json').read_text())
    script = ('import bpy, json, sys; bpy.ops.wm.open_mainfile(filepath=sys.argv[1]); '
              'print(json.dumps([o["synthdet_instance"] '
              'for o in bpy.data.collections["synthdet_room"].objects]))')
    result = subprocess.run(
        [sys.executable, '-c', script, str(room / 'factory_1.blend')],
        capture_output=True,
        text=True,
        timeout=120)
    names = json.loads(result.stdout.strip().splitlines()[-1])
    assert {o['instance']
            for o in meta['objects']} | {'floor_1', 'ceiling_1', 'wall_1'} <= set(names)


def _points_on_edge(xyz: np.ndarray, a: np.ndarray, b: np.ndarray, height: float) -> int:
    """Scan points on the wall above floor edge a-b (within 1 cm, away from its ends)."""
    length = float(np.linalg.norm(b - a))
    along = (xyz[:, :2] - a) @ (b - a) / length
    across = np.abs(np.cross(b - a, xyz[:, :2] - a)) / length
    wall = (xyz[:, 2] > 0.1) & (xyz[:, 2] < height - 0.1)
    return int(np.sum(wall & (across < 0.01) & (along > 0.05) & (along < length - 0.05)))


@pytest.mark.parametrize(
    'polygon',
    [
        [(0, 0), (0, 6), (2, 6), (2, 3), (4, 3), (4, 6), (7, 6), (7, 0)],  # U
        [(0, 0), (0, 6), (3, 6), (3, 3), (7, 3), (7, 0)],  # L
        [(0, 0), (0, 4), (6, 4), (6, 0)],  # box: the paper's single cross
    ])
def test_sensor_path_crosses_every_cell_of_the_room(polygon):
    from synthdet.geometry import grid_cells
    polygon = np.array(polygon, float)
    path, segments = sensor_path(polygon, 3.0, np.random.default_rng(3), steps=500)
    cells = grid_cells(polygon)
    assert len(segments) == 2 * len(cells) and len(path) == 500
    assert points_in_polygon(path[:, :2], polygon).all()
    for cell, pair in zip(cells, segments.reshape(-1, 2, 2, 2)):
        d1, d2 = pair[0, 1] - pair[0, 0], pair[1, 1] - pair[1, 0]
        assert abs(np.dot(d1, d2)) < 1e-9  # each cell's cross is at right angles
        lo, hi = cell.min(axis=0), cell.max(axis=0)
        inside = np.all((path[:, :2] > lo) & (path[:, :2] < hi), axis=1)
        assert inside.sum() >= 500 // len(segments)  # the sensor walks through every cell


def test_every_wall_of_generated_u_rooms_is_scanned(asset_cache, tmp_path):
    # A single cross through the base of a U left an arm's inner wall without a point.
    config = tmp_path / 'u.yaml'
    config.write_text('room:\n  shapes: {U: 1.0}\nscanner:\n  sensors: {paper: 1.0}\n')
    out = tmp_path / 'u'
    generate_rooms(out, 9, 3, 20000, 2, '--asset-cache', asset_cache, '--config', config)
    for room in _rooms(out):
        meta = json.loads((room / 'meta.json').read_text())
        polygon, height = np.asarray(meta['room']['polygon']), meta['room']['height']
        xyz, _ = parse_lines(room / f'{room.name}.txt')
        counts = [
            _points_on_edge(xyz, a, b, height)
            for a, b in zip(polygon, np.roll(polygon, -1, axis=0))
        ]
        assert min(counts) >= 20, (room.name, counts)


def box(lo, hi, inward: bool) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and triangles (12, 3) of an axis-aligned box, the first two triangles its
    bottom; faces towards the inside when ``inward``."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0], [x0, y0, z1],
                  [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6],
                  [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return v, (f[:, ::-1] if inward else f)


def box_room_scene() -> tuple[TriangleScene, np.ndarray]:
    """A 6 x 4 x 3 m box room (2 parts) with a 1 m cube (movable part 2) on the floor."""
    room_v, room_f = box((0, 0, 0), (6, 4, 3), True)
    cube_v, cube_f = box((2, 1, 0), (3, 2, 1), False)
    vertices = np.concatenate([room_v, cube_v])
    triangles = np.concatenate([room_f, cube_f + 8]).astype(np.int32)
    part = np.array([0, 0] + [1] * 10 + [2] * 12, dtype=np.int32)  # floor, walls+ceiling, cube
    colors = np.array([[10, 20, 30]] * 2 + [[200, 200, 200]] * 10 + [[255, 0, 0]] * 12, np.uint8)
    scene = TriangleScene(vertices, triangles, colors, part, np.array([False, False, True]))
    return scene, np.array([[0, 0], [0, 4], [6, 4], [6, 0]], float)


def test_scanner_on_a_hand_made_room():
    scene, polygon = box_room_scene()
    config = dict(DEFAULTS['scanner'], batch_rays=8192)
    path, segments = sensor_path(polygon, 3.0, np.random.default_rng(0))
    assert np.allclose(path[:, 2], 2.0) and points_in_polygon(path[:, :2], polygon).all()
    d1, d2 = segments[0, 1] - segments[0, 0], segments[1, 1] - segments[1, 0]
    assert abs(np.dot(d1, d2)) < 1e-9  # crossing at right angles
    scan = Scanner(scene).scan(path, 10000, 0.3, np.random.default_rng(1), config)
    assert len(scan.xyz) == 10000 and scan.object_points == 3000
    on_cube = scan.part == 2
    assert on_cube.sum() == 3000 and np.all(scan.rgb[on_cube] == [255, 0, 0])
    cube = scan.xyz[on_cube]
    assert np.all((cube >= np.array([2, 1, 0]) - 1e-4) & (cube <= np.array([3, 2, 1]) + 1e-4))
    floor = scan.xyz[scan.part == 0]
    assert np.abs(floor[:, 2]).max() < 1e-4 and np.all(scan.rgb[scan.part == 0] == [10, 20, 30])
    # the cube hides the floor under it from every ray
    assert not np.any((floor[:, 0] > 2.01) & (floor[:, 0] < 2.99) & (floor[:, 1] > 1.01)
                      & (floor[:, 1] < 1.99))
    # noise models: range noise moves floor points off the plane, dropout costs extra rays
    noisy = Scanner(scene).scan(path, 10000, 0.3, np.random.default_rng(1),
                                dict(config, range_noise=0.01, angular_jitter=0.002, dropout=0.5))
    noisy_floor = noisy.xyz[noisy.part == 0]
    assert 0.002 < np.std(noisy_floor[:, 2]) < 0.05
    assert noisy.rays_cast > scan.rays_cast
    assert len(noisy.xyz) == 10000
    # paper-faithful uniform directions also reach the requested ratio
    uniform = Scanner(scene).scan(path, 4000, 0.5, np.random.default_rng(2),
                                  dict(config, aim_at_objects=False))
    assert (uniform.part == 2).sum() == 2000
    cube = uniform.xyz[uniform.part == 2]
    assert np.all((cube >= np.array([2, 1, 0]) - 1e-4) & (cube <= np.array([3, 2, 1]) + 1e-4))


def test_scanner_cast_is_the_same_on_one_and_two_threads():
    """Threads cast slices of a batch: the same hits, in ray order, as one thread; a miss is
    inf and the largest uint32; the distance is in units of the direction's length."""
    scene, _ = box_room_scene()
    rng = np.random.default_rng(0)
    origins = np.concatenate([
        rng.uniform([0.5, 0.5, 1.5], [5.5, 3.5, 2.5], (60000, 3)),
        np.tile([[3.0, 2.0, 5.0]], (40000, 1))
    ])  # above the ceiling
    directions = random_directions(rng, 100000)
    directions[60000:] = [0.0, 0.0, 2.0]  # upwards from above the room: misses
    one, two = Scanner(scene, threads=1), Scanner(scene, threads=2)
    t1, p1 = one.cast(one.full_scene, origins, directions)
    t2, p2 = two.cast(two.full_scene, origins, directions)
    assert t1.dtype == np.float32 and p1.dtype == np.uint32
    assert np.array_equal(t1, t2) and np.array_equal(p1, p2)
    assert np.isfinite(t1[:60000]).all() and np.isinf(t1[60000:]).all()
    assert np.all(p1[60000:] == np.iinfo(np.uint32).max)
    down = one.cast(one.full_scene, np.array([[1.0, 1.0, 2.0]]), np.array([[0.0, 0.0, -2.0]]))
    assert down[0][0] == pytest.approx(1.0) and scene.part[down[1][0]] == 0  # the floor
    config = dict(DEFAULTS['scanner'], batch_rays=65536)
    path, _ = sensor_path(box_room_scene()[1], 3.0, np.random.default_rng(0))
    scans = [s.scan(path, 50000, 0.3, np.random.default_rng(1), config) for s in (one, two)]
    assert np.array_equal(scans[0].xyz, scans[1].xyz)
    assert np.array_equal(scans[0].part, scans[1].part)


def test_user_library_with_two_classes(tmp_path):
    """--library DIR: only the classes of the user's <class>.blend files appear."""
    from generator.assets import build_library
    library = tmp_path / 'library'
    build_library(library, instances_per_class=2, seed=4, classes=('table', 'yumi'))
    out = tmp_path / 'out'
    config = tmp_path / 'config.json'
    config.write_text(
        json.dumps({'probabilities': {
            'table': 1.0,
            'sofa': 0.0,
            'yumi': 1.0,
            '3dprinter': 0.0
        }}))
    assert main([
        '--out',
        str(out), '--areas', '9', '--rooms-per-area', '1', '--points', '3000', '--library',
        str(library), '--config',
        str(config), '--quiet'
    ]) == 0
    meta = json.loads((out / 'Area_9' / 'factory_1' / 'meta.json').read_text())
    classes = {o['class'] for o in meta['objects']}
    assert {'table', 'yumi'} <= classes <= {'table', 'yumi', 'clutter'}
    assert meta['generator']['library'] == 'user'
    assert {o['asset'].split('/')[0]
            for o in meta['objects'] if o['class'] != 'clutter'} == {'table', 'yumi'}
