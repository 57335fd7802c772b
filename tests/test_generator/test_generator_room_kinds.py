"""Room kinds beyond the factory room (generator/room_kinds.py, generator/household.py).

Meshes: every household kind builds closed solids exactly filling its size. Layouts: seeded rooms
of each kind, checked from their ``meta.json`` boxes with the geometry of
tests/test_generator/test_generator_layout.py: no YuMi or 3D printer, everything inside the room,
nothing intersecting, the furniture of the kind present and where its rules put it. The default
configuration draws no room kind: its layouts are those of the factory rooms before room kinds
existed. End to end: a small office scanned with bpy writes its annotations.
"""
import copy
import hashlib
import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from generator.config import DEFAULTS, ROOM_KINDS, ConfigError, load_config
from generator.household import (FURNITURE_KINDS, HOUSEHOLD_KINDS, household_mesh,
                                 sample_household)
from generator.layout import generate_layout, layout_meta
from synthdet.contracts import ROOM_FORMAT, validate_room
from tests.test_generator.test_generator_layout import (TOL, catalog, footprint,  # noqa
                                                        front, inside_convex, inside_polygon,
                                                        quad_distance, side_by_side, walls,
                                                        z_range)

REPO = Path(__file__).resolve().parents[2]
MIXED = REPO / 'generator' / 'profiles' / 'mixed_rooms.json'
OTHER_KINDS = tuple(kind for kind in ROOM_KINDS if kind != 'factory')
SEEDS = range(40)
# sha256 of the layouts of seeds 0-11 (stream 0) of the default configuration, as generated
# before room kinds existed (asset colors renamed only): the default rooms must not change
DEFAULT_LAYOUTS_SHA256 = 'f2dad3447ca8a0b12ff59e87a75353aced4ca38be844a7f77ceeb95f37e8323e'


def kind_config(kind: str) -> dict:
    config = copy.deepcopy(DEFAULTS)
    config['room_kinds'] = {name: float(name == kind) for name in ROOM_KINDS}
    return config


@pytest.fixture(scope='module')
def rooms_by_kind(catalog):  # noqa: F811  (the module fixture of the layout tests)
    return {
        kind: [layout_meta(generate_layout(np.random.default_rng([seed, 7]), catalog,
                                           kind_config(kind))) for seed in SEEDS]
        for kind in OTHER_KINDS
    }


# ----------------------------------------------------------------------------- meshes


@pytest.mark.parametrize('kind', HOUSEHOLD_KINDS)
def test_every_household_kind_builds_a_closed_mesh_of_its_size(kind):
    rng = np.random.default_rng(HOUSEHOLD_KINDS.index(kind))
    for _ in range(30):
        spec = sample_household(rng, kind, rng.uniform(1.5, 2.4))
        assert spec.cls == FURNITURE_KINDS.get(kind, 'clutter') and spec.params['kind'] == kind
        json.dumps(spec.params)  # written to meta.json as it is
        vertices, triangles, colors = household_mesh(spec)
        assert colors.shape == (len(triangles), 3) and colors.dtype == np.uint8
        size = np.asarray(spec.size)
        assert np.all(size > 0.02) and size[2] <= 2.4 + 1e-9, (kind, size)
        if kind in FURNITURE_KINDS:  # within the largest library sofa: the window overlap
            assert math.hypot(size[0], size[1]) <= 2.54, (kind, size)
        assert np.allclose(vertices.min(axis=0), [-size[0] / 2, -size[1] / 2, 0], atol=1e-9)
        assert np.allclose(vertices.max(axis=0), [size[0] / 2, size[1] / 2, size[2]], atol=1e-9)
        edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
        directed = Counter(map(tuple, edges))
        assert max(directed.values()) == 1, kind
        assert all(directed[(b, a)] == 1 for a, b in directed), f'{kind}: not closed'


# ----------------------------------------------------------------------------- layouts


@pytest.mark.parametrize('kind', OTHER_KINDS)
def test_rooms_of_a_kind_hold_no_yumi_or_printer_and_stay_valid(rooms_by_kind, kind):
    for meta in rooms_by_kind[kind]:
        assert meta['room']['kind'] == kind
        validate_room({'format': ROOM_FORMAT, **meta}, kind)
        classes = Counter(obj['class'] for obj in meta['objects'])
        assert classes['yumi'] == 0 and classes['3dprinter'] == 0, (kind, classes)


@pytest.mark.parametrize('kind', OTHER_KINDS)
def test_objects_stay_inside_the_room_and_apart(rooms_by_kind, kind):
    """Inside the floor polygon; no two boxes overlap (an object and what it stands on
    excepted); detection objects keep the layout clearance among themselves."""
    clearance = DEFAULTS['layout']['clearance']
    for meta in rooms_by_kind[kind]:
        polygon = np.asarray(meta['room']['polygon'])
        objects = meta['objects']
        quads = [footprint(obj) for obj in objects]
        for obj, quad in zip(objects, quads):
            assert all(inside_polygon(corner, polygon) for corner in quad), obj['instance']
        for i, j, distance in side_by_side(objects):
            a, b = objects[i], objects[j]
            detection = 'clutter' not in (a['class'], b['class'])
            assert distance >= (clearance if detection else 0.0) - TOL, (
                f"{kind}: {a['instance']} and {b['instance']} are {distance:.4f} m apart")
            if not detection:  # touching is allowed, entering is not
                assert not inside_convex(quads[i], quads[j]).any()


