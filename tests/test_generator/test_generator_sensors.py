"""Sensor models (generator/sensors.py, tls.py, tablet.py) on real Open3D/Embree: hand-made box
rooms for the TLS grid, range noise and mixed pixels, the tablet's range window and dropouts, the
paper profile's uniform directions; and small real rooms from ``python -m generator`` for the
per-room mix and determinism."""
import json
import resource
import shutil
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest

from configurator.corners import detect_corners
from generator.__main__ import main
from generator.assets.palette import METAL, SEE_THROUGH
from generator.config import DEFAULTS, ConfigError, load_config
from generator.scanner import Scanner, TriangleScene
from generator.sensor_common import RoomGeometry, room_geometry
from generator.sensors import choose_sensor, scan_room
from generator.tablet import cast_tablet
from generator.tls import cast_tls, scan_tls
from generator.tls_grid import tls_grid
from synthdet.contracts import SENSOR_MODELS
from synthdet.point_text import read_point_file
from synthdet.voxels import cube_keys
from tests.test_configurator.test_corners import corner_errors
from tests.test_generator.test_generator_pipeline import box, same_tree
from tests.test_repository.test_faults import assert_clean_error
from tests.test_synthdet.test_output_paths import run, temporaries
from synthdet.annotation_check import object_fit
from synthdet.geometry import rotation_z
from tools.check_annotations import main as check_annotations

REPO = Path(__file__).resolve().parents[2]
# the raw scanner: no noise, no mixed pixels, no export spacing filter (each tested on its own)
TLS = dict(DEFAULTS['scanner']['tls'], mixed_pixels=0.0, range_noise=[0.0, 0.0], point_spacing=None)
TABLET = DEFAULTS['scanner']['tablet']
# the sensor models of the default mix (the depth frame is in profiles only)
DEFAULT_MIX = {model for model, p in DEFAULTS['scanner']['sensors'].items() if p > 0}
BATCH = 65536


def room_scene(size, cubes=()) -> TriangleScene:
    """A box room ``size`` (part 0, structure) with cubes (lo, hi, rgb), each a movable part."""
    vertices, triangles = box((0, 0, 0), size, True)
    vertices, triangles = [vertices], [triangles]
    colors, part = [[200, 200, 200]] * 12, [0] * 12
    for index, (lo, hi, rgb) in enumerate(cubes, start=1):
        v, f = box(lo, hi, False)
        triangles.append(f + 8 * index)
        vertices.append(v)
        colors += [rgb] * 12
        part += [index] * 12
    return TriangleScene(
        np.concatenate(vertices),
        np.concatenate(triangles).astype(np.int32), np.array(colors, np.uint8),
        np.array(part, np.int32), np.array([False] + [True] * len(cubes)))


def objects(scanner: Scanner) -> np.ndarray:
    """Per triangle: does it belong to an object (here the movable cubes)."""
    return scanner.scene.movable[scanner.scene.part]


