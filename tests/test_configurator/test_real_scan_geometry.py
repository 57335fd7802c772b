"""Corners and up axis on scans with the properties of real ones, made here (never copied):
a reconstructed mesh sampled per vertex (floor sparser than the walls, no ceiling), an open-top
room, furniture in front of a wall the sensor never saw, a single depth view of one side of a
room, a y-up room and a depth camera's own frame (y down, z forward); and tools/scan2cad.py
end to end on three of them with the tiny model of tests/test_tools/test_scan2cad.py and the real
``freecadcmd`` (and ``configurator freecad`` finding the corners itself)."""
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

from configurator.__main__ import main as configurator_main
from configurator.corners import CornerDetectionError, CornerParams, detect_corners, room_outline
from configurator.corners.levels import floor_prominence
from synthdet.contracts import read_corners, read_predictions, write_predictions
from synthdet.geometry import (distance_to_polygon, first_self_crossing, points_in_polygon,
                               rotation2d, signed_area)
from synthdet.prepare import detect_up_axis, prepare_scan
from synthdet.scan_io import LoadedScan, load_scan, write_scan
from tests.room_scans import outside_box, sample_box, sample_flat, sample_walls
from tests.test_tools.test_scan2cad import TINY, predict_scan, tiny  # noqa: F401 (tiny: the model fixture)
from tests.test_tools.test_tr3d_tools import load_tool

WIDTH, DEPTH = 6.0, 5.0
RECTANGLE = np.array([[0.0, 0.0], [0.0, DEPTH], [WIDTH, DEPTH], [WIDTH, 0.0]])


def room_scan(*,
              height: float = 2.7,
              density: float = 1500.0,
              floor_share: float = 1.0,
              ceiling: bool = True,
              furniture: int = 3,
              furniture_density: float = 4.0,
              seed: int = 0,
              width: float = WIDTH,
              depth: float = DEPTH) -> np.ndarray:
    """A ``width`` x ``depth`` room (corner at the origin, floor at z = 0) as x y z r g b:
    floor (``floor_share`` of the walls' density per m^2: a mesh sampled per vertex has a
    sparse floor), walls with a door and a window, an optional ceiling and ``furniture``
    boxes standing free (``furniture_density`` times as dense)."""
    rng = np.random.default_rng(seed)
    polygon = np.array([[0.0, 0.0], [0.0, depth], [width, depth], [width, 0.0]])
    floor = sample_flat(polygon, 0.0, int(density * width * depth * floor_share), rng,
                        (150, 140, 130))
    parts = []
    if ceiling:
        parts.append(sample_flat(polygon, height, int(density * width * depth), rng,
                                 (230, 230, 225)))
    walls = sample_walls(polygon, height, density, rng, openings=True)
    for _ in range(furniture):
        size = np.array([rng.uniform(0.5, 1.2), rng.uniform(0.5, 0.9), rng.uniform(0.45, 0.8)])
        box = (rng.uniform([1.5, 1.5], [width - 1.5, depth - 1.5]), size,
               rng.uniform(0, math.pi), False)
        parts.append(sample_box(box, furniture_density * density, rng))
        floor = outside_box(floor, box, 0.0)
    points = np.concatenate([floor, walls, *parts])
    return points[rng.permutation(len(points))]


def depth_view(points: np.ndarray, camera: np.ndarray, half_width: float = 30.0,
               half_height: float = 23.0) -> np.ndarray:
    """What a depth camera at ``camera`` looking along +y sees (a frustum, half angles in
    degrees), in an upright camera frame: z up, the camera at the origin (as SUN RGB-D)."""
    relative = points[:, :3] - camera
    forward = relative[:, 1]
    keep = (forward > 0.4) & \
        (np.abs(np.arctan2(relative[:, 0], forward)) < math.radians(half_width)) & \
        (np.abs(np.arctan2(relative[:, 2], forward)) < math.radians(half_height))
    view = points[keep].copy()
    view[:, :3] -= camera
    return view