@pytest.mark.parametrize('kind', OTHER_KINDS)
def test_things_on_a_top_stand_on_it_without_overhanging(rooms_by_kind, kind):
    """An object with ``on`` stands on its support's top and inside its footprint (the boxes of
    tables and of the household supports are their tops)."""
    count = 0
    for meta in rooms_by_kind[kind]:
        by_name = {obj['instance']: obj for obj in meta['objects']}
        for obj in meta['objects']:
            if obj['on'] is None:
                continue
            support = by_name[obj['on']]
            assert abs(z_range(obj)[0] - z_range(support)[1]) < 1e-3, obj['instance']
            quad, top = footprint(obj), footprint(support)
            edges = np.roll(top, -1, axis=0) - top
            rel = quad[:, None, :] - top[None, :, :]
            inside = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0] >= -TOL
            assert inside.all(), f"{kind}: {obj['instance']} overhangs {support['instance']}"
            count += 1
    assert count >= len(SEEDS) / 2


def _kinds(meta: dict) -> Counter:
    return Counter(obj['params']['kind'] for obj in meta['objects'] if 'kind' in obj['params'])


def _share(rooms: list, test) -> float:
    return sum(bool(test(meta)) for meta in rooms) / len(rooms)


def test_offices_have_desks_with_chairs_and_monitors(rooms_by_kind):
    rooms = rooms_by_kind['office']
    assert _share(rooms, lambda m: any(o['class'] == 'table' for o in m['objects'])) >= 0.9
    by_name = {}
    monitors_on_tables = chairs_at_desks = 0
    for meta in rooms:
        by_name = {obj['instance']: obj for obj in meta['objects']}
        for obj in meta['objects']:
            if obj['params'].get('kind') == 'monitor' and obj['on']:
                support = by_name[obj['on']]
                assert support['class'] == 'table'
                # standing on the top: its bottom at the table's top
                assert abs(z_range(obj)[0] - z_range(support)[1]) < 0.01
                monitors_on_tables += 1
        tables = [o for o in meta['objects'] if o['class'] == 'table']
        for chair in (o for o in meta['objects'] if o['class'] == 'chair'):
            center = np.asarray(chair['box']['center'][:2])
            for table in tables:
                to_table = np.asarray(table['box']['center'][:2]) - center
                near = quad_distance(footprint(chair), footprint(table)) < 0.5
                if near and front(chair) @ to_table / np.linalg.norm(to_table) > 0.5:
                    chairs_at_desks += 1  # close to a desk and turned towards it
                    break
    assert monitors_on_tables >= len(rooms) and chairs_at_desks >= len(rooms)


def test_meeting_rooms_have_one_table_with_chairs_around_it(rooms_by_kind):
    surrounded = 0
    for meta in rooms_by_kind['meeting']:
        tables = [o for o in meta['objects'] if o['class'] == 'table']
        assert len(tables) <= 1
        if not tables:
            continue
        chairs = [o for o in meta['objects'] if o['class'] == 'chair'
                  and quad_distance(footprint(o), footprint(tables[0])) < 0.5]
        sides = {int(np.sign(round(float(front(c) @ [1.0, 0.0]), 1))) for c in chairs} | {
            int(np.sign(round(float(front(c) @ [0.0, 1.0]), 1))) for c in chairs}
        surrounded += len(chairs) >= 3 and len(sides) >= 2
    assert surrounded >= 0.7 * len(SEEDS)


def test_living_rooms_have_a_sofa_with_a_coffee_table(rooms_by_kind):
    rooms = rooms_by_kind['living']
    assert _share(rooms, lambda m: any(o['class'] == 'sofa' for o in m['objects'])) >= 0.9
    assert _share(rooms, lambda m: _kinds(m)['coffee_table']) >= 0.7
    assert _share(rooms, lambda m: _kinds(m)['side_table']) >= 0.4
    assert _share(rooms, lambda m: _kinds(m)['tv']) >= 0.3
    assert any(_kinds(m)['corner_sofa'] for m in rooms) and any(_kinds(m)['armchair']
                                                                for m in rooms)


def test_bedrooms_have_a_bed_with_its_head_at_a_wall(rooms_by_kind):
    rooms = rooms_by_kind['bedroom']
    assert _share(rooms, lambda m: _kinds(m)['bed']) >= 0.9
    assert _share(rooms, lambda m: _kinds(m)['nightstand']) >= 0.7
    for meta in rooms:
        polygon = np.asarray(meta['room']['polygon'])
        for bed in (o for o in meta['objects'] if o['params'].get('kind') == 'bed'):
            head = np.asarray(bed['box']['center'][:2]) - front(bed) * bed['box']['size'][1] / 2
            gaps = [abs(float((head - start) @ normal)) for start, _, _, normal in walls(polygon)
                    if float(front(bed) @ normal) > 0.99]
            assert min(gaps) < 0.05, f"{bed['instance']}: head {min(gaps):.3f} m from the wall"


