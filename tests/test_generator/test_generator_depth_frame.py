"""The depth-frame sensor (generator/depth_frame.py): one RGB-D camera frame per room, on real
Embree. Hand-made box rooms for the frustum, the range window, what the frame sees and what it
cannot, depth edges and sparse objects; small rooms from ``python -m generator`` for the
meta.json record, the annotations and determinism; configuration errors."""
import json
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest

from generator.config import DEFAULTS, load_config
from generator.depth_frame import DepthCamera, cast_depth_frame, depth_frame_returns
from generator.scanner import Scanner
from generator.sensor_common import ROOM_STRUCTURE, RoomGeometry
from generator.sensors import scan_room
from synthdet.geometry import distance_to_polygon
from synthdet.point_text import read_point_file
from tests.generator_runs import assert_sensor_config_error, generate_rooms, sensor_records
from tests.test_generator.test_generator_pipeline import same_tree
from tests.test_generator.test_generator_sensors import room_scene

FRAME = DEFAULTS['scanner']['depth_frame']
BATCH = 65536


def camera_axes(look: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The right and up vectors of a camera looking along ``look`` (no roll)."""
    right = np.array([look[1], -look[0], 0.0])
    right /= np.linalg.norm(right)
    return right, np.cross(right, look)


def in_frustum(xyz: np.ndarray, sensor: dict, slack: float) -> np.ndarray:
    """Per point: inside the recorded camera's field of view, ``slack`` in tangent units."""
    look = np.array(sensor['look'])
    right, up = camera_axes(look)
    rel = xyz - np.array(sensor['position'])
    ahead = rel @ look
    half = np.tan(np.radians(sensor['fov_deg']) / 2)
    return ((ahead > 0) & (np.abs(rel @ right) <= (half[0] + slack) * ahead)
            & (np.abs(rel @ up) <= (half[1] + slack) * ahead))


def box_room(size, cubes=()) -> tuple[Scanner, RoomGeometry]:
    """A box room (:func:`room_scene`) and its geometry for the sensors."""
    scanner = Scanner(room_scene(size, cubes))
    obstacles = np.array([[lo[:2], hi[:2]] for lo, hi, _ in cubes], float).reshape(-1, 2, 2)
    polygon = np.array([[0, 0], [0, size[1]], [size[0], size[1]], [size[0], 0]], float)
    return scanner, RoomGeometry(polygon, size[2], [], obstacles,
                                 np.array([False] + [True] * len(cubes)))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_frame_lies_in_the_frustum_and_range_and_sees_the_far_side_only(seed):
    size = (4.0, 3.5, 2.6)
    scanner, room = box_room(size, [((2.6, 2.4, 0.0), (3.2, 3.0, 0.9), (200, 0, 0))])
    # facing the room's centre: the walls next to the camera are then behind its view
    cfg = dict(DEFAULTS['scanner'], batch_rays=BATCH, depth_frame=dict(FRAME, aim_at_objects=0))
    scan, sensor = scan_room(scanner, room, 'depth_frame', 20000, 0.0,
                             np.random.default_rng(seed), cfg)
    assert sensor['model'] == 'depth_frame'
    assert len(scan.xyz) == 20000 - sensor['sparse_object_points']
    position = np.array(sensor['position'])
    # one pose near a wall, clear of the cube, at hand height, pitched down
    wall = min(position[0], position[1], size[0] - position[0], size[1] - position[1])
    assert FRAME['wall_distance'][0] <= wall <= FRAME['wall_distance'][1]
    gap = np.maximum(np.maximum(np.array([2.6, 2.4]) - position[:2],
                                position[:2] - np.array([3.2, 3.0])), 0.0)
    assert np.linalg.norm(gap) >= FRAME['object_clearance']
    assert FRAME['height'][0] <= position[2] <= FRAME['height'][1]
    assert FRAME['pitch_deg'][0] <= sensor['pitch_deg'] <= FRAME['pitch_deg'][1]
    assert np.allclose(scan.origin, position, atol=1e-5)  # meta.json keeps 6 decimals
    # every point in the field of view and the range window
    assert in_frustum(scan.xyz, sensor, 1e-4).all()
    distance = np.linalg.norm(scan.xyz - position, axis=1)
    assert distance.min() >= FRAME['min_range'] and distance.max() <= sensor['max_range']
    assert FRAME['max_range'][0] <= sensor['max_range'] <= FRAME['max_range'][1]
    # the wall nearest to the camera is behind it: no point on it; the farthest wall is seen
    planes = [(0, 0.0), (0, size[0]), (1, 0.0), (1, size[1])]
    gaps = [abs(position[axis] - plane) for axis, plane in planes]
    on_wall = [np.abs(scan.xyz[:, axis] - plane) < 0.03 for axis, plane in planes]
    assert not on_wall[int(np.argmin(gaps))].any()
    assert on_wall[int(np.argmax(gaps))].sum() > 500
    # nothing behind the camera: a frame is one side of the room
    look_xy = np.array(sensor['look'][:2])
    assert np.all((scan.xyz[:, :2] - position[:2]) @ look_xy > 0)


def test_depth_noise_grows_with_the_square_of_the_depth():
    """A wall seen straight on from 4.5 m and from 1.5 m: the spread of its points across the
    wall (the range error) grows as a + b * depth**2."""
    scanner, _ = box_room((6.0, 4.0, 3.0))
    quiet = dict(FRAME, edge_dropout=0.0, dark_dropout=0.0, shiny_dropout=0.0)
    stds = []
    for depth in (4.5, 1.5):  # the camera looks along -x at the wall x = 0
        camera = DepthCamera(np.array([depth, 2.0, 1.5]), np.array([-1.0, 0.0, 0.0]),
                             np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                             np.tan(np.radians([60.0, 47.0]) / 2), 5.0)
        scan, _ = cast_depth_frame(scanner, camera, 20000, np.random.default_rng(5), quiet,
                                   BATCH, np.array([False]))
        centre = scan.xyz[(np.abs(scan.xyz[:, 1] - 2.0) < 0.3) & (np.abs(scan.xyz[:, 2] - 1.5) <
                                                                   0.3)]
        assert len(centre) > 200
        stds.append(np.std(centre[:, 0]))
    a, b = FRAME['depth_noise']
    assert stds[0] / stds[1] == pytest.approx((a + b * 4.5**2) / (a + b * 1.5**2), rel=0.15)


def straight_camera(max_range: float = 5.0) -> DepthCamera:
    """A camera at (0.5, 2, 1.3) looking along +x, level, with a 60 x 47 degree view."""
    return DepthCamera(np.array([0.5, 2.0, 1.3]), np.array([1.0, 0.0, 0.0]),
                       np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                       np.tan(np.radians([60.0, 47.0]) / 2), max_range)


def test_returns_are_lost_at_depth_edges_only():
    """With ``edge_dropout`` 1 the pixels lost against ``edge_dropout`` 0 (same grid, no noise)
    lie on the outline of the cube's image (its foot on the floor is no depth step)."""
    scanner, _ = box_room((6.0, 4.0, 3.0), [((3.0, 1.5, 0.0), (3.5, 2.5, 1.0), (200, 0, 0))])
    on_object = np.array([False, True])[scanner.scene.part]
    quiet = dict(FRAME, depth_noise=[0.0, 0.0])
    camera = straight_camera()
    columns, rows = 200, 150
    full, edged = (depth_frame_returns(scanner, camera, columns, rows,
                                       np.random.default_rng(1), dict(quiet, edge_dropout=share),
                                       BATCH, on_object, np.zeros(len(on_object)))[0]
                   for share in (0.0, 1.0))
    kept = {tuple(p) for p in edged}
    lost = np.array([p for p in full if tuple(p) not in kept])
    assert len(kept) + len(lost) == len(full) and 100 < len(lost) < 0.05 * len(full)
    # image coordinates (right, up on the plane at distance 1) of the lost pixels and of the
    # cube's outline: the convex hull of its corners' images
    rel = lost - camera.position
    image = np.stack([rel @ camera.right, rel @ camera.up], axis=1) / (rel @ camera.look)[:, None]
    outline = np.array([[-0.2, -0.52], [-0.2, -0.12], [-0.5 / 3, -0.1], [0.5 / 3, -0.1],
                        [0.2, -0.12], [0.2, -0.52]])
    pixel = 2 * camera.half_tan[0] / columns
    assert distance_to_polygon(image, outline).max() < 2.5 * pixel


def test_objects_with_a_few_returns_lose_them():
    """A 3 cm cube in view gets fewer than ``min_object_points`` returns: they are dropped (no
    annotation of a handful of points) and recorded; with the rule off it keeps them."""
    scanner, _ = box_room((6.0, 4.0, 3.0), [((3.0, 1.5, 0.0), (3.5, 2.5, 1.0), (200, 0, 0)),
                                            ((2.0, 2.6, 0.9), (2.03, 2.63, 0.93), (0, 200, 0))])
    parts = np.array([False, True, True])
    scan, record = cast_depth_frame(scanner, straight_camera(), 20000,
                                    np.random.default_rng(2), FRAME, BATCH, parts)
    assert 2 not in scan.part and (scan.part == 1).sum() >= FRAME['min_object_points']
    assert record['sparse_objects'] == 1 and 0 < record['sparse_object_points']
    assert len(scan.xyz) == 20000 - record['sparse_object_points']
    kept, record = cast_depth_frame(scanner, straight_camera(), 20000,
                                    np.random.default_rng(2),
                                    dict(FRAME, min_object_points=0), BATCH, parts)
    assert 0 < (kept.part == 2).sum() < FRAME['min_object_points']
    assert record['sparse_objects'] == 0


def test_a_frame_beyond_its_range_returns_what_it_can_with_a_warning():
    """Every surface in a narrow view lies beyond the range: no points, a warning, and the
    grid refined up to its limit of 16 pixels per requested point."""
    scanner, _ = box_room((12.0, 4.0, 3.0))
    camera = DepthCamera(np.array([0.5, 2.0, 1.3]), np.array([1.0, 0.0, 0.0]),
                         np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]),
                         np.tan(np.radians([30.0, 10.0]) / 2), 4.5)
    with pytest.warns(UserWarning, match='depth frame: only 0 of 1000 points'):
        scan, record = cast_depth_frame(scanner, camera, 1000, np.random.default_rng(0), FRAME,
                                        BATCH, np.array([False]))
    assert len(scan.xyz) == 0 and scan.rays_cast >= 16 * 1000