def occluded_view(points: np.ndarray, camera: np.ndarray, look: np.ndarray,
                  half_width: float = 35.0, half_height: float = 30.0) -> np.ndarray:
    """What a depth camera at ``camera`` looking towards the plan point ``look`` sees, in its
    upright frame (z up, camera at the origin, looking along +y; :func:`depth_view`), and
    only the nearest surface of every 0.4 degree ray bin (points within 5 cm of it)."""
    turn = rotation2d(math.pi / 2 - math.atan2(*(look - camera[:2])[::-1]))
    turned = points.copy()
    turned[:, :2] = (points[:, :2] - camera[:2]) @ turn.T + camera[:2]
    view = depth_view(turned, camera, half_width, half_height)
    xyz = view[:, :3]
    distance = np.linalg.norm(xyz, axis=1)
    azimuth = np.degrees(np.arctan2(xyz[:, 0], xyz[:, 1]))
    elevation = np.degrees(np.arcsin(xyz[:, 2] / distance))
    rays = np.floor(azimuth / 0.4).astype(np.int64) * 100_000 + \
        np.floor(elevation / 0.4).astype(np.int64)
    _, inverse = np.unique(rays, return_inverse=True)
    nearest = np.full(inverse.max() + 1, np.inf)
    np.minimum.at(nearest, inverse, distance)
    return view[distance < nearest[inverse] + 0.05]


def in_view(plan: np.ndarray, camera: np.ndarray, look: np.ndarray) -> np.ndarray:
    """Plan points of the room in the frame of :func:`occluded_view`."""
    turn = rotation2d(math.pi / 2 - math.atan2(*(look - camera[:2])[::-1]))
    return (plan - camera[:2]) @ turn.T


def assert_rectangle(corners: np.ndarray, tolerance: float = 0.03) -> None:
    assert len(corners) == 4, corners
    errors = [np.linalg.norm(corners - corner, axis=1).min() for corner in RECTANGLE]
    assert max(errors) < tolerance, corners


def loaded(points: np.ndarray) -> LoadedScan:
    return LoadedScan(points=points.astype(np.float64), origin=np.zeros(3), report=[],
                      source='made by the test')


# --------------------------------------------------------------------------- corners


def test_sparse_floor_of_a_mesh_sample_is_the_floor():
    """A floor holding 8 % of the walls' density per m^2 is under 3 times as dense as a slab
    of the walls (what the old rule demanded), but it spans the room: it is the floor."""
    points = room_scan(floor_share=0.08, ceiling=False, seed=1)
    outline = detect_corners(points)
    assert floor_prominence(points[:, 2], 0.0, 2.7, CornerParams()) < 3.0
    assert outline.quality['floor_cover'] > 0.9
    assert outline.floor_z == pytest.approx(0.0, abs=0.01)
    assert_rectangle(outline.corners)
    assert not outline.approximate


def test_open_top_room_has_no_ceiling_and_walls_of_the_default_height():
    """No ceiling, and three cabinets whose tops (1.4 m) are the densest upper level: they
    were taken for the ceiling. They cover a strip of the room, no ceiling does that."""
    rng = np.random.default_rng(0)
    cabinets = [
        sample_box((np.array([x, DEPTH - 0.3]), np.array([1.0, 0.5, 1.4]), 0.0, True), 6000.0,
                   rng) for x in (1.0, 2.5, 4.0)
    ]
    points = np.vstack([room_scan(ceiling=False, height=2.2, furniture=0, seed=2), *cabinets])
    outline = detect_corners(points)
    assert outline.quality['ceiling_found'] == 0.0
    assert outline.ceiling_z == pytest.approx(CornerParams.default_wall_height, abs=0.01)
    assert any('no ceiling found' in note for note in outline.notes)
    assert_rectangle(outline.corners)


def test_furniture_in_front_of_an_unseen_wall_stays_out_of_the_outline():
    """A sofa 0.3-0.6 m in front of a wall hides it and the floor behind it (a reconstructed
    mesh has nothing there). The sofa's back faces the wall but does not reach up as a wall
    does, so the wall's two seen halves make one straight wall: no bite around the sofa."""
    for gap in (0.3, 0.6):
        points = room_scan(ceiling=False, height=2.4, furniture=2, seed=int(gap * 10))
        hidden = (points[:, 0] > 1.5) & (points[:, 0] < 4.5) & \
            (points[:, 1] > DEPTH - 0.95 - gap)
        sofa = sample_box((np.array([3.0, DEPTH - gap - 0.45]), np.array([3.0, 0.9, 0.85]),
                           0.0, False), 6000.0, np.random.default_rng(0))
        outline = detect_corners(np.vstack([points[~hidden], sofa]))
        assert_rectangle(outline.corners)


