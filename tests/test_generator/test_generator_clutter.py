"""Factory clutter (generator/clutter.py and its placement in generator/furnish.py).

Meshes: every kind builds closed solids exactly filling its size. Layouts: seeded rooms with the
default mix and with the heavy-clutter profile, checked from their ``meta.json`` boxes with
geometry computed here: every kind occurs, wall kinds stand with their back to a wall, clutter
touches detection objects but never enters their boxes, crates stand on tables and pallets.
End to end: a scanned room writes its clutter as ``Annotations/clutter_<k>.txt``.
"""
import copy
import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from generator.clutter import (CLUTTER_KINDS, FACTORY_KINDS, WALL_KINDS, clutter_mesh,
                               sample_clutter, sample_pipe_run, sample_primitive)
from generator.config import ConfigError, load_config
from generator.layout import generate_layout, layout_meta
from synthdet.classes import GENERATED_CLASSES
from tests.generator_runs import generate_rooms
from tests.test_generator.test_generator_layout import TOL, footprint, walls, z_range

REPO = Path(__file__).resolve().parents[2]
HEAVY = REPO / 'generator' / 'profiles' / 'clutter.json'


def kind_specs(kind: str, count: int = 40) -> list:
    """Seeded specs of one kind over its variants (pipes on walls and ceilings, small crates)."""
    rng = np.random.default_rng(list(CLUTTER_KINDS).index(kind))
    specs = []
    for i in range(count):
        if kind == 'pipe':
            mount = 'wall' if i % 2 else 'ceiling'
            specs.append(sample_pipe_run(rng, rng.uniform(1.5, 9.0), mount, 1.0))
        elif kind in ('box', 'cylinder'):
            specs.append(sample_primitive(rng, kind, (0.2, 0.8)))
        else:
            specs.append(sample_clutter(rng, kind, rng.uniform(1.3, 2.6), small=i % 3 == 0))
    return specs


@pytest.mark.parametrize('kind', CLUTTER_KINDS)
def test_every_kind_builds_a_closed_mesh_of_its_size(kind):
    for spec in kind_specs(kind):
        assert spec.cls == 'clutter' and spec.params['kind'] == kind
        assert spec.asset == f'clutter/{kind}'
        json.dumps(spec.params)  # written to meta.json as it is
        vertices, triangles, colors = clutter_mesh(spec)
        assert len(triangles) >= 12 and colors.shape == (len(triangles), 3)
        assert colors.dtype == np.uint8
        size = np.asarray(spec.size)
        assert np.all(size > 0.02) and np.all(size < 10.0), (kind, size)
        assert np.allclose(vertices.min(axis=0), [-size[0] / 2, -size[1] / 2, 0], atol=1e-9)
        assert np.allclose(vertices.max(axis=0), [size[0] / 2, size[1] / 2, size[2]], atol=1e-9)
        # closed and consistently wound: every directed edge once, its reverse once
        edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
        directed = Counter(map(tuple, edges))
        assert max(directed.values()) == 1, kind
        assert all((b, a) in directed for a, b in directed), f'{kind}: open mesh'
        a, b, c = (vertices[triangles[:, k]] for k in range(3))
        assert np.linalg.norm(np.cross(b - a, c - a), axis=1).min() > 1e-12, 'flat triangle'
        # outward: the signed volume of closed solids is positive
        assert np.einsum('ij,ij->i', a, np.cross(b, c)).sum() / 6 > 0


@pytest.fixture(scope='module')
def catalog(tmp_path_factory):
    import bpy  # noqa: F401  (before open3d: both ship libtbb and the first one loaded wins)
    from generator.assets import default_library
    from generator.layout import catalog_from_library
    return catalog_from_library(default_library(tmp_path_factory.mktemp('assets')))


def test_confusers_are_sized_like_the_classes(catalog):
    """Low cabinets and shelf carts as high as the tables, small crates as big as printers."""
    tables = np.array([s.size for s in catalog['table']])
    printers = np.array([s.size for s in catalog['3dprinter']])
    low, high = tables[:, 2].min() - 0.05, tables[:, 2].max() + 0.05
    seen = Counter()
    for spec in kind_specs('cabinet', 60) + kind_specs('cart', 60):
        if spec.params['style'] in ('low', 'shelf'):
            assert low <= spec.size[2] <= high, spec
            seen[spec.params['style']] += 1
    lo, hi = printers.min(axis=0) - 0.05, printers.max(axis=0) + 0.05
    rng = np.random.default_rng(1)
    for _ in range(40):
        spec = sample_clutter(rng, 'crate', 1.2, small=True)
        footprint = sorted(spec.size[:2])
        assert lo[:2].min() <= footprint[0] and footprint[1] <= hi[:2].max(), spec.size
        assert lo[2] <= spec.size[2] <= hi[2], spec.size
    assert seen['low'] >= 5 and seen['shelf'] >= 5, seen