@pytest.fixture(scope='module')
def frame_rooms(tmp_path_factory):
    """Two small generated rooms scanned by the depth frame only."""
    work = tmp_path_factory.mktemp('frame')
    config = work / 'frame.json'
    config.write_text(json.dumps({'scanner': {'sensors': {'depth_frame': 1.0}}}))
    options = ('--config', config, '--asset-cache', work / 'assets')
    generate_rooms(work / 'out', 7, 2, 20000, 3, *options)
    return work, options


def test_generated_rooms_record_the_camera_and_keep_no_sparse_object(frame_rooms):
    work, _ = frame_rooms
    for room, sensor in sensor_records(work / 'out', 'depth_frame', 2):
        assert {'position', 'look', 'pitch_deg', 'fov_deg', 'max_range', 'pixels', 'min_range',
                'depth_noise', 'edge_dropout', 'min_object_points'} <= set(sensor)
        for value, (low, high) in zip(sensor['fov_deg'], (FRAME['horizontal_fov_deg'],
                                                           FRAME['vertical_fov_deg'])):
            assert low <= value <= high
        points, _ = read_point_file(room / f'{room.name}.txt')
        assert len(points) == 20000 - sensor['sparse_object_points']
        # the text files' millimetres: 1 mm at 0.5 m is 0.002 in tangent units
        assert in_frustum(points[:, :3], sensor, 0.003).all()
        distance = np.linalg.norm(points[:, :3] - sensor['position'], axis=1)
        assert distance.max() <= sensor['max_range'] + 0.002
        for annotation in (room / 'Annotations').glob('*.txt'):
            if annotation.stem.rsplit('_', 1)[0] not in ROOM_STRUCTURE:
                seen, _ = read_point_file(annotation)
                assert len(seen) >= FRAME['min_object_points'], annotation.name


