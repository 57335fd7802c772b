"""Layout rules on many seeded rooms, Table 1 counts, configuration errors and the text format.

The layout itself is pure numpy; the catalog comes from the real procedural asset library (built
once per module with bpy), so the rules and the counts are checked with the real object sizes.
Every placement rule of the paper (Sec. 3.1) and of docs/generator.md has its own test, and the
geometry they use (footprints, wall normals, the inner boundary, distances) is computed here from
``meta.json``-style boxes, independently of generator/layout.py.
"""
import copy
import json
import math
import subprocess
import sys
from dataclasses import dataclass
from typing import Iterator

import numpy as np
import pytest

from generator.config import DEFAULTS, ConfigError, load_config
from generator.layout import AssetSpec, generate_layout, layout_meta
from generator.pipeline import plan_tasks
from generator.writer import format_lines
from synthdet.classes import GENERATED_CLASSES

TABLE1 = {'chair': 364, 'table': 252, 'sofa': 86, 'yumi': 200, '3dprinter': 192}
TOL = 1e-5  # meta.json rounds to 6 decimals


@pytest.fixture(scope='module')
def catalog(tmp_path_factory):
    import bpy  # noqa: F401  (before open3d: both ship libtbb and the first one loaded wins)
    from generator.assets import ASSET_CLASSES, default_library
    from generator.layout import catalog_from_library
    assert tuple(ASSET_CLASSES) == GENERATED_CLASSES
    return catalog_from_library(default_library(tmp_path_factory.mktemp('assets')))


@dataclass
class Room:
    """One generated room: its meta.json parts, the asset spec of every object and its config."""

    name: str
    meta: dict
    specs: dict[str, AssetSpec]
    config: dict

    @property
    def polygon(self) -> np.ndarray:
        return np.asarray(self.meta['room']['polygon'], dtype=float)

    def objects(self, *classes: str) -> list[dict]:
        return [o for o in self.meta['objects'] if not classes or o['class'] in classes]


def make_rooms(catalog, config: dict, seeds: range, stream: int) -> list[Room]:
    rooms = []
    for seed in seeds:
        layout = generate_layout(np.random.default_rng([seed, stream]), catalog, config)
        rooms.append(
            Room(f'room [{seed}, {stream}]', layout_meta(layout),
                 {o.instance: o.spec
                  for o in layout.objects}, config))
    return rooms


@pytest.fixture(scope='module')
def rooms(catalog) -> list[Room]:
    """100 rooms of the defaults, 60 packed L/U rooms and 40 low rooms (the height limit binds)."""
    config = load_config()
    dense = copy.deepcopy(config)
    dense['room']['shapes'] = {'box': 0.0, 'L': 0.5, 'U': 0.5}
    dense['probabilities'].update({'table': 0.8, 'sofa': 0.2, 'chair': 1.0, 'yumi': 0.5})
    dense['probabilities']['3dprinter'] = 0.5
    dense['layout']['clutter'] = [4, 8]
    low = copy.deepcopy(dense)
    low['room']['shapes'] = {'box': 0.6, 'L': 0.2, 'U': 0.2}
    low['room']['height'] = [2.2, 2.3]
    result = (
        make_rooms(catalog, config, range(100), 0) + make_rooms(catalog, dense, range(60), 1) +
        make_rooms(catalog, low, range(40), 2))
    shapes = [room.meta['room']['shape'] for room in result]
    assert min(shapes.count(shape) for shape in ('box', 'L', 'U')) >= 10
    return result


# ----------------------------------------------------------------------------- geometry


def footprint(obj: dict) -> np.ndarray:
    """Corners (4, 2) of an object's box seen from above, counter-clockwise."""
    box = obj['box']
    hx, hy = box['size'][0] / 2, box['size'][1] / 2
    c, s = math.cos(box['yaw']), math.sin(box['yaw'])
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(box['center'][:2])


def front(obj: dict) -> np.ndarray:
    """World direction of an object's front (its local -y)."""
    yaw = obj['box']['yaw']
    return np.array([math.sin(yaw), -math.cos(yaw)])


def z_range(obj: dict) -> tuple[float, float]:
    box = obj['box']
    return box['center'][2] - box['size'][2] / 2, box['center'][2] + box['size'][2] / 2


def walls(polygon: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float, np.ndarray]]:
    """(start, unit direction, length, inward unit normal) of each edge of a clockwise polygon:
    walking clockwise seen from above, the room lies on the right."""
    result = []
    for start, end in zip(polygon, np.roll(polygon, -1, axis=0)):
        length = float(np.linalg.norm(end - start))
        direction = (end - start) / length
        result.append((start, direction, length, np.array([direction[1], -direction[0]])))
    return result


