"""The RGB-D reconstruction sensor model (generator/reconstruction.py) on real Embree: hand-made
box rooms for the fused surface's one point per cube, its even density (the tablet's falls with
the distance), the ceiling, the budget and determinism; small generated rooms for the meta.json
record, the annotation check and the profile; the configuration's errors."""
import json
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest

from generator.config import DEFAULTS, load_config
from generator.reconstruction import scan_reconstruction
from generator.scanner import Scanner
from generator.sensor_common import RoomGeometry
from generator.sensors import scan_room
from synthdet.point_text import read_point_file
from synthdet.voxels import cube_keys
from tests.generator_runs import assert_sensor_config_error, generate_rooms, sensor_records
from tests.test_generator.test_generator_pipeline import same_tree
from tests.test_generator.test_generator_sensors import room_scene
from tools.check_annotations import main as check_annotations

REPO = Path(__file__).resolve().parents[2]
RECONSTRUCTION = DEFAULTS['scanner']['reconstruction']
BATCH = 65536
# a 10 x 8 x 3 m box room: the walk goes round 1 m from the walls
SIZE = (10.0, 8.0, 3.0)
# fused cubes of 5 cm: the small room's surfaces get a few returns per cube
COARSE = dict(RECONSTRUCTION, surface_spacing=0.05)
# fused cubes of 10 cm, 16 returns per point and a walk facing the room's inside for 70 % of
# the way: every cube of the floor gets several returns, far from the walk too
SATURATED = dict(RECONSTRUCTION, surface_spacing=0.1, oversample=16.0, wall_look=0.3)


def box_room(size=SIZE, cubes=()) -> tuple[Scanner, RoomGeometry]:
    """The scanner and geometry of a box room (one structure part) with movable cubes."""
    width, depth, height = size
    polygon = np.array([[0, 0], [0, depth], [width, depth], [width, 0]], float)
    obstacles = np.array([[lo[:2], hi[:2]] for lo, hi, _ in cubes], float).reshape(-1, 2, 2)
    room = RoomGeometry(polygon, height, [], obstacles, np.array([False] + [True] * len(cubes)))
    return Scanner(room_scene(size, cubes)), room


def reconstruct(n_points: int, cfg: dict, seed: int = 0, size=SIZE):
    scanner, room = box_room(size)
    return scan_reconstruction(scanner, room, n_points, np.random.default_rng(seed), cfg, BATCH)


def floor_densities(xyz: np.ndarray, size=SIZE) -> tuple[float, float]:
    """Floor points per m^2 in the band along the walls up to 0.5 m from them (0.5-1 m from
    the walk) and 2.5 m or more from them (the floor's centre, 1.5 m and more from the
    walk)."""
    floor = xyz[xyz[:, 2] < 0.05]
    width, depth, _ = size
    wall = np.minimum.reduce([floor[:, 0], width - floor[:, 0], floor[:, 1], depth - floor[:, 1]])

    def inset_area(margin: float) -> float:
        return (width - 2 * margin) * (depth - 2 * margin)

    near = (wall < 0.5).sum() / (inset_area(0.0) - inset_area(0.5))
    far = (wall >= 2.5).sum() / inset_area(2.5)
    return near, far


def test_the_fused_surface_keeps_at_most_one_point_per_cube():
    scan, record = reconstruct(30000, dict(COARSE, range_noise=0.0))
    keys = cube_keys(scan.xyz - record['grid_offset'], COARSE['surface_spacing'])
    assert len(np.unique(keys)) == len(keys) == 30000
    assert record['fused_points'] >= 30000


def test_the_density_is_even_near_and_far_from_the_walk_and_the_tablets_is_not():
    for seed in range(3):
        scan, _ = reconstruct(8000, SATURATED, seed)
        near, far = floor_densities(scan.xyz)
        assert abs(near / far - 1) < 0.25, (seed, near, far)
    # the same walk and casts without the fused surface: the tablet's returns
    scanner, room = box_room()
    tablet, _ = scan_room(scanner, room, 'tablet', 8000, 0.5, np.random.default_rng(0),
                          dict(DEFAULTS['scanner'], batch_rays=BATCH, tablet=SATURATED))
    near, far = floor_densities(tablet.xyz)
    assert near / far > 1.5, (near, far)


def test_the_ceiling_is_dropped_unless_kept():
    height = SIZE[2]
    for keep, seen in ((0.0, False), (1.0, True)):
        scan, _ = reconstruct(20000, dict(COARSE, range_noise=0.0, ceiling_keep=keep,
                                          pitch_deg=[-10.0, 40.0]))
        assert ((scan.xyz[:, 2] > height - 1e-3).sum() > 100) == seen, keep
        assert len(scan.xyz) == 20000