def test_a_library_without_a_class_gets_none_of_it(catalog):  # noqa: F811
    """As in factory rooms, a class the asset library lacks never appears: no household desks,
    coffee tables or end tables without library tables, no corner sofas without sofas."""
    for cls in ('table', 'sofa', 'chair'):
        partial = {name: (specs if name != cls else []) for name, specs in catalog.items()}
        for kind in OTHER_KINDS:
            for seed in range(8):
                layout = generate_layout(np.random.default_rng([seed, 9]), partial,
                                         kind_config(kind))
                assert cls not in {obj.cls for obj in layout.objects}, (cls, kind, seed)


def test_mixed_profile_mixes_the_kinds(catalog):  # noqa: F811
    config = load_config(MIXED)
    kinds = Counter(generate_layout(np.random.default_rng([seed, 3]), catalog, config).kind
                    for seed in range(60))
    assert set(kinds) == {'factory', 'office', 'meeting', 'living', 'bedroom'}
    assert 0.25 <= kinds['factory'] / 60 <= 0.55


def test_default_configuration_draws_no_room_kind(catalog):  # noqa: F811
    """Without ``room_kinds`` the layouts (and hence every file) are those of the factory rooms
    of earlier versions, with no ``room.kind``."""
    config = load_config(None)
    assert 'room_kinds' not in config
    digest = hashlib.sha256()
    for seed in range(12):
        meta = layout_meta(generate_layout(np.random.default_rng([seed, 0]), catalog, config))
        assert 'kind' not in meta['room']
        digest.update(json.dumps(meta, sort_keys=True).encode())
    assert digest.hexdigest() == DEFAULT_LAYOUTS_SHA256


@pytest.mark.parametrize('room_kinds, message', [
    ({'office': 0.5, 'kitchen': 0.5}, 'unknown room kind "kitchen"'),
    ({'office': 0.5, 'factory': 0.4}, '"room_kinds" probabilities sum to 0.9, not 1'),
    ({'office': 1.5}, '"room_kinds.office" must be a probability'),
    (['office'], '"room_kinds" must be a mapping'),
])
def test_bad_room_kinds_are_rejected(tmp_path, room_kinds, message):
    path = tmp_path / 'kinds.json'
    path.write_text(json.dumps({'room_kinds': room_kinds}))
    with pytest.raises(ConfigError, match=message.replace('(', r'\(').replace('.', r'\.')):
        load_config(path)


def test_room_kinds_and_halls_do_not_mix(tmp_path):
    path = tmp_path / 'hall.json'
    path.write_text(json.dumps({'room_kinds': {'office': 1.0}, 'hall': {}}))
    with pytest.raises(ConfigError, match='bays of a hall'):
        load_config(path)


# ----------------------------------------------------------------------------- end to end


def test_an_office_is_generated_and_annotated_end_to_end(tmp_path):
    import bpy  # noqa: F401  (bpy before open3d: both ship libtbb)
    from generator.__main__ import main
    from synthdet.point_text import read_point_file
    config = tmp_path / 'office.json'
    config.write_text(json.dumps({'room_kinds': {'office': 1.0},
                                  'scanner': {'sensors': {'paper': 1.0}}}))
    out = tmp_path / 'out'
    assert main(['--out', str(out), '--areas', '7', '--rooms-per-area', '1', '--points', '8000',
                 '--seed', '2', '--asset-cache', str(tmp_path / 'assets'), '--config',
                 str(config), '--quiet']) == 0
    room = out / 'Area_7' / 'factory_1'
    meta = validate_room(json.loads((room / 'meta.json').read_text()), 'meta.json')
    assert meta['room']['kind'] == 'office'
    assert meta['generator']['config']['room_kinds']['office'] == 1.0
    names = {obj['instance']: obj for obj in meta['objects']}
    assert any(obj['asset'] == 'clutter/monitor' for obj in names.values())
    annotated = 0
    for path in sorted((room / 'Annotations').glob('*.txt')):
        instance = path.stem
        if instance not in names:
            continue  # the room's structure: floor, walls, ...
        points = read_point_file(path)[0][:, :3]
        box = names[instance]['box']
        c, s = math.cos(box['yaw']), math.sin(box['yaw'])
        local = (points[:, :2] - box['center'][:2]) @ np.array([[c, -s], [s, c]])
        half = np.asarray(box['size']) / 2 + 2e-3
        assert np.all(np.abs(local) <= half[:2]), instance
        assert np.all(np.abs(points[:, 2] - box['center'][2]) <= half[2]), instance
        annotated += 1
    classes = {names[p.stem]['class'] for p in (room / 'Annotations').glob('*.txt')
               if p.stem in names}
    assert annotated >= 3 and {'table', 'clutter'} <= classes
    assert not classes & {'yumi', '3dprinter'}