def make_rooms(catalog, config: dict, seeds: range) -> list[dict]:
    rooms = []
    for seed in seeds:
        layout = generate_layout(np.random.default_rng([seed, 0]), catalog, config)
        rooms.append({**layout_meta(layout), 'config': config, 'name': f'room {seed}'})
    return rooms


@pytest.fixture(scope='module')
def rooms(catalog) -> list[dict]:
    """60 rooms of the defaults and 30 of the heavy-clutter profile."""
    return (make_rooms(catalog, load_config(), range(60)) +
            make_rooms(catalog, load_config(HEAVY), range(1000, 1030)))


def clutter(room: dict) -> list[dict]:
    return [o for o in room['objects'] if o['class'] == 'clutter']


def test_every_kind_appears_as_clutter(rooms):
    kinds = Counter()
    for room in rooms:
        for obj in clutter(room):
            assert obj['asset'] == f"clutter/{obj['params']['kind']}"
            assert obj['instance'].startswith('clutter_')
            kinds[obj['params']['kind']] += 1
        for obj in room['objects']:
            assert obj['class'] in GENERATED_CLASSES + ('clutter', )
    assert all(kinds[kind] >= 5 for kind in FACTORY_KINDS), kinds
    mounts = Counter(o['params']['mount'] for r in rooms for o in clutter(r)
                     if o['params']['kind'] == 'pipe')
    assert mounts['wall'] >= 5 and mounts['ceiling'] >= 5, mounts


def test_wall_kinds_stand_at_a_wall_with_their_back_to_it(rooms):
    """Shelves, cabinets, machines and wall pipes: front towards the room, back within
    ``layout.wall_gap`` of one wall, along its length; ceiling pipes hang from the ceiling."""
    checked = Counter()
    for room in rooms:
        gap_low, gap_high = room['config']['layout']['wall_gap']
        for obj in clutter(room):
            kind, box = obj['params']['kind'], obj['box']
            if kind == 'pipe' and obj['params']['mount'] == 'ceiling':
                assert z_range(obj)[1] == pytest.approx(room['room']['height'], abs=TOL)
                checked['ceiling pipe'] += 1
                continue
            if kind not in WALL_KINDS and kind != 'pipe':
                continue
            front = np.array([math.sin(box['yaw']), -math.cos(box['yaw'])])
            centre, quad = np.asarray(box['center'][:2]), footprint(obj)
            at = []
            for start, direction, length, normal in walls(np.asarray(room['room']['polygon'])):
                gap = float((centre - start) @ normal) - box['size'][1] / 2
                along = (quad - start) @ direction
                if (front @ normal > 1 - 1e-6 and gap_low - TOL <= gap <= gap_high + TOL
                        and along.min() >= -TOL and along.max() <= length + TOL):
                    at.append(start)
            assert len(at) == 1, f"{room['name']}: {obj['instance']} ({kind}) is not at a wall"
            checked[kind] += 1
    assert all(checked[k] >= 5 for k in WALL_KINDS + ('pipe', 'ceiling pipe')), checked


def penetration(a: dict, b: dict) -> float:
    """How deep the boxes of ``a`` and ``b`` enter each other (0 when apart or touching)."""
    (a0, a1), (b0, b1) = z_range(a), z_range(b)
    depth = min(a1, b1) - max(a0, b0)
    p, q = footprint(a), footprint(b)
    for quad in (p, q):
        for i in range(4):
            edge = quad[(i + 1) % 4] - quad[i]
            axis = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
            depth = min(
                depth,
                min((p @ axis).max(), (q @ axis).max()) - max((p @ axis).min(), (q @ axis).min()))
    return max(depth, 0.0)


def test_clutter_touches_objects_but_never_enters_them(rooms):
    touching = Counter()
    for room in rooms:
        by_name = {o['instance']: o for o in room['objects']}
        for obj in clutter(room):
            for other in room['objects']:
                if other is obj or obj['on'] == other['instance'] or other['on'] == obj['instance']:
                    continue
                depth = penetration(obj, other)
                assert depth <= TOL, (f"{room['name']}: {obj['instance']} enters "
                                      f"{other['instance']} by {depth:.4f} m")
                if other['class'] != 'clutter':  # within 1 cm of it, side by side
                    grown = {**obj['box'], 'size': [s + 0.02 for s in obj['box']['size']]}
                    side_by_side = min(z_range(obj)[1],
                                       z_range(other)[1]) > max(
                                           z_range(obj)[0],
                                           z_range(other)[0])
                    touching[other['class']] += side_by_side and penetration({'box': grown},
                                                                             other) > 0
            if obj['on'] is not None:  # on an empty pallet or a table top, inside it
                support = by_name[obj['on']]
                assert support['class'] == 'table' or support['params']['kind'] == 'pallet'
                assert obj['params']['kind'] == 'crate'
                assert z_range(obj)[0] == pytest.approx(z_range(support)[1], abs=0.011)
                inside = footprint(obj) - np.asarray(support['box']['center'][:2])
                yaw = support['box']['yaw']
                local = inside @ np.array([[math.cos(yaw), -math.sin(yaw)],
                                           [math.sin(yaw), math.cos(yaw)]])
                half = np.asarray(support['box']['size'][:2]) / 2
                assert np.all(np.abs(local) <= half + TOL)
                touching['on ' + support['class']] += 1
    assert touching['table'] >= 10 and touching['chair'] >= 5, touching
    assert touching['on table'] >= 5 and touching['on clutter'] >= 3, touching


