"""Appearance of generated scans: shading by a light, per-instance colors, colorless rooms.

Through the real generator (bpy, Embree, procedural library) on small rooms, and on a hand-made
triangle scene scanned by the real Embree scanner where the expected colors follow from the
geometry.
"""
import json
from pathlib import Path

import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
import numpy as np
import pytest

from generator.__main__ import main
from generator.appearance import RoomAppearance, apply_appearance, draw_appearance
from generator.config import DEFAULTS, ConfigError, load_config
from generator.scanner import Scanner, TriangleScene, sensor_path
from synthdet.point_text import read_point_file
from tests.test_generator.test_generator_pipeline import box_room_scene

PROFILES = Path(__file__).resolve().parents[2] / 'generator' / 'profiles'
OFF = {'shading': 0.0, 'instance_variation': 0.0, 'colorless': 0.0}


@pytest.fixture(scope='module')
def asset_cache(tmp_path_factory):
    return tmp_path_factory.mktemp('assets')


def _generate(out: Path, asset_cache: Path, config: Path) -> list[Path]:
    """Two small rooms of area 7 (seed 11) with the given configuration file."""
    common = '--areas 7 --rooms-per-area 2 --points 4000 --seed 11 --quiet'.split()
    run = ['--out', str(out), '--asset-cache', str(asset_cache), '--config', str(config)]
    assert main(run + common) == 0
    return sorted(p for p in (out / 'Area_7').iterdir() if p.is_dir())


def _points(path: Path) -> np.ndarray:
    return read_point_file(path)[0]


def _config_file(tmp_path: Path, appearance: dict) -> Path:
    path = tmp_path / 'appearance.json'
    path.write_text(json.dumps({'appearance': appearance}))
    return path


def test_colorless_rooms_write_zeros_and_keep_the_scan(asset_cache, tmp_path):
    root = tmp_path / 'colorless'
    out = root / 'Stanford3dDataset_v1.2_Aligned_Version'
    rooms = _generate(out, asset_cache, PROFILES / 'colorless.json')
    # the paper profile: the same settings with appearance off
    plain = _generate(tmp_path / 'off', asset_cache, PROFILES / 'paper.json')
    for room, reference in zip(rooms, plain):
        points = _points(room / f'{room.name}.txt')
        assert len(points) == 4000 and np.all(points[:, 3:] == 0)
        annotations = sorted((room / 'Annotations').glob('*.txt'))
        assert len(annotations) > 5
        for path in annotations:
            assert np.all(_points(path)[:, 3:] == 0), path
        meta = json.loads((room / 'meta.json').read_text())
        assert meta['generator']['appearance'] == {
            'shading': False,
            'light': None,
            'colorless': True,
            'instance_variation': 0.0
        }
        # appearance draws from its own stream: same points and objects as without it
        reference_points = _points(reference / f'{reference.name}.txt')
        assert np.array_equal(points[:, :3], reference_points[:, :3])
        assert reference_points[:, 3:].max() > 0
        reference_meta = json.loads((reference / 'meta.json').read_text())
        assert meta['objects'] == reference_meta['objects']
        assert meta['room'] == reference_meta['room']
    # the dataset converter and the Table 1 counter take all-zero colors
    from projects.synthdet.datasets.s3dis_converter import convert_s3dis
    from projects.synthdet.evaluation.table1 import count_instances
    converted = tmp_path / 'converted'
    convert_s3dis(root, converted, areas=[7])
    bins = sorted((converted / 'points').glob('*.bin'))
    assert len(bins) == 2
    for path in bins:
        assert np.all(np.fromfile(path, dtype=np.float32).reshape(-1, 6)[:, 3:] == 0)
    assert sum(count_instances(converted, [7])[7].values()) > 0


def test_shaded_profile_changes_colors_only(asset_cache, tmp_path):
    rooms = _generate(tmp_path / 'shaded', asset_cache, PROFILES / 'shaded.json')
    # the paper profile: the same settings with appearance off
    plain = _generate(tmp_path / 'off', asset_cache, PROFILES / 'paper.json')
    for room, reference in zip(rooms, plain):
        points = _points(room / f'{room.name}.txt')
        reference_points = _points(reference / f'{reference.name}.txt')
        assert np.array_equal(points[:, :3], reference_points[:, :3])
        assert not np.array_equal(points[:, 3:], reference_points[:, 3:])
        appearance = json.loads((room / 'meta.json').read_text())['generator']['appearance']
        assert appearance['shading'] and not appearance['colorless']
        light = np.asarray(appearance['light'])
        assert abs(np.linalg.norm(light) - 1) < 1e-5 and light[2] >= np.cos(np.radians(60)) - 1e-6


def _two_cube_room() -> tuple[TriangleScene, np.ndarray]:
    """The pipeline tests' box room with a second, equal cube (part 3) 2 m further along x."""
    scene, polygon = box_room_scene()
    cube = scene.triangles[scene.part == 2]
    vertices = np.concatenate([scene.vertices, scene.vertices[8:16] + [2.0, 0.0, 0.0]])
    triangles = np.concatenate([scene.triangles, cube + 8])
    colors = np.concatenate([scene.colors[:12], np.tile([200, 40, 40], (24, 1))]).astype(np.uint8)
    part = np.concatenate([scene.part, np.full(12, 3, np.int32)])
    movable = np.array([False, False, True, True])
    return TriangleScene(vertices, triangles, colors, part, movable), polygon


def _scan(scene: TriangleScene, polygon: np.ndarray):
    config = dict(DEFAULTS['scanner'], batch_rays=8192)
    path, _ = sensor_path(polygon, 3.0, np.random.default_rng(0))
    return Scanner(scene).scan(path, 20000, 0.5, np.random.default_rng(1), config)


