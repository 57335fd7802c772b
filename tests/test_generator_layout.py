"""Layout rules on many seeded rooms, Table 1 counts, configuration errors and the text format.

The layout itself is pure numpy; the catalog comes from the real procedural asset library (built
once per module with bpy), so the rules and the counts are checked with the real object sizes.
"""
import copy
import json
import subprocess
import sys

import numpy as np
import pytest

from generator.config import DEFAULTS, ConfigError, load_config
from generator.layout import box_corners_xy, generate_layout, points_in_polygon
from generator.pipeline import plan_tasks
from generator.writer import format_lines
from synthdet.classes import GENERATED_CLASSES

TABLE1 = {'chair': 364, 'table': 252, 'sofa': 86, 'yumi': 200, '3dprinter': 192}


@pytest.fixture(scope='module')
def catalog(tmp_path_factory):
    import bpy  # noqa: F401  (before open3d, see docs/stack)
    from generator.assets import ASSET_CLASSES, default_library
    from generator.layout import catalog_from_library
    assert tuple(ASSET_CLASSES) == GENERATED_CLASSES
    return catalog_from_library(default_library(tmp_path_factory.mktemp('assets')))


def _inside_convex(points: np.ndarray, quad: np.ndarray, tol: float) -> np.ndarray:
    """Points strictly inside a counter-clockwise convex quad, by more than ``tol``."""
    inside = np.ones(len(points), dtype=bool)
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        edge = (b - a) / np.linalg.norm(b - a)
        cross = edge[0] * (points[:, 1] - a[1]) - edge[1] * (points[:, 0] - a[0])
        inside &= cross > tol
    return inside


def _footprints_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Independent of the layout's separating-axis test: samples of each quad in the other."""
    if np.linalg.norm(a.mean(0) - b.mean(0)) > (np.ptp(a, 0).sum() + np.ptp(b, 0).sum()):
        return False  # far apart: cannot overlap
    t = np.linspace(0.0, 1.0, 15)
    for p, q in ((a, b), (b, a)):
        u, v = np.meshgrid(t, t)
        samples = (p[0] + u.reshape(-1, 1) * (p[1] - p[0]) + v.reshape(-1, 1) * (p[3] - p[0]))
        if _inside_convex(samples, q, 1e-6).any():
            return True
    return False


def _vertical_overlap(a: dict, b: dict) -> bool:
    az = a['box']['center'][2], a['box']['size'][2]
    bz = b['box']['center'][2], b['box']['size'][2]
    return (az[0] + az[1] / 2 > bz[0] - bz[1] / 2 + 1e-6) and (bz[0] + bz[1] / 2
                                                               > az[0] - az[1] / 2 + 1e-6)


def _check_rules(layout) -> None:
    from generator.layout import layout_meta
    meta = layout_meta(layout)
    polygon = np.asarray(meta['room']['polygon'])
    x, y = polygon[:, 0], polygon[:, 1]
    assert np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y) < 0, 'polygon not clockwise'
    objects = meta['objects']
    counts = {cls: sum(o['class'] == cls for o in objects) for cls in GENERATED_CLASSES}
    assert counts['chair'] <= 4
    assert counts['table'] + counts['sofa'] <= 4
    by_name = {o['instance']: o for o in objects}
    quads = {
        o['instance']: box_corners_xy(o['box']['center'], o['box']['size'], o['box']['yaw'])
        for o in objects
    }
    sides_used: dict[str, list[int]] = {}
    for obj in objects:
        box = obj['box']
        quad = quads[obj['instance']]
        assert points_in_polygon(quad, polygon).all(), f"{obj['instance']} outside the room"
        assert not _inside_convex(polygon, quad, 1e-6).any(), 'a room corner pokes into an object'
        sensor_z = DEFAULTS['scanner']['sensor_height'] * meta['room']['height']
        assert box['center'][2] + box['size'][2] / 2 <= sensor_z - 0.1 + 1e-6  # below the sensor
        if obj['class'] in ('yumi', '3dprinter'):
            table = by_name[obj['on']]  # only on tables
            assert table['class'] == 'table'
            tb = table['box']
            assert box['center'][2] - box['size'][2] / 2 == pytest.approx(
                _top_z(table, layout), abs=1e-6)
            # footprint on one half of the table top, in the table frame
            rot = np.array([[np.cos(-tb['yaw']), -np.sin(-tb['yaw'])],
                            [np.sin(-tb['yaw']), np.cos(-tb['yaw'])]])
            local = (quads[obj['instance']] - np.asarray(tb['center'][:2])) @ rot.T
            top_w, top_d = _top_size(table, layout)
            assert np.all(np.abs(local[:, 0]) <= top_w / 2 + 1e-6)
            assert np.all(np.abs(local[:, 1]) <= top_d / 2 + 1e-6)
            side = 1 if local[:, 0].min() >= -1e-6 else -1
            assert side == 1 or local[:, 0].max() <= 1e-6, 'item straddles the table middle'
            sides_used.setdefault(obj['on'], []).append(side)
        else:
            assert obj['on'] is None
    for table, sides in sides_used.items():
        assert len(sides) == len(set(sides)) <= 2, f'{table}: two items on one side'
    names = list(by_name)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            oa, ob = by_name[a], by_name[b]
            if oa['on'] == b or ob['on'] == a:
                continue
            if _vertical_overlap(oa, ob):
                assert not _footprints_overlap(quads[a], quads[b]), f'{a} intersects {b}'