def test_heavy_clutter_profile_yields_more_clutter(rooms):
    default = [len(clutter(r)) for r in rooms if r['config']['layout']['clutter'] == [2, 8]]
    heavy = [len(clutter(r)) for r in rooms if r['config']['layout']['clutter'] == [10, 20]]
    assert len(default) == 60 and len(heavy) == 30
    assert np.mean(heavy) > 1.8 * np.mean(default), (np.mean(heavy), np.mean(default))


def test_clutter_does_not_change_the_detection_objects(catalog):
    """Clutter is placed after the detection objects: without it they are the same."""
    config = load_config()
    bare = copy.deepcopy(config)
    bare['layout'].update(clutter=[0, 0], free_side_crate=0.0)
    for seed in range(20):
        full, empty = (
            layout_meta(generate_layout(np.random.default_rng([seed, 0]), catalog, c))
            for c in (config, bare))
        assert [o for o in full['objects'] if o['class'] != 'clutter'] == empty['objects']


def test_free_table_sides_get_printer_sized_crates(catalog):
    """With ``layout.free_side_crate`` 1 and no YuMi or printer, both sides of every table hold
    a crate as big as a printer (where the room above the top allows one); with 0 none."""
    config = load_config()
    config['probabilities'].update(yumi=0.0, **{'3dprinter': 0.0})
    config['layout']['clutter'] = [0, 0]
    on_tables = Counter()
    for share in (0.0, 1.0):
        config['layout']['free_side_crate'] = share
        for room in make_rooms(catalog, copy.deepcopy(config), range(30)):
            tables = {o['instance'] for o in room['objects'] if o['class'] == 'table'}
            crates = [o for o in clutter(room) if o['on'] in tables]
            assert len(crates) == len(clutter(room)), room['name']  # no other clutter
            for crate in crates:
                assert crate['params']['kind'] == 'crate' and crate['params']['layers'] == 1
                assert 0.38 <= min(crate['box']['size'][:2]) and max(crate['box']['size']) <= 0.7
            on_tables[share, 'tables'] += len(tables)
            on_tables[share, 'crates'] += len(crates)
    assert on_tables[0.0, 'crates'] == 0, on_tables
    assert on_tables[1.0, 'crates'] >= 1.5 * on_tables[1.0, 'tables'] > 0, on_tables


@pytest.mark.parametrize('kinds, message', [({
    'crane': 1.0
}, 'unknown clutter kind "crane"'), ({
    'shelf': 0.5
}, 'sum to 0.5'), ({
    'shelf': 1.5
}, 'must be a probability')])
def test_bad_clutter_kinds_are_rejected(tmp_path, kinds, message):
    path = tmp_path / 'bad.json'
    path.write_text(json.dumps({'layout': {'clutter_kinds': kinds}}))
    with pytest.raises(ConfigError, match=message) as err:
        load_config(path)
    assert str(path) in str(err.value)


def test_a_scanned_room_annotates_its_clutter(tmp_path):
    """The heavy profile end to end (real bpy and Embree): every clutter object that received
    points has its ``clutter_<k>`` annotation, inside its box, and is in meta.json."""
    from synthdet.point_text import read_point_file
    out = tmp_path / 'out'
    generate_rooms(out, 7, 1, 30000, 2, '--config', HEAVY, '--asset-cache', tmp_path / 'assets')
    room = out / 'Area_7' / 'factory_1'
    meta = json.loads((room / 'meta.json').read_text())
    objects = {o['instance']: o for o in meta['objects']}
    annotated = sorted(p.stem for p in (room / 'Annotations').glob('clutter_*.txt'))
    assert len(annotated) >= 8
    kinds = set()
    for name in annotated:
        obj = objects[name]
        assert obj['class'] == 'clutter'
        kinds.add(obj['params']['kind'])
        points, _ = read_point_file(room / 'Annotations' / f'{name}.txt')
        box = obj['box']
        c, s = math.cos(box['yaw']), math.sin(box['yaw'])
        local = (points[:, :2] - box['center'][:2]) @ np.array([[c, -s], [s, c]])
        assert np.all(np.abs(local) <= np.asarray(box['size'][:2]) / 2 + 2e-3), name
        assert np.all(np.abs(points[:, 2] - box['center'][2]) <= box['size'][2] / 2 + 2e-3)
    assert len(kinds) >= 4, kinds