def test_same_seed_gives_the_same_frame_files(frame_rooms):
    work, options = frame_rooms
    generate_rooms(work / 'again', 7, 2, 20000, 3, *options)
    same_tree(work / 'out', work / 'again')


def test_the_depth_frame_profile_draws_it_and_mixed_rooms_does_not():
    profiles = Path(__file__).resolve().parents[2] / 'generator' / 'profiles'
    sensors = load_config(profiles / 'mixed_rooms_depth_frame.json')['scanner']['sensors']
    assert sensors['depth_frame'] == pytest.approx(0.25)
    assert load_config(profiles / 'mixed_rooms.json')['scanner']['sensors']['depth_frame'] == 0.0
    assert DEFAULTS['scanner']['sensors']['depth_frame'] == 0.0


@pytest.mark.parametrize('settings, message', [
    ({'height': [1.6, 1.0]}, 'scanner.depth_frame.height" has min > max'),
    ({'pitch_deg': [0, 95]}, 'scanner.depth_frame.pitch_deg" must stay within'),
    ({'horizontal_fov_deg': [50, 200]}, 'scanner.depth_frame.horizontal_fov_deg" must lie in'),
    ({'max_range': [0.4, 5.0]}, 'scanner.depth_frame.min_range" must be below'),
    ({'depth_noise': [0.001]}, 'scanner.depth_frame.depth_noise" must be'),
    ({'edge_dropout': 1.5}, 'scanner.depth_frame.edge_dropout" is outside'),
    ({'min_object_points': 2.5}, 'scanner.depth_frame.min_object_points" must be'),
    ({'object_clearance': -1}, 'scanner.depth_frame.object_clearance" must not be negative'),
    ({'fov': 60}, 'unknown key "scanner.depth_frame.fov"'),
])
def test_depth_frame_configuration_errors_name_the_file_and_key(tmp_path, settings, message):
    assert_sensor_config_error(tmp_path, 'depth_frame', settings, message)