def true_ranges(scanner: Scanner, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Noise-free ranges along the given rays."""
    t_hit, _ = scanner.cast(scanner.full_scene, np.ascontiguousarray(origins),
                            np.ascontiguousarray(directions))
    return t_hit.astype(np.float64)


def grid_position(points: np.ndarray, station: np.ndarray, step: float) -> np.ndarray:
    """Azimuth and elevation of each point seen from ``station``, in units of ``step`` degrees."""
    rel = points - station
    azimuth = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360.0
    elevation = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
    return np.stack([azimuth, elevation], axis=1) / step


def unit(degrees: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) float32 of (azimuth, elevation) pairs in degrees."""
    azimuth, elevation = np.radians(degrees).T
    return np.stack([
        np.cos(elevation) * np.cos(azimuth),
        np.cos(elevation) * np.sin(azimuth),
        np.sin(elevation)
    ],
                    axis=1).astype(np.float32)


def test_tls_directions_lie_on_the_angular_grid_of_its_step():
    scanner = Scanner(room_scene((12, 6, 3), [((5, 2, 0), (6, 3, 1), (200, 0, 0))]))
    station = np.array([[2.0, 3.0, 1.5]])
    cfg = dict(TLS, range_noise=[0.005, 0.002], mixed_pixels=0.5)
    scan, step = scan_tls(scanner, station, 50000, np.random.default_rng(0), cfg, BATCH,
                          objects(scanner))
    assert len(scan.xyz) == 50000 and 0.1 < step < 5
    assert np.isclose(360.0 / step, round(360.0 / step))  # a whole number of azimuth steps
    position = grid_position(scan.xyz, station[0], step)
    assert np.abs(position - np.round(position)).max() < 1e-6
    assert position[:, 1].min() >= cfg['min_elevation_deg'] / step - 1e-6
    assert (scan.part == 1).sum() > 100 and len(np.unique(scan.triangle)) > 12
    assert np.array_equal(scan.origin, np.repeat(station, 50000, 0).astype(np.float32))
    # a coarser fixed step: every beam of the grid that hits is there, once
    xyz, _, _, _ = cast_tls(scanner, station, 2.0, np.random.default_rng(0), TLS, BATCH,
                         objects(scanner))
    azimuth, elevation = tls_grid(2.0, TLS['min_elevation_deg'])
    assert len(xyz) == len(azimuth) * len(elevation)  # a closed room returns every beam
    cells = np.round(grid_position(xyz, station[0], 2.0)).astype(int)
    assert len(np.unique(cells, axis=0)) == len(xyz)


def test_tls_export_keeps_one_return_per_cube_and_gives_far_objects_their_share():
    """The default export (8 beams per point of the budget, one return per 1 cm cube, then the
    budget) against every return of a scan at the budget's own step: the floor and walls next
    to the tripod no longer take the points a far object needs."""
    scanner = Scanner(room_scene((8, 5, 3), [((7, 2, 0), (7.4, 2.4, 0.4), (200, 0, 0))]))
    station = np.array([[1.0, 2.0, 1.5]])
    on_far_cube = {}
    for spacing, oversample in ((None, 1.0), (0.01, 8.0)):
        cfg = dict(TLS, point_spacing=spacing, oversample=oversample)
        scan, step = scan_tls(scanner, station, 200000, np.random.default_rng(0), cfg, BATCH,
                              objects(scanner))
        assert len(scan.xyz) == 200000
        on_far_cube[spacing] = int((scan.part == 1).sum())
        position = grid_position(scan.xyz, station[0], step)  # still the scanner's beams
        assert np.abs(position - np.round(position)).max() < 1e-4
    keys = cube_keys(scan.xyz.astype(np.float64), 0.01)
    assert len(np.unique(keys)) == len(keys)  # one return per 1 cm cube
    assert on_far_cube[0.01] > 1.5 * on_far_cube[None] > 30


def test_tls_beams_escaping_an_open_room_are_lost_without_error():
    """Windows and doors are openings: beams that hit nothing are no points (and no index)."""
    scene = room_scene((8, 6, 3), [((3, 2, 0), (4, 3, 1), (200, 0, 0))])
    corners = scene.vertices[scene.triangles]
    closed = ~np.all(np.isclose(corners[:, :, 2], 3.0), axis=1)  # no ceiling
    scene = TriangleScene(scene.vertices, scene.triangles[closed], scene.colors[closed],
                          scene.part[closed], scene.movable)
    scanner = Scanner(scene)
    station = np.array([[2.0, 3.0, 1.5]])
    cfg = dict(TLS, mixed_pixels=1.0)
    xyz, triangle, _, _ = cast_tls(scanner, station, 2.0, np.random.default_rng(0), cfg, BATCH,
                                objects(scanner))
    azimuth, elevation = tls_grid(2.0, TLS['min_elevation_deg'])
    assert 0 < len(xyz) < len(azimuth) * len(elevation)
    assert np.all(xyz[:, 2] < 3.0 + 1e-4) and triangle.max() < len(scene.triangles)


def test_tls_range_noise_grows_with_distance():
    scanner = Scanner(room_scene((30, 4, 3)))
    station = np.array([[1.0, 2.0, 1.5]])
    a, b = 0.002, 0.002
    xyz, _, _, _ = cast_tls(scanner, station, 0.25, np.random.default_rng(1),
                         dict(TLS, range_noise=[a, b]), BATCH, objects(scanner))
    measured = np.linalg.norm(xyz - station, axis=1)
    truth = true_ranges(scanner, np.repeat(station, len(xyz), axis=0),
                        (xyz - station) / measured[:, None])
    error = measured - truth
    stds = []
    for low, high in ((1.0, 3.0), (8.0, 12.0), (20.0, 28.0)):
        rows = (truth > low) & (truth < high)
        assert rows.sum() > 300
        stds.append(error[rows].std())
        # the model: std a + b * d, checked on the normalised error
        assert abs(np.std(error[rows] / (a + b * truth[rows])) - 1.0) < 0.1
    assert stds[0] < stds[1] < stds[2] and stds[2] > 4 * stds[0]


def test_tls_mixed_pixels_appear_only_at_depth_edges():
    cube = ((4, 2.5, 0), (5, 3.5, 1), (0, 0, 200))
    station = np.array([[1.5, 3.0, 1.5]])
    cfg = dict(TLS, mixed_pixels=1.0)
    step = 0.5
    for cubes in ([], [cube]):
        scanner = Scanner(room_scene((10, 6, 3), cubes))
        xyz, _, _, stray = cast_tls(scanner, station, step, np.random.default_rng(2), cfg, BATCH,
                                    objects(scanner))
        measured = np.linalg.norm(xyz - station, axis=1)
        directions = (xyz - station) / measured[:, None]
        off = np.abs(measured -
                     true_ranges(scanner, np.repeat(station, len(xyz), 0), directions)) > 1e-3
        if not cubes:  # walls, floor (even at grazing angles) and corners: no depth edge
            assert not off.any() and not stray.any()
            continue
        assert off.sum() > 20
        assert not (off & ~stray).any()  # every return off its surface is marked stray
        # every mixed return: a grid neighbour of its beam hits the other surface (cube vs room)
        # and the return lies between the two surfaces along its beam
        for cell, r in zip(np.round(grid_position(xyz[off], station[0], step)), measured[off]):
            beams = unit(
                np.array([cell, cell + [1, 0], cell - [1, 0], cell + [0, 1], cell - [0, 1]]) *
                step)
            t_hit, prim = scanner.cast(scanner.full_scene, np.repeat(station, 5, 0), beams)
            part = scanner.scene.part[prim]
            other = part[1:] != part[0]
            assert other.any()
            assert min(t_hit[0], t_hit[1:][other].min()) - 1e-4 <= r
            assert r <= max(t_hit[0], t_hit[1:][other].max()) + 1e-4


def walk(start, end, n: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Tablet poses along a straight line at 1.4 m, looking along it and slightly down."""
    positions = np.linspace(start, end, n)
    look = np.tile(np.append(np.subtract(end, start)[:2], -0.3), (n, 1))
    return positions, look / np.linalg.norm(look, axis=1, keepdims=True)


def test_tablet_returns_lie_within_its_range_window():
    scanner = Scanner(room_scene((20, 4, 3), [((8, 1.5, 0), (9, 2.5, 1), (200, 0, 0))]))
    positions, look = walk((1.0, 2.0, 1.4), (3.0, 2.0, 1.4))
    scan, pose = cast_tablet(scanner, positions, look, 30000, np.random.default_rng(3), TABLET,
                             BATCH)
    distance = np.linalg.norm(scan.xyz - positions[pose], axis=1)
    assert len(scan.xyz) == 30000
    assert np.array_equal(scan.origin, positions[pose].astype(np.float32))
    assert distance.min() >= TABLET['min_range'] and distance.max() <= TABLET['max_range']
    assert distance.max() > 0.95 * TABLET['max_range']  # the window, not the room, bounds it
    # without the window the same walk sees the far end of the 20 m room
    wide, pose = cast_tablet(scanner, positions, look, 30000, np.random.default_rng(3),
                             dict(TABLET, max_range=40.0, far_keep=1.0), BATCH)
    assert np.linalg.norm(wide.xyz - positions[pose], axis=1).max() > 15.0
    # density falls with distance: fewer returns at 4-5 m than with every return kept
    kept = dict(TABLET, far_keep=1.0)
    flat, pose = cast_tablet(scanner, positions, look, 30000, np.random.default_rng(3), kept,
                             BATCH)
    far_share = np.mean(distance > 4.0)
    assert far_share < 0.9 * np.mean(np.linalg.norm(flat.xyz - positions[pose], axis=1) > 4.0)


def test_tablet_drops_returns_on_dark_and_shiny_triangles():
    dark, shiny, plain = (20, 20, 24), METAL[1], (200, 60, 40)
    scanner = Scanner(
        room_scene((8, 6, 3), [((5, 0.5, 0), (6, 1.5, 1.2), dark),
                               ((5, 2.5, 0), (6, 3.5, 1.2), shiny),
                               ((5, 4.5, 0), (6, 5.5, 1.2), plain)]))
    positions, look = walk((1.0, 1.0, 1.4), (1.0, 5.0, 1.4))
    look = np.tile([0.95, 0.0, -0.3], (len(look), 1))  # towards the three boxes

    def shares(dark_dropout: float, shiny_dropout: float) -> np.ndarray:
        cfg = dict(TABLET, dark_dropout=dark_dropout, shiny_dropout=shiny_dropout)
        scan, _ = cast_tablet(
            scanner,
            positions,
            look,
            40000,
            np.random.default_rng(4),
            cfg,
            BATCH,
            shiny_colors=METAL)
        return np.array([np.mean(scan.part == p) for p in (1, 2, 3)])

    clean = shares(0.0, 0.0)
    assert np.all(clean > 0.03)
    gone = shares(1.0, 1.0)
    assert gone[0] == 0 and gone[1] == 0 and gone[2] > clean[2]
    half = shares(0.5, 0.5)
    ratio = half / clean
    assert 0.35 < ratio[0] < 0.7 and 0.35 < ratio[1] < 0.7 and 0.95 < ratio[2] < 1.3


def wall_coverage(xyz: np.ndarray, size) -> list[float]:
    """Per wall of a box room (x=0, x=X, y=0, y=Y): the share of its length, in 10 cm bins,
    with points within 5 cm of the wall plane (between 0.2 m above the floor and below the
    ceiling)."""
    xyz = xyz[(xyz[:, 2] > 0.2) & (xyz[:, 2] < size[2] - 0.2)]
    shares = []
    for axis, plane in ((0, 0.0), (0, size[0]), (1, 0.0), (1, size[1])):
        along = xyz[np.abs(xyz[:, axis] - plane) < 0.05, 1 - axis]
        bins = int(round(size[1 - axis] / 0.1))
        counts = np.histogram(along, bins=bins, range=(0.0, size[1 - axis]))[0]
        shares.append(float(np.mean(counts > 0)))
    return shares


@pytest.mark.parametrize(
    'cubes',
    [
        [],
        # a bench along the south wall, across the walk's line 1 m from the wall, and a cabinet
        [((1.5, 0.5, 0.0), (8.5, 1.4, 0.9), (200, 0, 0)),
         ((8.8, 4.6, 0.0), (9.6, 5.7, 1.2), (0, 200, 0))],
    ],
    ids=['empty', 'objects-along-walls'])
def test_tablet_walk_covers_every_wall(cubes):
    """A handheld scan faces the walls while walking around: every wall is seen along >= 90 % of
    its length, and the walk steps around objects instead of leaving gaps."""
    size = (10.0, 6.0, 3.0)
    scanner = Scanner(room_scene(size, cubes))
    obstacles = np.array([[lo[:2], hi[:2]] for lo, hi, _ in cubes], float).reshape(-1, 2, 2)
    room = RoomGeometry(
        np.array([[0, 0], [0, 6], [10, 6], [10, 0]], float), 3.0, [], obstacles,
        np.array([False] + [True] * len(cubes)))
    cfg = dict(DEFAULTS['scanner'], batch_rays=BATCH)
    scan, sensor = scan_room(scanner, room, 'tablet', 100000, 0.0, np.random.default_rng(6),
                             cfg)
    shares = wall_coverage(scan.xyz, size)
    assert min(shares) >= 0.9, f'wall coverage {shares}'
    trajectory = np.array(sensor['trajectory'])[:, :2]
    # stepping around a box jumps at most across it (the old walk left metres-long gaps here)
    assert np.linalg.norm(np.diff(trajectory, axis=0), axis=1).max() < 1.5
    for low, high in obstacles:  # poses next to an object were pushed out to 0.3 m
        gap = np.maximum(np.maximum(low - trajectory, trajectory - high), 0.0)
        assert np.linalg.norm(gap, axis=1).min() >= 0.3 - 1e-3


def test_corners_of_generated_tablet_rooms(tmp_path):
    """The corner finder recovers generated rooms scanned by the tablet: the walls the walk
    faces are dense enough (the old walk along the walk direction missed walls in 3 of these 4
    rooms)."""
    out = tmp_path / 'out'
    assert main([
        '--out',
        str(out), '--areas', '9', '--rooms-per-area', '4', '--points', '200000', '--seed', '0',
        '--profile', 'tablet', '--asset-cache',
        str(tmp_path / 'assets'), '--quiet'
    ]) == 0
    metas = sorted(out.rglob('meta.json'))
    assert len(metas) == 4
    for meta_path in metas:
        meta = json.loads(meta_path.read_text())
        assert meta['generator']['sensor']['model'] == 'tablet'
        points, _ = read_point_file(meta_path.parent / f'{meta_path.parent.name}.txt')
        truth = np.asarray(meta['room']['polygon'], dtype=float)
        errors = corner_errors(detect_corners(points).corners, truth)
        assert errors.max() < 0.05, f'{meta_path.parent.name}: corner errors {errors}'


class RecordingScanner(Scanner):
    """The real scanner, keeping the directions of every batch it casts."""

    def __init__(self, scene: TriangleScene):
        super().__init__(scene)
        self.directions: list[np.ndarray] = []

    def cast(self, raycaster, origins, directions, rng=None):
        self.directions.append(np.array(directions))
        return super().cast(raycaster, origins, directions, rng)


def test_paper_profile_casts_uniform_directions():
    profile = load_config(REPO / 'generator' / 'profiles' / 'paper.json')['scanner']
    assert profile['sensors'] == {'paper': 1.0, 'tls': 0.0, 'tablet': 0.0,
                                  'depth_frame': 0.0, 'reconstruction': 0.0}
    scene = room_scene((6, 4, 3), [((2, 1, 0), (3, 2, 1), (255, 0, 0))])
    room = RoomGeometry(
        np.array([[0, 0], [0, 4], [6, 4], [6, 0]], float), 3.0, [], np.zeros((0, 2, 2)),
        np.array([False, True]))
    z_histograms = {}
    for aim in (False, True):
        scanner = RecordingScanner(scene)
        cfg = dict(profile, batch_rays=16384, aim_at_objects=aim)
        scan, sensor = scan_room(scanner, room, 'paper', 4000, 0.5, np.random.default_rng(5), cfg)
        assert sensor['model'] == 'paper' and sensor['aim_at_objects'] == aim
        assert (scan.part == 1).sum() == 2000
        directions = np.concatenate(scanner.directions)
        z_histograms[aim] = np.histogram(
            directions[:, 2], bins=10, range=(-1, 1))[0] / len(directions)
        assert np.abs(directions.mean(axis=0)).max() < (0.02 if not aim else 1.0)
    # uniform on the sphere: z uniform in [-1, 1]; aimed rays mostly go down to the cube
    assert np.abs(z_histograms[False] - 0.1).max() < 0.01
    assert np.abs(z_histograms[True] - 0.1).max() > 0.05


def test_choose_sensor_follows_the_probabilities():
    draws = [
        choose_sensor(DEFAULTS['scanner']['sensors'], np.random.default_rng([9, i]))
        for i in range(3000)
    ]
    for model in SENSOR_MODELS:
        assert abs(draws.count(model) / 3000 - DEFAULTS['scanner']['sensors'][model]) < 0.03
    only = {'paper': 0.0, 'tls': 1.0, 'tablet': 0.0}
    assert {choose_sensor(only, np.random.default_rng(i)) for i in range(50)} == {'tls'}


def test_sensor_configuration_errors_name_the_file_and_key(tmp_path):
    config = tmp_path / 'bad.json'
    for settings, message in (
        ({
            'scanner': {
                'sensors': {
                    'paper': 0.5
                }
            }
        }, 'scanner.sensors" probabilities sum to 0.5'),
        ({
            'scanner': {
                'sensors': {
                    'lidar': 1.0
                }
            }
        }, 'unknown sensor model "lidar"'),
        ({
            'scanner': {
                'tls': {
                    'range_noise': [0.1]
                }
            }
        }, 'scanner.tls.range_noise'),
        ({
            'scanner': {
                'tls': {
                    'angular_step_deg': 0
                }
            }
        }, 'scanner.tls.angular_step_deg'),
        ({
            'scanner': {
                'tls': {
                    'point_spacing': -0.01
                }
            }
        }, 'scanner.tls.point_spacing'),
        ({
            'scanner': {
                'tls': {
                    'oversample': 0.5
                }
            }
        }, 'scanner.tls.oversample'),
        ({
            'scanner': {
                'tls': {
                    'stations': 2
                }
            }
        }, 'unknown key "scanner.tls.stations"'),
        ({
            'scanner': {
                'tablet': {
                    'min_range': 6.0
                }
            }
        }, 'scanner.tablet.min_range" must be below'),
        ({
            'scanner': {
                'tablet': {
                    'dark_dropout': 1.5
                }
            }
        }, 'scanner.tablet.dark_dropout'),
        ({
            'scanner': {
                'tablet': {
                    'wall_look': 1.5
                }
            }
        }, 'scanner.tablet.wall_look" is outside'),
    ):
        config.write_text(json.dumps(settings))
        with pytest.raises(ConfigError, match=f'{config}: .*{message}'.replace('[', r'\[')):
            load_config(config)


@pytest.fixture(scope='module')
def mixed_run(tmp_path_factory):
    """Three small rooms with the default sensor mix; seed 1 draws paper, TLS and tablet."""
    work = tmp_path_factory.mktemp('mix')
    args = [
        '--areas', '7', '--rooms-per-area', '3', '--points', '20000', '--seed', '1',
        '--asset-cache',
        str(work / 'assets'), '--quiet'
    ]
    assert main(['--out', str(work / 'out'), *args]) == 0
    return work, args


def test_the_default_mix_gives_each_sensor_its_rooms(mixed_run):
    work, _ = mixed_run
    models = {}
    for meta_path in sorted((work / 'out').rglob('meta.json')):
        meta = json.loads(meta_path.read_text())
        room = meta_path.parent
        points, _ = read_point_file(room / f'{room.name}.txt')
        assert len(points) == 20000
        sensor = meta['generator']['sensor']
        models[sensor['model']] = (meta, points[:, :3])
    assert set(models) == DEFAULT_MIX
    paper, _ = models['paper']
    assert paper['generator']['sensor_path'] and paper['generator']['object_points'] == 10000
    meta, xyz = models['tls']
    sensor = meta['generator']['sensor']
    assert 'sensor_path' not in meta['generator'] and sensor['stations']
    stations = np.array(sensor['stations'])
    assert np.all((stations[:, 2] >= 1.4) & (stations[:, 2] <= 1.7))
    # every point on the grid of the recorded step seen from one of the stations (within the
    # text files' millimetre rounding)
    on_grid = np.zeros(len(xyz), bool)
    for station in stations:
        rel = xyz - station
        tol = np.degrees(1e-3 / np.hypot(rel[:, 0], rel[:, 1])) / sensor['angular_step_deg']
        position = grid_position(xyz, station, sensor['angular_step_deg'])
        on_grid |= np.all(np.abs(position - np.round(position)) <= tol[:, None] + 1e-3, axis=1)
    assert on_grid.mean() > 0.99  # a mixed pixel rounded across a cell boundary may miss
    meta, xyz = models['tablet']
    sensor = meta['generator']['sensor']
    trajectory = np.array(sensor['trajectory'])
    assert len(trajectory) > 100 and sensor['max_range'] == 5.0
    nearest = np.min(np.linalg.norm(xyz[:, None, :] - trajectory[None, ::4], axis=2), axis=1)
    assert nearest.max() <= 5.0 + 0.05  # within the range of the walk (text rounding)


def test_tls_mixed_pixels_are_clutter_not_part_of_the_object(mixed_run):
    work, _ = mixed_run
    tls = [m for m in (work / 'out').rglob('meta.json')
           if json.loads(m.read_text())['generator']['sensor']['model'] == 'tls']
    assert len(tls) == 1
    meta, room = json.loads(tls[0].read_text()), tls[0].parent
    sensor = meta['generator']['sensor']
    stray, _ = read_point_file(room / 'Annotations' / f'{sensor["stray_instance"]}.txt')
    assert sensor['stray_instance'].startswith('clutter_') and len(stray) == sensor['stray_points']
    assert len(stray) > 20
    checked = 0
    for obj in meta['objects']:
        annotation = room / 'Annotations' / f'{obj["instance"]}.txt'
        if obj['class'] == 'clutter' or not annotation.exists():
            continue
        points, _ = read_point_file(annotation)
        box = obj['box']
        rel = points[:, :3] - box['center']
        cos, sin = np.cos(box['yaw']), np.sin(box['yaw'])
        local = np.stack([cos * rel[:, 0] + sin * rel[:, 1], -sin * rel[:, 0] + cos * rel[:, 1],
                          rel[:, 2]], axis=1)
        # the object's points lie on it, within the range noise and the text files' millimetres
        assert np.all(np.abs(local) <= np.array(box['size']) / 2 + 0.03), obj['instance']
        checked += 1
    assert checked >= 2


def test_object_fit_measures_the_share_of_a_turned_box_an_annotation_covers():
    box = {'center': [2.0, 1.0, 0.5], 'size': [1.0, 0.5, 0.4], 'yaw': np.radians(30.0)}
    rng = np.random.default_rng(0)
    # seen from one side only: the front half of the box's depth (local y from -0.25 to 0)
    local = rng.uniform([-0.5, -0.25, -0.2], [0.5, 0.0, 0.2], size=(20000, 3))
    world = local @ rotation_z(box['yaw']).T + box['center']
    ratio, outside, coverage = object_fit(world, box, tolerance=0.05)
    assert ratio == pytest.approx(1.0, abs=0.01) and outside == 0.0
    assert coverage == pytest.approx(0.5, abs=0.01)
    # a point 0.3 m beyond the box's side counts as outside and does not raise the coverage
    stray = np.array([[0.8, -0.1, 0.0]]) @ rotation_z(box['yaw']).T + box['center']
    ratio, outside, coverage = object_fit(np.vstack([world, stray]), box, tolerance=0.05)
    assert ratio == pytest.approx(1.3, abs=0.01) and outside == pytest.approx(1 / 20001)
    assert coverage == pytest.approx(0.5, abs=0.01)


def test_check_annotations_passes_the_rooms_and_catches_points_given_to_an_object(
        mixed_run, tmp_path, capsys):
    work, _ = mixed_run
    assert check_annotations([str(work / 'out'), '--areas', '7', '--out', str(tmp_path / 'ok.json')]) == 0
    rows = json.loads((tmp_path / 'ok.json').read_text())['rows']
    assert {row['sensor'] for row in rows} == DEFAULT_MIX
    assert all(row['objects_with_points_outside'] == 0 for row in rows)
    assert all(row['extent_median'] <= 1.1 for row in rows)  # tablet noise: about 1 cm
    assert all(0.0 < row['coverage_median'] <= 1.0 for row in rows)
    # an --out that does not fit on the disk: one line naming it, exit 1, nothing half-written
    report = tmp_path / 'full' / 'report.json'
    report.parent.mkdir()
    proc = run('tools/check_annotations.py', work / 'out', '--areas', '7', '--out', report,
               preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0)))
    assert_clean_error(proc, 1, str(report))
    assert not report.exists() and temporaries(report.parent) == []
    # the labelling before the fix: the TLS room's mixed pixels given to one of its objects
    copy = tmp_path / 'raw'
    shutil.copytree(work / 'out', copy)
    meta_path = next(m for m in copy.rglob('meta.json')
                     if json.loads(m.read_text())['generator']['sensor']['model'] == 'tls')
    meta, room = json.loads(meta_path.read_text()), meta_path.parent
    stray = room / 'Annotations' / f'{meta["generator"]["sensor"]["stray_instance"]}.txt'
    chair = next(o['instance'] for o in meta['objects']
                 if o['class'] in ('chair', 'table', 'yumi', '3dprinter', 'sofa')
                 and (room / 'Annotations' / f'{o["instance"]}.txt').exists())
    with open(room / 'Annotations' / f'{chair}.txt', 'a') as f:
        f.write(stray.read_text())
    capsys.readouterr()
    assert check_annotations([str(copy), '--areas', '7']) == 1
    out = capsys.readouterr()
    assert f'{room.name}/{chair} (tls)' in out.out and 'points outside their box' in out.err
    assert check_annotations([str(copy), '--areas', '8']) == 2  # no such area: named, exit 2
    assert f'{copy / "Area_8"}: no such area folder' in capsys.readouterr().err


def test_same_seed_gives_the_same_files(mixed_run):
    work, args = mixed_run
    assert main(['--out', str(work / 'again'), *args, '--workers', '2']) == 0
    same_tree(work / 'out', work / 'again')


def test_profile_option_selects_a_packaged_profile(mixed_run, capsys):
    work, args = mixed_run
    assert main(['--out', str(work / 'paper'), *args[:-1], '--profile', 'paper', '--quiet']) == 0
    for meta_path in (work / 'paper').rglob('meta.json'):
        meta = json.loads(meta_path.read_text())
        generator = meta['generator']
        assert generator['sensor']['model'] == 'paper'
        assert generator['config']['scanner']['aim_at_objects'] is False
        assert not generator['appearance']['shading'] and not generator['appearance']['colorless']
        assert not [obj for obj in meta['objects'] if obj['class'] == 'clutter']
    with pytest.raises(SystemExit):
        main(['--out', str(work / 'bad'), '--profile', 'nope'])
    assert "invalid choice: 'nope'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['--out', str(work / 'bad'), '--profile', 'paper', '--config', 'x.json'])
    assert 'not allowed with argument' in capsys.readouterr().err


def glass_scene() -> TriangleScene:
    """A room with a 6 mm glass pane (printer door glass) 1 m in front of a red box."""
    return room_scene((8, 6, 3), [((3.0, 1.0, 0.0), (3.006, 5.0, 2.5), SEE_THROUGH[-1]),
                                  ((4.0, 2.0, 0.0), (5.0, 4.0, 2.0), (200, 0, 0))])


@pytest.mark.parametrize('transmission', [0.0, 0.5, 1.0])
def test_rays_pass_glass_with_the_configured_probability(transmission):
    scanner = Scanner(glass_scene(), glass_colors=SEE_THROUGH, glass_transmission=transmission)
    rng = np.random.default_rng(0)
    n = 4000
    origins = np.tile([1.0, 3.0, 1.0], (n, 1))
    directions = np.column_stack([np.ones(n), rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n)])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for raycaster, triangle_of in ((scanner.full_scene, np.arange(len(scanner.scene.part))),
                                   (scanner.object_scene, scanner.object_tri)):
        t_hit, prim = scanner.cast(raycaster, origins, directions, np.random.default_rng(1))
        part = scanner.scene.part[triangle_of[prim]]
        assert set(np.unique(part)) <= {1, 2}  # every ray returns from the glass or the box
        on_box = part == 2
        assert on_box.mean() == pytest.approx(transmission, abs=0.03)
        x = origins[:, 0] + directions[:, 0] * t_hit
        # the box's face at x = 4 (the ray's true distance), the pane's near face at x = 3
        assert np.allclose(x[on_box], 4.0, atol=1e-3) and np.allclose(x[~on_box], 3.0, atol=1e-3)
    # without a random stream, and by default, glass is opaque
    t_plain, _ = scanner.cast(scanner.full_scene, origins, directions)
    assert np.allclose(origins[:, 0] + directions[:, 0] * t_plain, 3.0, atol=1e-3)
    assert not Scanner(glass_scene()).glass_tri.any()


def test_every_sensor_model_sees_through_glass():
    """The paper path, the laser scanner and the tablet all cast through Scanner.cast: with
    glass_transmission 1 none of them returns a point on the glass, with 0 all of them do."""
    cfg = dict(DEFAULTS['scanner'], batch_rays=BATCH)
    room = room_geometry(
        np.array([[0, 0], [8, 0], [8, 6], [0, 6]], float), 3.0, [], glass_scene(),
        ['wall', '3dprinter', 'clutter'])
    for transmission, seen in ((1.0, False), (0.0, True)):
        scanner = Scanner(glass_scene(), glass_colors=SEE_THROUGH,
                          glass_transmission=transmission)
        for model in SENSOR_MODELS:
            scan, _ = scan_room(scanner, room, model, 20000, 0.5, np.random.default_rng(2),
                                dict(cfg, glass_transmission=transmission), METAL)
            assert (1 in scan.part) == seen, (model, transmission)
            assert 2 in scan.part, model  # the box behind the glass