def _spec(table: dict, layout):
    return next(o.spec for o in layout.objects if o.instance == table['instance'])


def _top_z(table: dict, layout) -> float:
    tb = table['box']
    return tb['center'][2] - tb['size'][2] / 2 + _spec(table, layout).top_z


def _top_size(table: dict, layout):
    return _spec(table, layout).top_size


def test_rules_hold_on_many_seeded_rooms(catalog):
    config = load_config()
    shapes = {'box': 0, 'L': 0, 'U': 0}
    for seed in range(100):
        layout = generate_layout(np.random.default_rng([seed, 0]), catalog, config)
        shapes[layout.shape] += 1
        _check_rules(layout)
    # the same rules in L and U rooms, packed with objects
    dense = copy.deepcopy(config)
    dense['room']['shapes'] = {'box': 0.0, 'L': 0.5, 'U': 0.5}
    dense['probabilities'].update(table=0.8, sofa=0.2, chair=1.0, yumi=0.5)
    dense['probabilities']['3dprinter'] = 0.5
    dense['layout']['clutter'] = [4, 8]
    for seed in range(60):
        layout = generate_layout(np.random.default_rng([seed, 1]), catalog, dense)
        shapes[layout.shape] += 1
        _check_rules(layout)
    assert min(shapes.values()) >= 10, shapes


def test_default_run_reproduces_table1_counts(catalog):
    config = load_config()
    totals = dict.fromkeys(GENERATED_CLASSES, 0)
    for task in plan_tasks([7, 8, 9], 50, seed=0):  # exactly the rooms of the default run
        layout = generate_layout(np.random.default_rng([task.seed, 0]), catalog, config)
        for cls, n in layout.counts().items():
            totals[cls] += n
    for cls, target in TABLE1.items():
        assert abs(totals[cls] - target) <= 0.15 * target, (cls, totals[cls], target)


def test_expected_counts_are_calibrated(catalog):
    """The mean over many rooms, not just one lucky run, matches Table 1 (per 150 rooms)."""
    config = load_config()
    totals = dict.fromkeys(GENERATED_CLASSES, 0)
    tasks = plan_tasks([101, 102, 103, 104, 105, 106], 150, seed=7)
    for task in tasks:
        layout = generate_layout(np.random.default_rng([task.seed, 0]), catalog, config)
        for cls, n in layout.counts().items():
            totals[cls] += n
    for cls, target in TABLE1.items():
        mean = totals[cls] * 150 / len(tasks)
        assert abs(mean - target) <= 0.09 * target, (cls, mean, target)