def test_the_budget_is_exact_or_short_with_a_warning():
    scan, _ = reconstruct(12345, COARSE)
    assert len(scan.xyz) == 12345 and len(scan.part) == 12345
    # 50 cm cubes: a few hundred on the whole room, every one of them kept (the ceiling's too)
    with pytest.warns(UserWarning, match=r'reconstruction: only \d+ of 5000 points'):
        scan, record = reconstruct(5000, dict(COARSE, surface_spacing=0.5, ceiling_keep=1.0))
    assert 0 < len(scan.xyz) == record['fused_points'] < 5000


def test_the_same_seed_gives_the_same_points():
    first, record = reconstruct(20000, COARSE, seed=4)
    again, same_record = reconstruct(20000, COARSE, seed=4)
    assert first.xyz.tobytes() == again.xyz.tobytes() and record == same_record
    assert np.array_equal(first.triangle, again.triangle)
    other, _ = reconstruct(20000, COARSE, seed=5)
    assert first.xyz.tobytes() != other.xyz.tobytes()


@pytest.fixture(scope='module')
def reconstruction_rooms(tmp_path_factory):
    """Two small generated rooms of the mixed room kinds scanned by the reconstruction only."""
    work = tmp_path_factory.mktemp('reconstruction')
    config = work / 'reconstruction.json'
    profile = json.loads((REPO / 'generator/profiles/mixed_rooms_reconstruction.json').read_text())
    profile['scanner']['sensors'] = {'reconstruction': 1.0}
    config.write_text(json.dumps(profile))
    options = ('--config', config, '--asset-cache', work / 'assets')
    generate_rooms(work / 'out', 7, 2, 20000, 3, *options)
    return work, options


def test_generated_rooms_record_the_reconstruction_and_pass_the_annotation_check(
        reconstruction_rooms, tmp_path):
    work, _ = reconstruction_rooms
    for room, sensor in sensor_records(work / 'out', 'reconstruction', 2):
        assert {'trajectory', 'fused_points', 'grid_offset', 'surface_spacing', 'ceiling_keep',
                'oversample', 'range_noise', 'max_range'} <= set(sensor)
        points, _ = read_point_file(room / f'{room.name}.txt')
        assert len(points) == 20000
        assert not list((room / 'Annotations').glob('ceiling_*.txt'))
    report = tmp_path / 'check.json'
    assert check_annotations([str(work / 'out'), '--areas', '7', '--out', str(report)]) == 0
    rows = json.loads(report.read_text())['rows']
    assert {row['sensor'] for row in rows} == {'reconstruction'}
    assert all(row['objects_with_points_outside'] == 0 for row in rows)


def test_same_seed_gives_the_same_room_files(reconstruction_rooms):
    work, options = reconstruction_rooms
    generate_rooms(work / 'again', 7, 2, 20000, 3, *options)
    same_tree(work / 'out', work / 'again')


def test_the_profile_draws_a_quarter_of_reconstructions_and_the_defaults_none():
    profiles = REPO / 'generator' / 'profiles'
    config = load_config(profiles / 'mixed_rooms_reconstruction.json')
    assert config['scanner']['sensors'] == pytest.approx(
        {'paper': 0.25, 'tls': 0.25, 'tablet': 0.25, 'depth_frame': 0.0, 'reconstruction': 0.25})
    assert config['room_kinds'] == load_config(profiles / 'mixed_rooms.json')['room_kinds']
    assert DEFAULTS['scanner']['sensors']['reconstruction'] == 0.0
    assert load_config(profiles / 'mixed_rooms.json')['scanner']['sensors'][
        'reconstruction'] == 0.0


@pytest.mark.parametrize('settings, message', [
    ({'height': [1.6, 1.0]}, 'scanner.reconstruction.height" has min > max'),
    ({'pitch_deg': [0, 95]}, 'scanner.reconstruction.pitch_deg" must be two numbers'),
    ({'fov_deg': [60]}, 'scanner.reconstruction.fov_deg" must be two numbers'),
    ({'poses': 1}, 'scanner.reconstruction.poses" must be an integer'),
    ({'max_range': 0.2}, 'scanner.reconstruction.min_range" must be below'),
    ({'ceiling_keep': 1.5}, 'scanner.reconstruction.ceiling_keep" is outside'),
    ({'dark_dropout': -0.1}, 'scanner.reconstruction.dark_dropout" is outside'),
    ({'range_noise': -1}, 'scanner.reconstruction.range_noise" must not be negative'),
    ({'oversample': 0.5}, 'scanner.reconstruction.oversample" must be at least 1'),
    ({'surface_spacing': 0}, 'scanner.reconstruction.surface_spacing" must be in'),
    ({'surface_spacing': 'fine'}, 'scanner.reconstruction.surface_spacing" must be a number'),
    ({'spacing': 0.01}, 'unknown key "scanner.reconstruction.spacing"'),
])
def test_reconstruction_configuration_errors_name_the_file_and_key(tmp_path, settings, message):
    assert_sensor_config_error(tmp_path, 'reconstruction', settings, message)