def narrow_view() -> np.ndarray:
    """One depth frame (16 degrees wide) of a 7 m x 6 m room from 1.4 m above its floor, from
    one corner towards the opposite one: a strip of floor and the far corner's walls."""
    room = room_scan(width=7.0, depth=6.0, furniture=5, seed=4)
    return occluded_view(room, np.array([0.5, 0.5, 1.4]), np.array([6.5, 5.5]), half_width=8.0)


def test_narrow_view_gives_an_approximate_floor_holding_the_points():
    """A view of less than half the room (:func:`narrow_view`): neither the traced outline
    nor the one built on the walls is the room; the approximate floor is a simple clockwise
    polygon on the floor level that holds the points. (A wider view of one side of a room
    gets a partial outline: tests/test_configurator/test_wall_evidence.py.)"""
    view = narrow_view()
    outline = room_outline(view)
    assert outline.approximate and outline.quality['approximate_floor'] == 1.0
    assert any(note.startswith('approximate floor') and 'less than half the room' in note
               for note in outline.notes)
    assert outline.floor_z == pytest.approx(-1.4, abs=0.02)
    assert 3 <= len(outline.corners) <= CornerParams.max_approximate_corners
    assert first_self_crossing(outline.corners) is None and signed_area(outline.corners) < 0
    held = points_in_polygon(view[:, :2], outline.corners) | \
        (distance_to_polygon(view[:, :2], outline.corners) < 0.02)  # the far wall is an edge
    assert held.mean() > 0.95


def test_room_outline_is_the_traced_outline_when_there_is_one():
    points = room_scan(seed=5)
    traced, outline = detect_corners(points), room_outline(points)
    np.testing.assert_array_equal(traced.corners, outline.corners)
    assert outline.quality == traced.quality and not outline.approximate
    assert outline.quality['ceiling_found'] == 1.0
    assert outline.ceiling_z == pytest.approx(2.7, abs=0.01)


# --------------------------------------------------------------------------- up axis


def test_y_up_room_with_a_sparse_floor_and_a_full_ceiling_is_not_upside_down():
    """The ceiling holds ten times the floor's points: the plane count says the ceiling is
    the floor. The furniture inside the room stands on the floor."""
    points = room_scan(floor_share=0.1, furniture=4, furniture_density=1.0, seed=6)
    y_up = points.copy()
    y_up[:, :3] = np.column_stack([points[:, 0], points[:, 2], -points[:, 1]])
    assert detect_up_axis(y_up[:, :3]) == '+y'
    prepared = prepare_scan(loaded(y_up))
    heights = prepared.points[:, 2]
    assert np.percentile(heights, 1) > -0.05 and np.percentile(heights, 99) < 2.75


def test_camera_frame_of_a_depth_view_has_y_down():
    """A depth camera's own frame (x right, y down, z forward, as PCL and Kinect save it)."""
    room = room_scan(width=7.0, depth=6.0, furniture=5, seed=7)
    view = depth_view(room, np.array([3.5, 0.3, 1.4]))
    camera = np.column_stack([view[:, 0], -view[:, 2], view[:, 1]])
    assert detect_up_axis(camera) == '-y'
    assert detect_up_axis(view[:, :3]) == '+z'  # the same view upright


def test_camera_frame_read_from_a_file_has_y_down(tmp_path):
    """Read from a file, the points come in a local frame (shifted by whole metres): the
    camera is still found at the file's origin."""
    room = room_scan(width=7.0, depth=6.0, furniture=5, seed=7)
    view = depth_view(room, np.array([3.5, 0.3, 1.4]))
    frame = view.copy()
    frame[:, :3] = np.column_stack([view[:, 0], -view[:, 2], view[:, 1]])
    path = tmp_path / 'frame.ply'
    write_scan(path, frame)
    prepared = prepare_scan(load_scan(path))
    assert 'up axis: -y' in '\n'.join(prepared.report)