@pytest.mark.parametrize('patch, message', [
    ({
        'probabilities': {
            'chair': 1.5
        }
    }, 'outside [0, 1]'),
    ({
        'probabilities': {
            'robot': 0.5
        }
    }, 'unknown class "robot"'),
    ({
        'probabilities': {
            'table': 0.7,
            'sofa': 0.5
        }
    }, 'share one slot'),
    ({
        'layout': {
            'clutter': [-1, 3]
        }
    }, 'must not be negative'),
    ({
        'layout': {
            'chair_positions': -2
        }
    }, 'non-negative integer'),
    ({
        'layout': {
            'wall_slots': 6
        }
    }, 'at most 4'),
    ({
        'room': {
            'height': [3.5, 3.0]
        }
    }, 'min > max'),
    ({
        'room': {
            'shapes': {
                'box': 0.5
            }
        }
    }, 'sum to'),
    ({
        'room': {
            'colour': 'red'
        }
    }, 'unknown key "room.colour"'),
    ({
        'scanner': {
            'dropout': 'high'
        }
    }, 'must be a number'),
])
def test_bad_configuration_is_rejected_with_its_key(tmp_path, patch, message):
    path = tmp_path / 'bad.json'
    path.write_text(json.dumps(patch))
    with pytest.raises(ConfigError, match=message.replace('[', r'\[').replace(']', r'\]')) as err:
        load_config(path)
    assert str(path) in str(err.value)


def test_yaml_configuration_and_parse_errors(tmp_path):
    good = tmp_path / 'good.yaml'
    good.write_text('probabilities:\n  sofa: 0.0\nscanner:\n  range_noise: 0.01\n')
    config = load_config(good)
    assert config['probabilities']['sofa'] == 0.0 and config['scanner']['range_noise'] == 0.01
    assert config['probabilities']['table'] == DEFAULTS['probabilities']['table']
    broken = tmp_path / 'broken.yaml'
    broken.write_text('probabilities:\n  sofa: [0.1\n')
    with pytest.raises(ConfigError, match='line'):
        load_config(broken)


def test_cli_rejects_bad_input_before_any_work(tmp_path):
    bad = tmp_path / 'bad.json'
    bad.write_text(json.dumps({'probabilities': {'yumi': -0.1}}))
    for extra, message in ((['--config', str(bad)], 'outside [0, 1]'),
                           (['--points',
                             '-5'], '--points must be >= 1'), (['--shard',
                                                                '3/2'], '--shard must be K/N'),
                           (['--object-ratio',
                             '1.5'], '--object-ratio'), (['--rooms-per-area',
                                                          '0'], '--rooms-per-area')):
        out = tmp_path / 'out'
        result = subprocess.run([sys.executable, '-m', 'generator', '--out',
                                 str(out), *extra],
                                capture_output=True,
                                text=True,
                                timeout=60)
        assert result.returncode == 2, result.stderr
        assert message in result.stderr
        assert not out.exists()
    real = tmp_path / 's3dis'
    (real / 'Area_5' / 'office_1').mkdir(parents=True)
    result = subprocess.run(
        [sys.executable, '-m', 'generator', '--out',
         str(real), '--areas', '5'],
        capture_output=True,
        text=True,
        timeout=60)
    assert result.returncode == 2 and 'did not make (e.g. office_1)' in result.stderr
    assert [p.name for p in (real / 'Area_5').iterdir()] == ['office_1']


def test_text_format_parses_back_exactly():
    rng = np.random.default_rng(3)
    xyz = np.concatenate([
        rng.uniform(-30, 30, (5000, 3)),
        [[0.0, -0.0004, 0.0006], [-0.0006, 9.9996, -12.3454], [100.0, -0.001, 0.0]]
    ])
    rgb = rng.integers(0, 256, (len(xyz), 3))
    text, offsets = format_lines(xyz, rgb)
    lines = text.decode('ascii').split('\n')
    assert lines[-1] == '' and len(lines) == len(xyz) + 1
    assert offsets[-1] == len(text)
    assert text[offsets[5]:offsets[6]].decode() == lines[5] + '\n'
    parsed = np.array([[float(v) for v in line.split(' ')] for line in lines[:-1]])
    assert np.array_equal(parsed[:, :3], np.rint(xyz * 1000) / 1000)
    assert np.array_equal(parsed[:, 3:], rgb)
    assert all(len(line.split(' ')) == 6 and '-0.000' not in line for line in lines[:-1])
    assert [line.rsplit(' ', 3)[0] for line in lines[-4:-1]
            ] == ['0.000 0.000 0.001', '-0.001 10.000 -12.345', '100.000 -0.001 0.000']