def point_segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((points - a) @ ab / float(ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def inside_convex(points: np.ndarray, quad: np.ndarray) -> np.ndarray:
    """Points strictly inside a counter-clockwise convex quad."""
    edges = np.roll(quad, -1, axis=0) - quad
    rel = points[:, None, :] - quad[None, :, :]
    return np.all(edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0] > 1e-9, axis=1)


def segments_cross(a0, a1, b0, b1) -> bool:

    def side(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    return (side(a0, a1, b0) * side(a0, a1, b1) < 0) and (side(b0, b1, a0) * side(b0, b1, a1) < 0)


def quad_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Distance between two convex quads (0 when they overlap)."""
    if inside_convex(p, q).any() or inside_convex(q, p).any():
        return 0.0
    best = np.inf
    for first, second in ((p, q), (q, p)):
        for i in range(4):
            a, b = second[i], second[(i + 1) % 4]
            if any(segments_cross(first[j], first[(j + 1) % 4], a, b) for j in range(4)):
                return 0.0
            best = min(best, float(point_segment_distance(first, a, b).min()))
    return best


def narrowest_leg(polygon: np.ndarray) -> float:
    """Smallest distance between two facing walls that overlap along their direction."""
    sides = walls(polygon)
    best = np.inf
    for start_i, dir_i, len_i, normal_i in sides:
        for start_j, dir_j, len_j, normal_j in sides:
            if normal_i @ normal_j > -0.999:
                continue
            gap = float((start_j - start_i) @ normal_i)
            span_j = sorted([
                float((start_j - start_i) @ dir_i),
                float((start_j + dir_j * len_j - start_i) @ dir_i)
            ])
            if gap > 0 and min(len_i, span_j[1]) - max(0.0, span_j[0]) > 1e-9:
                best = min(best, gap)
    return best


def inner_boundary(polygon: np.ndarray, distance: float) -> np.ndarray:
    """The polygon with every wall moved ``distance`` into the room (corners where the moved
    walls meet)."""
    lines = [(start + normal * distance, direction)
             for start, direction, _, normal in walls(polygon)]
    corners = []
    for (p, d), (q, e) in zip(lines[-1:] + lines[:-1], lines):
        t = np.linalg.solve(np.column_stack([d, -e]), q - p)[0]
        corners.append(p + t * d)
    return np.array(corners)


def inside_polygon(point: np.ndarray, polygon: np.ndarray) -> bool:
    """Even-odd rule; points on the boundary (within TOL) count as inside."""
    edges = list(zip(polygon, np.roll(polygon, -1, axis=0)))
    if any(point_segment_distance(point[None], a, b)[0] < TOL for a, b in edges):
        return True
    crossings = 0
    for a, b in edges:
        if (a[1] > point[1]) != (b[1] > point[1]):
            crossings += point[0] < a[0] + (point[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
    return crossings % 2 == 1


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


# ----------------------------------------------------------------------------- the rules


def test_rooms_are_clockwise_and_hold_their_objects(rooms):
    for room in rooms:
        polygon = room.polygon
        x, y = polygon[:, 0], polygon[:, 1]
        assert np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y) < 0, 'not clockwise'
        for obj in room.objects():
            quad = footprint(obj)
            outside = [corner for corner in quad if not inside_polygon(corner, polygon)]
            assert not outside, f"{room.name}: {obj['instance']} leaves the room at {outside}"
            assert not inside_convex(polygon, quad).any(), \
                f"{room.name}: a room corner pokes into {obj['instance']}"


def test_tables_and_sofas_stand_at_a_wall_with_their_back_to_it(rooms):
    """Paper: along the walls, sharing the space; docs: back to the wall (a gap of
    ``layout.wall_gap``), front towards the room, one per wall slot (the 4 longest walls)."""
    placed = 0
    for room in rooms:
        gap_low, gap_high = room.config['layout']['wall_gap']
        sides = walls(room.polygon)
        lengths = np.array([length for _, _, length, _ in sides])
        used = []
        for obj in room.objects('table', 'sofa'):
            centre = np.asarray(obj['box']['center'][:2])
            depth = obj['box']['size'][1]
            quad = footprint(obj)
            at = []
            for index, (start, direction, length, normal) in enumerate(sides):
                gap = float((centre - start) @ normal) - depth / 2
                along = (quad - start) @ direction
                if (front(obj) @ normal > 1 - 1e-6 and gap_low - TOL <= gap <= gap_high + TOL
                        and along.min() >= -TOL and along.max() <= length + TOL):
                    at.append(index)
            assert len(at) == 1, (
                f"{room.name}: {obj['instance']} (centre {centre}, yaw "
                f"{obj['box']['yaw']:.3f}) stands at no wall with its back to it")
            wall = at[0]
            longer = int((lengths > lengths[wall] + 1e-6).sum())
            assert longer < room.config['layout']['wall_slots'], \
                f"{room.name}: {obj['instance']} stands at wall {wall}, not a slot wall"
            used.append(wall)
            placed += 1
        assert len(used) == len(set(used)), f'{room.name}: two wall items share a wall slot'
        assert len(used) <= 4
    assert placed > 200


def test_chairs_stand_on_the_inner_boundary_with_random_rotations(rooms):
    """Paper: 4 positions on an imaginary inner boundary, free rotation; docs: the floor polygon
    moved ``layout.chair_margin`` (1.7 m) inwards, 0.3 x the narrowest leg in narrow rooms."""
    yaws = []
    for room in rooms:
        chairs = room.objects('chair')
        assert len(chairs) <= room.config['layout']['chair_positions']
        polygon = room.polygon
        margin = min(room.config['layout']['chair_margin'], 0.3 * narrowest_leg(polygon))
        ring = inner_boundary(polygon, margin)
        for chair in chairs:
            centre = np.asarray(chair['box']['center'][:2])
            off = min(
                point_segment_distance(centre[None], a, b)[0]
                for a, b in zip(ring, np.roll(ring, -1, axis=0)))
            assert off < TOL, (f"{room.name}: {chair['instance']} at {centre} is {off:.3f} m off "
                               f'the inner boundary ({margin:.3f} m from the walls)')
            yaws.append(chair['box']['yaw'])
    assert len(yaws) > 300
    counts, _ = np.histogram(yaws, bins=8, range=(-math.pi, math.pi))
    assert counts.min() > 0.5 * len(yaws) / 8, f'chair rotations are not uniform: {counts}'


def test_items_stand_on_one_side_of_a_table_top(rooms):
    """Paper: yumis and 3D printers only on tables, one on each local side (left -x, right +x);
    docs: inside the top."""
    items = 0
    for room in rooms:
        by_name = {obj['instance']: obj for obj in room.objects()}
        sides_used: dict[str, list[int]] = {}
        for obj in room.objects(*GENERATED_CLASSES):
            if obj['class'] not in ('yumi', '3dprinter'):
                assert obj['on'] is None, f"{room.name}: {obj['instance']} stands on something"
                continue
            table = by_name[obj['on']]
            assert table['class'] == 'table', f"{room.name}: {obj['instance']} not on a table"
            spec = room.specs[table['instance']]
            top = z_range(table)[0] + spec.top_z
            assert z_range(obj)[0] == pytest.approx(top, abs=TOL), 'not standing on the top'
            yaw = table['box']['yaw']
            to_table = np.array([[math.cos(yaw), math.sin(yaw)], [-math.sin(yaw), math.cos(yaw)]])
            local = (footprint(obj) - np.asarray(table['box']['center'][:2])) @ to_table.T
            top_w, top_d = spec.top_size
            assert np.all(np.abs(local[:, 0]) <= top_w / 2 + TOL), 'beyond the top (x)'
            assert np.all(np.abs(local[:, 1]) <= top_d / 2 + TOL), 'beyond the top (y)'
            right, left = local[:, 0].min() >= -TOL, local[:, 0].max() <= TOL
            assert right or left, f"{room.name}: {obj['instance']} straddles the table middle"
            sides_used.setdefault(obj['on'], []).append(1 if right else -1)
            items += 1
        for table, sides in sides_used.items():
            assert len(sides) == len(set(sides)), f'{room.name}: two items on one side of {table}'
    assert items > 200


def test_yumis_face_the_front_of_their_table_printers_turn_by_quarter_turns(rooms):
    """docs: a yumi faces the front of its table (like its operator: the same yaw); a printer may
    be turned by quarter turns."""
    yumis, printer_turns = 0, set()
    for room in rooms:
        by_name = {obj['instance']: obj for obj in room.objects()}
        for obj in room.objects('yumi', '3dprinter'):
            table = by_name[obj['on']]
            turn = wrap(obj['box']['yaw'] - table['box']['yaw'])
            if obj['class'] == 'yumi':
                assert front(obj) @ front(table) > 1 - 1e-6, \
                    f"{room.name}: {obj['instance']} is turned {turn:.3f} rad from its table"
                yumis += 1
            else:
                quarters = turn / (math.pi / 2)
                assert abs(quarters - round(quarters)) < 1e-5, \
                    f"{room.name}: {obj['instance']} is turned {turn:.3f} rad from its table"
                printer_turns.add(round(quarters) % 4)
    assert yumis > 100
    assert len(printer_turns) >= 2, printer_turns  # turned printers do occur


def side_by_side(objects: list[dict]) -> Iterator[tuple[int, int, float]]:
    """``(i, j, plan distance)`` of every pair of objects whose heights overlap and neither
    of which stands on the other: the pairs the clearance rule applies to."""
    quads = [footprint(obj) for obj in objects]
    for i, a in enumerate(objects):
        for j in range(i + 1, len(objects)):
            b = objects[j]
            if a['on'] == b['instance'] or b['on'] == a['instance']:
                continue
            (a0, a1), (b0, b1) = z_range(a), z_range(b)
            if a1 <= b0 + TOL or b1 <= a0 + TOL:
                continue  # one above the other
            yield i, j, quad_distance(quads[i], quads[j])


def test_objects_keep_the_clearance_apart(rooms):
    """docs: no two objects intersect, and every placement keeps ``layout.clearance`` (5 cm)
    from the others (an item and the table it stands on excepted). Clutter may touch; that it
    never enters another box is tested in tests/test_generator/test_generator_clutter.py."""
    closest = np.inf
    for room in rooms:
        clearance = room.config['layout']['clearance']
        objects = room.objects(*GENERATED_CLASSES)
        for i, j, distance in side_by_side(objects):
            pair = f"{objects[i]['instance']} and {objects[j]['instance']}"
            assert distance >= clearance - TOL, f'{room.name}: {pair} are {distance:.4f} m apart'
            closest = min(closest, distance)
    assert closest < 0.1  # the rule binds: some objects stand close to each other


def test_door_swings_stay_free(rooms):
    """docs: the space in front of a door is kept free (checked 0.9 m deep over the door)."""
    doors = 0
    for room in rooms:
        sides = walls(room.polygon)
        for opening in room.meta['room']['openings']:
            if opening['kind'] != 'door':
                continue
            start, direction, _, normal = sides[opening['wall']]
            u0, u1 = opening['u']
            swing = np.array([
                start + direction * u0, start + direction * u1,
                start + direction * u1 + normal * 0.9, start + direction * u0 + normal * 0.9
            ])
            if np.cross(swing[1] - swing[0], swing[2] - swing[1]) < 0:
                swing = swing[::-1]  # counter-clockwise
            for obj in room.objects():
                if z_range(obj)[0] < opening['z'][1]:
                    assert quad_distance(footprint(obj), swing) > 0, \
                        f"{room.name}: {obj['instance']} blocks {opening['instance']}"
            doors += 1
    assert doors >= len(rooms)


def test_objects_stay_below_the_sensor(rooms):
    """docs: objects stay 10 cm below the sensor height (2/3 of the room height) and below the
    ceiling; in the low rooms this limit drops items that would be too tall on their table.
    Only pipe runs may hang over the sensor: 10 cm above it or more, under the ceiling."""
    near_limit = overhead = 0
    for room in rooms:
        height = room.meta['room']['height']
        sensor = room.config['scanner']['sensor_height'] * height
        limit = min(height - 0.05, sensor - 0.1)
        for obj in room.objects():
            bottom, top = z_range(obj)
            if obj['class'] == 'clutter' and obj['params']['kind'] == 'pipe' and top > limit:
                assert bottom >= sensor + 0.1 - TOL and top <= height + TOL, obj['instance']
                overhead += 1
                continue
            assert top <= limit + TOL, f"{room.name}: {obj['instance']} reaches {top:.3f} m"
            near_limit += top > limit - 0.15
    assert near_limit > 0 and overhead > 0  # the limit binds somewhere; pipes hang over it


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
        'layout': {
            'free_side_crate': 1.5
        }
    }, 'free_side_crate" = 1.5 is outside'),
    ({
        'scanner': {
            'glass_transmission': -0.1
        }
    }, 'glass_transmission" = -0.1 is outside'),
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
            'color': 'red'
        }
    }, 'unknown key "room.color"'),
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