def test_tilted_z_up_room_with_a_sparse_floor_keeps_z():
    """A mesh sample's floor (15 % density) tilted 4 degrees holds fewer points than one
    wall, yet the room is wider than tall: z stays up."""
    points = room_scan(floor_share=0.15, ceiling=False, furniture=5, seed=8)
    tilt = math.radians(4.0)
    turn = np.array([[math.cos(tilt), 0, math.sin(tilt)], [0, 1, 0],
                     [-math.sin(tilt), 0, math.cos(tilt)]])
    assert detect_up_axis(points[:, :3] @ turn.T) == '+z'


# --------------------------------------------------------------------------- scan2cad


def open_top_scan() -> np.ndarray:
    """The open-top room of the corner test: no ceiling, cabinets 1.4 m tall along a wall."""
    rng = np.random.default_rng(0)
    cabinets = [
        sample_box((np.array([x, DEPTH - 0.3]), np.array([1.0, 0.5, 1.4]), 0.0, True), 6000.0,
                   rng) for x in (1.0, 2.5, 4.0)
    ]
    return np.vstack([room_scan(ceiling=False, height=2.2, furniture=0, seed=2), *cabinets])


@pytest.fixture(scope='module')
def real_like_scans(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('real_like')
    scans = {
        'sparse_floor': room_scan(floor_share=0.08, ceiling=False, seed=1),
        'one_sided': depth_view(room_scan(width=7.0, depth=6.0, furniture=5, seed=4),
                                np.array([3.5, 0.3, 1.4])),
        'narrow_view': narrow_view(),
        'open_top': open_top_scan(),
    }
    paths = {}
    for name, points in scans.items():
        paths[name] = folder / f'{name}.ply'
        write_scan(paths[name], points)
    return paths


def document_property(document: Path, name: str) -> str:
    """The value of the Bool property ``name`` in a .FCStd's Document.xml."""
    with zipfile.ZipFile(document) as archive:
        xml = archive.read('Document.xml').decode('utf-8')
    start = xml.index('<Bool value="', xml.index(f'<Property name="{name}"'))
    return xml[start + len('<Bool value="'):].split('"', 1)[0]


def scan2cad_args(tiny: dict, scan: Path, out: Path, threshold: str, *options: str) -> list[str]:
    return [
        str(scan), '--config',
        str(TINY), '--checkpoint',
        str(tiny['checkpoint']), '--out',
        str(out), '--score-thr', threshold, '--device', 'cpu', *options
    ]


def best_scores_threshold(tiny: dict, scan: Path, folder: Path, keep: int = 8) -> str:
    """A score threshold keeping the weak model's best ``keep`` boxes of ``scan``."""
    scores = sorted((d['score'] for d in predict_scan(tiny, scan, folder)['detections']),
                    reverse=True)
    assert scores, f'the tiny model found nothing in {scan.name}'
    return str(scores[min(keep, len(scores)) - 1])


@pytest.mark.parametrize('name', ['sparse_floor', 'one_sided', 'narrow_view', 'open_top'])
def test_scan2cad_writes_a_document_with_the_objects_and_a_marked_floor(
        tiny, real_like_scans, tmp_path, capsys, name):
    """Before, the sparse floor and the one-sided view exited 2 without a document; the
    one-sided view's document now has the walls it sees (a partial outline), a view of less
    than half the room an approximate floor."""
    scan = real_like_scans[name]
    threshold = best_scores_threshold(tiny, scan, tmp_path / 'scores')
    out = tmp_path / f'{name}.FCStd'
    scan2cad = load_tool('scan2cad')
    result = scan2cad.scan_to_cad(scan2cad.parse_args(scan2cad_args(tiny, scan, out, threshold)),
                                  lambda line: None)
    assert out.is_file() and result['document'] == str(out.resolve())
    detections = read_predictions(str(out.with_suffix('.pred.json')))['detections']
    assert detections and result['objects']
    with zipfile.ZipFile(out) as archive:
        xml = archive.read('Document.xml').decode('utf-8')
    assert all(f'name="{item["name"]}"' in xml for item in result['objects'])
    corners = read_corners(str(out.with_suffix('.corners.json')))
    approximate = corners['quality']['approximate_floor'] == 1.0
    assert document_property(out, 'ApproximateFloor') == str(approximate).lower()
    assert document_property(out, 'CeilingFound') == \
        str(corners['quality']['ceiling_found'] == 1.0).lower()
    if name == 'one_sided':
        assert not approximate and any('partial outline' in w for w in result['warnings'])
    if name == 'narrow_view':
        assert approximate and any('approximate floor' in w for w in result['warnings'])
        assert 'Floor (approximate)' in xml
    if name == 'open_top':
        assert corners['quality']['ceiling_found'] == 0.0
        assert corners['ceiling_z'] - corners['floor_z'] == pytest.approx(2.5, abs=0.01)
    # the command line: exit 0, the notes as warnings on stderr
    assert scan2cad.main(scan2cad_args(tiny, scan, tmp_path / 'again.FCStd', threshold)) == 0
    stderr = capsys.readouterr().err
    assert ('approximate floor' in stderr) == approximate


def test_failed_scan2cad_run_leaves_the_previous_outputs_as_they_were(
        tiny, real_like_scans, tmp_path):
    scan = real_like_scans['one_sided']
    threshold = best_scores_threshold(tiny, scan, tmp_path / 'scores', keep=3)
    out = tmp_path / 'out' / 'room.FCStd'
    out.parent.mkdir()
    scan2cad = load_tool('scan2cad')
    assert scan2cad.main(scan2cad_args(tiny, scan, out, threshold)) == 0
    outputs = [out, out.with_suffix('.pred.json'), out.with_suffix('.corners.json')]
    before = [path.read_bytes() for path in outputs]
    # a different scan whose run fails in FreeCAD, the last stage
    other = real_like_scans['open_top']
    assert scan2cad.main(scan2cad_args(tiny, other, out, threshold, '--freecadcmd',
                                       'false')) == 1
    assert [path.read_bytes() for path in outputs] == before
    assert sorted(path.name for path in out.parent.iterdir()) == sorted(p.name for p in outputs)


@pytest.mark.parametrize('points,message', [
    (np.zeros((0, 6)), 'no points'),
    (np.full((200, 3), np.nan), 'non-finite'),
    (np.column_stack([np.random.default_rng(0).uniform(0, 5, (5000, 2)), np.zeros(5000)]),
     'only 0.00 m tall'),
])
def test_room_outline_refuses_a_scan_with_no_room_at_all(points, message):
    with pytest.raises(CornerDetectionError, match=message):
        room_outline(points)


def test_freecad_without_corners_gives_a_narrow_view_an_approximate_floor(
        real_like_scans, tmp_path):
    """``configurator freecad`` without ``--corners`` finds them itself, approximate floor
    allowed: a document with both detections, marked, exit 0 (before: exit 2, no document)."""
    scan = real_like_scans['narrow_view']
    predictions = tmp_path / 'view.pred.json'
    write_predictions(predictions, {
        'format': 'synthdet.predictions/1', 'scan': scan.name, 'model': 'by hand',
        'classes': ['table', 'chair'],
        'detections': [
            {'class': 'table', 'score': 0.9, 'center': [0.0, 4.0, -1.0],
             'size': [1.2, 0.8, 0.75], 'yaw': 0.0},
            {'class': 'chair', 'score': 0.8, 'center': [1.0, 4.6, -1.0],
             'size': [0.5, 0.5, 0.9], 'yaw': 0.3},
        ]})
    out = tmp_path / 'view.FCStd'
    assert configurator_main(['freecad', '--scan', str(scan), '--predictions', str(predictions),
                              '--out', str(out)]) == 0
    assert document_property(out, 'ApproximateFloor') == 'true'
    with zipfile.ZipFile(out) as archive:
        xml = archive.read('Document.xml').decode('utf-8')
    assert 'Floor (approximate)' in xml and xml.count('DetectedClass') >= 2