def _appearance(light=(0.0, 0.0, 1.0), shading=True, variation=0.0, colorless=False,
                factor=None) -> RoomAppearance:
    factor = np.ones((4, 3)) if factor is None else factor
    light = np.asarray(light, float) / np.linalg.norm(light)
    return RoomAppearance(shading, light, 0.5, colorless, variation, factor)


def test_shading_darkens_faces_turned_away_from_the_light():
    scene, polygon = _two_cube_room()
    scan = _scan(scene, polygon)
    assert np.array_equal(scan.rgb, scene.colors[scan.triangle])
    light = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)  # from +x, 45 degrees up
    rgb = apply_appearance(_appearance(light), scan, scene).astype(float)
    cube = (scan.part == 2) | (scan.part == 3)
    face = scan.triangle % 12  # the order of box(): bottom, top, -y, +x, +y, -x (2 each)
    on_face = {
        '+x': cube & (face // 2 == 3),
        '-x': cube & (face // 2 == 5),
        'top': cube & (face // 2 == 1)
    }
    x, z = scan.xyz[:, 0], scan.xyz[:, 2]
    at_x = x[on_face['+x']]  # the cubes span x 2-3 and 4-5
    assert np.all(np.isclose(at_x, 3, atol=1e-4) | np.isclose(at_x, 5, atol=1e-4))
    assert all(mask.sum() > 100 for mask in on_face.values())
    lit = 0.5 + 0.5 * np.cos(np.pi / 4)
    assert np.all(rgb[on_face['+x'], 0] == np.rint(200 * lit))
    assert np.all(rgb[on_face['top'], 0] == np.rint(200 * lit))
    assert np.all(rgb[on_face['-x'], 0] == 100)  # turned away: ambient only
    # the ceiling is seen from below: its side facing the sensor looks away from the light
    ceiling = (scan.part == 1) & np.isclose(z, 3, atol=1e-4)
    assert ceiling.sum() > 100 and np.all(rgb[ceiling] == 100)
    floor = scan.part == 0
    assert np.all(rgb[floor] == np.rint(np.array([10, 20, 30]) * lit))
    # the normal is turned towards the sensor: the triangles' winding does not matter
    flipped = TriangleScene(scene.vertices, scene.triangles[:, ::-1].copy(), scene.colors,
                            scene.part, scene.movable)
    assert np.array_equal(apply_appearance(_appearance(light), scan, flipped), rgb)


def test_instance_variation_gives_two_instances_of_one_asset_different_colors():
    scene, polygon = _two_cube_room()
    scan = _scan(scene, polygon)
    config = dict(DEFAULTS['appearance'], **OFF) | {'instance_variation': 0.1}
    appearance = draw_appearance(np.random.default_rng(3), config, 4)
    rgb = apply_appearance(appearance, scan, scene)
    colors = [np.unique(rgb[scan.part == p], axis=0) for p in (2, 3)]
    # one color per instance (no shading), and the two cubes differ
    assert len(colors[0]) == 1 and len(colors[1]) == 1
    assert not np.array_equal(colors[0], colors[1])
    expected = np.rint(np.array([200, 40, 40]) * appearance.part_factor[2:]).astype(int)
    assert np.array_equal(np.concatenate(colors), np.clip(expected, 0, 255))


def test_appearance_off_keeps_the_material_colors():
    scene, polygon = _two_cube_room()
    scan = _scan(scene, polygon)
    appearance = draw_appearance(np.random.default_rng(4), dict(DEFAULTS['appearance'], **OFF), 4)
    assert appearance.meta() == {
        'shading': False,
        'light': None,
        'colorless': False,
        'instance_variation': 0.0
    }
    assert np.array_equal(apply_appearance(appearance, scan, scene), scene.colors[scan.triangle])
    colorless = apply_appearance(_appearance(colorless=True), scan, scene)
    assert colorless.shape == scan.rgb.shape and not colorless.any()


def test_switching_one_effect_leaves_the_other_draws_unchanged():
    base = dict(DEFAULTS['appearance'], instance_variation=0.2)
    draws = [
        draw_appearance(np.random.default_rng(9), dict(base, shading=p, colorless=q), 5)
        for p, q in ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0))
    ]
    flags = [(d.shading, d.colorless) for d in draws]
    assert flags == [(False, False), (True, False), (False, True)]
    for other in draws[1:]:
        assert np.array_equal(other.light, draws[0].light)
        assert np.array_equal(other.part_factor, draws[0].part_factor)


@pytest.mark.parametrize('key, value, message', [
    ('shading', 1.5, '"appearance.shading" = 1.5 is outside [0, 1]'),
    ('colorless', -0.1, '"appearance.colorless" = -0.1 is outside [0, 1]'),
    ('ambient', 'dim', '"appearance.ambient" must be a number'),
    ('instance_variation', -1, '"appearance.instance_variation" must not be negative'),
    ('light_tilt', [60, 30], '"appearance.light_tilt" has min > max'),
    ('light_tilt', [0, 120], '"appearance.light_tilt" must stay within [0, 90] degrees'),
    ('glossy', 1, 'unknown key "appearance.glossy"'),
])
def test_config_errors_name_the_file_and_key(tmp_path, key, value, message):
    path = _config_file(tmp_path, {key: value})
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert str(error.value).startswith(f'{path}: ') and message in str(error.value)


def test_profiles_load():
    assert load_config(PROFILES / 'shaded.json')['appearance']['shading'] == 1.0
    assert load_config(PROFILES / 'colorless.json')['appearance']['colorless'] == 1.0
    assert load_config()['appearance'] == DEFAULTS['appearance']
