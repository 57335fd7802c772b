"""Scan preparation (synthdet/prepare.py) and the corners read through it."""
import math
import tracemalloc

import numpy as np
import pytest

from configurator.corners import corners_for_scan, detect_corners
from synthdet.geometry import box_corners_xy, dominant_direction, rotation_between, rotation_z
from synthdet.prepare import detect_up_axis, prepare_scan, sparse_points
from synthdet.scan_io import LoadedScan, load_scan, write_scan
from tests.room_scans import NoiseModel, make_room


@pytest.fixture(scope='module')
def room():
    return make_room('L', n_points=150_000, seed=8, noise=NoiseModel())


def loaded(points: np.ndarray) -> LoadedScan:
    return LoadedScan(points=points.copy(), origin=np.zeros(3), source='test')


def first_from_min(polygon: np.ndarray) -> np.ndarray:
    start = int(np.argmin(np.linalg.norm(polygon - polygon.min(axis=0), axis=1)))
    return np.roll(polygon, -start, axis=0)


def tilted(points: np.ndarray, centre: np.ndarray, yaw_deg: float, tilt_deg: float):
    """Points turned about z by ``yaw_deg`` then tilted about x by ``tilt_deg``, about
    ``centre``; returns the points and the 3x3 rotation."""
    t = math.radians(tilt_deg)
    tilt = np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])
    rotation = tilt @ rotation_z(math.radians(yaw_deg))
    moved = points.copy()
    moved[:, :3] = (points[:, :3] - centre) @ rotation.T + centre
    return moved, rotation


def test_prepared_frame_is_level_axis_aligned_and_maps_back_exactly(room):
    prepared = prepare_scan(loaded(room.points))
    assert prepared.up_axis == '+z' and len(prepared.report) >= 4
    floor = prepared.points[np.abs(prepared.points[:, 2]) < 0.05]
    assert len(floor) > 0.1 * len(prepared.points)  # the floor lies at z = 0
    outline = detect_corners(prepared.points)
    edges = np.roll(outline.corners, -1, axis=0) - outline.corners
    along_axes = np.minimum(np.abs(edges[:, 0]), np.abs(edges[:, 1])) / \
        np.linalg.norm(edges, axis=1)
    assert along_axes.max() < 0.01  # walls along the axes
    back = prepared.points_to_scan(prepared.points[:, :3])
    kept = ~sparse_points(room.points[:, :3])
    np.testing.assert_allclose(back, room.points[kept, :3], atol=1e-9)
    homogeneous = np.column_stack([prepared.points[:, :3], np.ones(len(back))])
    np.testing.assert_allclose((homogeneous @ prepared.to_scan.T)[:, :3], back, atol=1e-9)


def test_rotated_and_tilted_copy_gives_the_same_corners(tmp_path, room):
    centre = np.r_[room.polygon.mean(axis=0), room.floor_z]
    write_scan(tmp_path / 'room.ply', room.points)
    moved, rotation = tilted(room.points, centre, 30.0, 3.0)
    write_scan(tmp_path / 'moved.ply', moved)
    plain = corners_for_scan(tmp_path / 'room.ply')
    result = corners_for_scan(tmp_path / 'moved.ply')
    found = np.array(result['corners'])
    floor = np.column_stack([room.polygon, np.full(len(room.polygon), room.floor_z)])
    expected = first_from_min(((floor - centre) @ rotation.T + centre)[:, :2])
    assert found.shape == expected.shape
    assert np.abs(found - expected).max() <= 0.03
    assert np.abs(np.array(plain['corners']) - first_from_min(room.polygon)).max() <= 0.03
    assert abs(result['floor_z'] - room.floor_z) < 0.03  # at the room's centre


def test_boxes_go_back_to_the_scan_frame_with_their_yaw(room):
    moved, _ = tilted(room.points, np.zeros(3), 30.0, 0.0)
    prepared = prepare_scan(
        LoadedScan(points=moved, origin=np.array([500000.0, 5400000.0, 300.0]), source='t'))
    centers = np.array([[1.0, 2.0, 0.4], [3.0, -1.0, 1.0]])
    sizes = np.array([[2.0, 1.0, 0.8], [0.5, 0.5, 2.0]])
    yaws = np.array([0.0, 0.4])
    scan_centers, scan_sizes, scan_yaws = prepared.boxes_to_scan(centers, sizes, yaws)
    np.testing.assert_array_equal(scan_sizes, sizes)
    for k in range(2):  # the footprint's corners, moved one by one, are the moved box's
        footprint = box_corners_xy(centers[k], sizes[k], yaws[k])
        expected = prepared.points_to_scan(np.column_stack([footprint, np.full(4, centers[k, 2])]))
        np.testing.assert_allclose(
            box_corners_xy(scan_centers[k], scan_sizes[k], scan_yaws[k]),
            expected[:, :2],
            atol=1e-4)  # up to the levelled tilt of a few thousandths of a degree
    assert scan_centers[0][0] > 499000 and scan_centers[0][1] > 5399000


def test_a_stray_point_5_km_away_changes_nothing(room):
    scans = loaded(room.points), loaded(np.vstack([room.points, [[5000.0, 5000.0, 0, 0, 0, 0]]]))
    results, peaks = [], []
    for scan in scans:
        tracemalloc.start()
        results.append(prepare_scan(scan))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    (plain, with_stray), (plain_peak, stray_peak) = results, peaks
    np.testing.assert_array_equal(with_stray.points, plain.points)
    np.testing.assert_array_equal(with_stray.to_scan, plain.to_scan)
    assert stray_peak < 1.02 * plain_peak  # no grid over the 5 km bounding box
    assert plain.report[0].startswith('outliers: removed') and \
        with_stray.report[0] != plain.report[0]  # one more point removed


def test_corners_of_a_scan_with_a_stray_point_5_km_away_are_unchanged(tmp_path, room):
    write_scan(tmp_path / 'room.pcd', room.points)
    write_scan(tmp_path / 'stray.pcd', np.vstack([room.points, [[3000.0, -4000.0, 0, 0, 0, 0]]]))
    plain, stray = (corners_for_scan(tmp_path / f'{name}.pcd') for name in ('room', 'stray'))
    assert stray['corners'] == plain['corners'] and stray['floor_z'] == plain['floor_z']


def test_a_sparse_scan_is_prepared_without_losing_its_points():
    points = np.column_stack(
        [np.random.default_rng(5).uniform(0, 10, (1000, 3)),
         np.zeros((1000, 3))])
    prepared = prepare_scan(loaded(points))
    assert len(prepared.points) == 1000 and 'too sparse for the density test' in \
        prepared.report[0]
    back = prepared.points_to_scan(prepared.points[:, :3])
    np.testing.assert_allclose(np.sort(back, axis=0), np.sort(points[:, :3], axis=0), atol=1e-9)


def test_outliers_in_sparse_isolated_cells_are_removed(room):
    rng = np.random.default_rng(4)
    strays = np.column_stack([rng.uniform(-300, 300, (50, 3)), np.zeros((50, 3))])
    points = np.vstack([room.points, strays])
    sparse = sparse_points(points[:, :3])
    assert sparse[-50:].all()
    assert sparse[:-50].mean() < 0.002


def test_y_up_scan_is_detected_and_its_corners_come_out_seen_from_above(tmp_path, room):
    y_up = room.points.copy()
    y_up[:, :3] = np.column_stack([room.points[:, 0], room.points[:, 2], -room.points[:, 1]])
    write_scan(tmp_path / 'tablet.ply', y_up)
    prepared = prepare_scan(load_scan(tmp_path / 'tablet.ply', voxel=0.02))
    assert prepared.up_axis == '+y' and 'up axis: +y' in ' '.join(prepared.report)
    result = corners_for_scan(tmp_path / 'tablet.ply')
    assert np.abs(np.array(result['corners']) - first_from_min(room.polygon)).max() <= 0.03
    assert detect_up_axis(room.points[:, :3]) == '+z'
    x_down = np.column_stack([-room.points[:, 2], room.points[:, 1], room.points[:, 0]])
    assert detect_up_axis(x_down) == '-x'


def test_density_resampling_and_warning(room):
    prepared = prepare_scan(loaded(room.points))
    density = prepared.density
    lower = prepare_scan(loaded(room.points), target_density=density / 3)
    assert abs(len(lower.points) - len(prepared.points) / 3) < 0.01 * len(prepared.points)
    assert lower.report[-1].startswith('warning: density:') and 'resampled' in lower.report[-1]
    close = prepare_scan(loaded(room.points), target_density=density / 1.5)
    assert close.report[-1].startswith('density:') and 'resampled' in close.report[-1]
    sparse = prepare_scan(loaded(room.points), target_density=density * 5)
    assert len(sparse.points) == len(prepared.points)
    assert 'sparser than training' in sparse.report[-1]


def test_geometry_helpers():
    for a, b in (([0, 0, 1], [0, 0, 1]), ([0, 1, 0], [0, 0, 1]), ([0, 0,
                                                                   -1], [0, 0,
                                                                         1]), ([1, 2,
                                                                                3], [-3, 0.5, 2])):
        rotation = rotation_between(a, b)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)
        np.testing.assert_allclose(
            rotation @ a / np.linalg.norm(a), np.asarray(b) / np.linalg.norm(b), atol=1e-12)
    walls = make_room('rect', n_points=60_000, seed=2, rotate=False).points
    walls = walls[(walls[:, 2] > walls[:, 2].min() + 0.5)][:, :2] @ \
        rotation_z(math.radians(30))[:2, :2].T
    assert math.degrees(dominant_direction(walls)) == pytest.approx(30.0, abs=0.1)
