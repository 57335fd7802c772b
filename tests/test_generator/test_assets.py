"""Tests of the procedural asset library (generator/assets) with real bpy and real .blend files."""
import hashlib
import itertools
import json
import math
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from generator.assets import (ASSET_CLASSES, AssetLibrary, build_library, default_library,
                              load_library)
from generator.assets import chair, palette, printer3d, sofa, table, yumi
from generator.assets.library import instance_from_params, procedural_params
from tests.tool_process import run_tool

REPO = Path(__file__).resolve().parents[2]
MODULES = {'table': table, 'chair': chair, 'sofa': sofa, 'yumi': yumi, '3dprinter': printer3d}
# plausible bounding boxes in metres: (min x, max x), (min y, max y), (min z, max z)
SIZE_RANGES = {
    'table': ((1.2, 2.5), (0.70, 1.55), (0.70, 1.06)),  # standing desks up to 1.05 m
    'chair': ((0.33, 0.75), (0.33, 0.75), (0.55, 1.35)),  # stools from 0.55 m
    'sofa': ((0.55, 2.60), (0.45, 1.75), (0.42, 1.00)),  # benches 0.45 deep, chaises 1.7
    'yumi': ((0.39, 1.20), (0.39, 1.20), (0.570, 0.92)),
    '3dprinter': ((0.22, 1.00), (0.22, 1.00), (0.34, 1.20)),
}
# distinct variants per class in the default library: at least twice the first library's
# (table 5, chair 3, sofa 3, yumi 1, 3dprinter 4)
MIN_VARIANTS = {'table': 10, 'chair': 6, 'sofa': 6, 'yumi': 2, '3dprinter': 8}
DEFAULT_INSTANCES = 24


def mesh_digest(instance) -> str:
    digest = hashlib.sha256()
    for array in instance.mesh_arrays():
        digest.update(array.tobytes())
    return digest.hexdigest()


@pytest.fixture(scope='module')
def library_dir(tmp_path_factory) -> Path:
    directory = tmp_path_factory.mktemp('library')
    paths = build_library(directory, seed=0)  # the default size, as the generator uses it
    assert sorted(p.name for p in paths) == sorted(f'{c}.blend' for c in ASSET_CLASSES)
    return directory


@pytest.fixture(scope='module')
def library(library_dir) -> AssetLibrary:
    return load_library(library_dir)


def all_instances(library):
    return [inst for cls in library.classes() for inst in library.instances(cls)]


def test_each_class_has_distinct_instances_covering_all_variants(library):
    assert library.classes() == ASSET_CLASSES
    names = [inst.name for inst in all_instances(library)]
    assert len(names) == len(set(names))
    for cls in ASSET_CLASSES:
        instances = library.instances(cls)
        assert len(instances) == DEFAULT_INSTANCES
        assert len(MODULES[cls].VARIANTS) >= MIN_VARIANTS[cls]
        assert len({mesh_digest(inst) for inst in instances}) == len(instances)
        assert all(inst.cls == cls and inst.asset.startswith(cls + '/') for inst in instances)
        variants = {inst.asset.split('/', 1)[1] for inst in instances}
        assert variants == set(MODULES[cls].VARIANTS)
        for inst in instances:
            assert json.loads(json.dumps(inst.params)) == inst.params


def test_sizes_are_realistic(library):
    for cls, ranges in SIZE_RANGES.items():
        for inst in library.instances(cls):
            for axis, (low, high) in enumerate(ranges):
                assert low <= inst.size[axis] <= high, (inst.name, axis, inst.size)


def test_local_frame_size_and_arrays(library):
    for inst in all_instances(library):
        vertices, triangles, colors = inst.mesh_arrays()
        assert vertices.dtype == np.float64 and vertices.shape[1] == 3
        assert triangles.dtype == np.int32 and triangles.shape[1] == 3
        assert colors.dtype == np.uint8 and colors.shape == triangles.shape
        assert triangles.min() == 0 and triangles.max() == len(vertices) - 1
        corners = vertices[triangles].reshape(-1, 3)
        low, high = corners.min(0), corners.max(0)
        assert tuple(high - low) == inst.size
        assert low[2] == 0.0
        assert np.allclose(low[:2], -high[:2], atol=1e-9)
        assert len(np.unique(colors, axis=0)) >= 2, inst.name
        assert inst.mesh_arrays()[0] is vertices  # stored once, not rebuilt per call
        assert not vertices.flags.writeable


def test_meshes_are_closed_solids(library):
    for inst in all_instances(library):
        triangles = inst.mesh_arrays()[1]
        edges = np.sort(
            np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]),
            axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert np.all(counts == 2), inst.name


def test_face_colors_come_from_the_parameters(library):
    for inst in library.instances('chair'):
        found = {tuple(c) for c in inst.mesh_arrays()[2]}
        assert found == {tuple(inst.params['frame_color']), tuple(inst.params['seat_color'])}


def test_table_tops_are_flat_usable_and_highest(library):
    for inst in library.instances('table'):
        assert inst.top_z == inst.size[2]
        assert 0 < inst.top_size[0] <= inst.size[0] and 0 < inst.top_size[1] <= inst.size[1]
        vertices, triangles, _ = inst.mesh_arrays()
        corners = vertices[triangles]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        up = (normals[:, 2] > 0) & np.all(np.isclose(corners[:, :, 2], inst.top_z), axis=1)
        # every point of the usable rectangle (1 cm in from its edge) lies on an upward top face
        gx, gy = np.meshgrid(
            np.linspace(-0.5, 0.5, 9) * (inst.top_size[0] - 0.02),
            np.linspace(-0.5, 0.5, 9) * (inst.top_size[1] - 0.02))
        points = np.stack([gx.ravel(), gy.ravel()], 1)
        a, b, c = (corners[up][:, k, None, :2] for k in range(3))
        cross = [np.cross(q - p, points[None] - p) for p, q in ((a, b), (b, c), (c, a))]
        inside = np.all(np.stack(cross) >= -1e-12, axis=0)
        assert inside.any(axis=0).all(), inst.name
    for inst in all_instances(library):
        if inst.cls != 'table':
            assert inst.top_z is None and inst.top_size is None


def test_yumi_joint_angles_within_limits(library):
    for inst in library.instances('yumi'):
        for side in yumi.SIDES:
            angles = inst.params['joints'][side]
            assert set(angles) == set(yumi.JOINTS)
            for joint, value in angles.items():
                low, high = yumi.JOINT_LIMITS[joint]
                assert low <= value <= high, (inst.name, side, joint, value)
    # the limits are those of the IRB 14000 product specification, in degrees
    assert yumi.JOINT_LIMITS_DEG['j2'] == (-143.5, 43.5)
    assert yumi.JOINT_LIMITS_DEG['j3'] == (-123.5, 80.0)
    assert yumi.JOINT_LIMITS_DEG['j5'] == (-88.0, 138.0)


def test_yumi_joint_angle_moves_the_arm_geometry(library):
    base = library.instances('yumi')[0]
    params = json.loads(json.dumps(base.params))
    variant = base.asset.split('/')[1]
    rebuilt = instance_from_params('yumi', variant, params)
    assert np.array_equal(rebuilt.mesh_arrays()[0], base.mesh_arrays()[0])
    low, high = yumi.JOINT_LIMITS['j4']
    params['joints']['right']['j4'] = float(
        np.clip(params['joints']['right']['j4'] + 0.6, low, high))
    params['joints']['right']['j2'] -= 0.2
    moved = instance_from_params('yumi', variant, params)
    before, after = base.mesh_arrays()[0], moved.mesh_arrays()[0]
    assert before.shape == after.shape
    # undo the re-centring: vertex 0 belongs to the base plate, which is built first
    shift = np.linalg.norm((after - after[0]) - (before - before[0]), axis=1)
    assert (shift > 0.01).sum() > 50  # the right forearm and gripper moved
    assert (shift < 1e-9).sum() > len(before) / 3  # the torso and the left arm did not


def test_yumi_footprint_and_home_height():
    depth, width, _ = yumi.BASE_SIZE
    assert 0.39 <= min(depth, width) and max(depth, width) <= 0.5
    assert yumi.TORSO[-1][0] == pytest.approx(0.571)
    home = {
        side: {
            j: math.radians(v) * (-1 if side == 'left' and j in yumi.MIRRORED else 1)
            for j, v in yumi.REST_DEG.items()
        }
        for side in yumi.SIDES
    }
    assert yumi.pose_is_valid(home)
    tips = [yumi.arm_frames(side, home[side])[-1][:3, 3] for side in yumi.SIDES]
    assert np.allclose(tips[0] * [1, -1, 1], tips[1], atol=2e-3)  # the arms mirror each other


def test_boxes_follow_the_real_product_dimensions(library):
    """The annotation box is the model's real extent: a table is exactly its top and height
    (nothing sticks out), benches and chaise sofas their parameters, box-shaped printers at least
    their frame (plus door, spool or display)."""
    for inst in library.instances('table'):
        p, variant = inst.params, inst.asset.split('/')[1]
        top = (p['diameter'], p['diameter']) if variant == 'round' else (p['width'], p['depth'])
        assert np.allclose(inst.size, (*top, p['height']), atol=1e-5), inst.name
    for inst in library.instances('sofa'):
        p, variant = inst.params, inst.asset.split('/')[1]
        if variant == 'bench':
            expected = (p['seats'] * p['seat_width'], p['depth'], p['seat_height'])
            assert np.allclose(inst.size, expected, atol=1e-5), inst.name
        elif variant == 'chaise':
            assert inst.size[1] == pytest.approx(p['chaise_depth'], abs=1e-5), inst.name
        else:
            assert inst.size[1] == pytest.approx(p['depth'], abs=1e-5), inst.name
    for inst in library.instances('3dprinter'):
        p = inst.params
        if inst.asset.split('/')[1] in ('enclosed', 'largeformat', 'corexy', 'resin', 'boxframe'):
            frame = np.array([p['width'], p['depth'], p['height']])
            assert np.all(np.asarray(inst.size) >= frame - 1e-5), inst.name
        if p.get('door') == 'swung':  # the open door stands out in front by its width
            assert inst.size[1] >= p['depth'] + p['width'] - 0.07, inst.name
    stools = [i for i in library.instances('chair') if i.asset == 'chair/stool']
    for inst in stools:
        if inst.params['backrest'] == 'none':
            assert inst.size[2] == pytest.approx(inst.params['seat_height'], abs=1e-5)


def test_every_variant_and_option_builds_as_a_closed_solid_of_real_size():
    """Other seeds draw the options the default library may miss (door swung open, lid style,
    stool base, chaise side, ...): every instance builds, is closed and has a plausible size."""
    seen: dict[str, set] = {cls: set() for cls in ASSET_CLASSES}
    for seed in (1, 2):
        for cls in ASSET_CLASSES:
            for index in range(DEFAULT_INSTANCES):
                variant, params = procedural_params(cls, index, seed)
                inst = instance_from_params(cls, variant, params)
                triangles = inst.mesh_arrays()[1]
                edges = np.sort(
                    np.concatenate(
                        [triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]),
                    axis=1)
                assert np.all(np.unique(edges, axis=0, return_counts=True)[1] == 2), inst.name
                for axis, (low, high) in enumerate(SIZE_RANGES[cls]):
                    assert low <= inst.size[axis] <= high, (seed, inst.name, axis, inst.size)
                seen[cls].add(
                    (variant,
                     *(str(params.get(key))
                       for key in ('door', 'lid_style', 'stool_base', 'chaise_side', 'pose'))))
    assert {v for v, *_ in seen['3dprinter']} == set(printer3d.VARIANTS)
    assert {door for v, door, *_ in seen['3dprinter'] if v == 'enclosed'} >= {'glass', 'swung'}
    assert {lid for v, _, lid, *_ in seen['3dprinter'] if v == 'resin'} == {'box', 'hinged'}
    assert {base for v, _, _, base, *_ in seen['chair'] if v == 'stool'} == {'star', 'legs'}
    assert {side for v, *_, side, _ in seen['sofa'] if v == 'chaise'} == {'-1', '1'}
    yumi_kinds = {(v, pose) for v, *_, pose in seen['yumi']}
    assert yumi_kinds == set(itertools.product(yumi.VARIANTS, yumi.POSES))


def test_only_glass_doors_have_the_colors_the_scanner_sees_through():
    """Printer doors of glass (closed or swung open) carry a see-through color
    (``scanner.glass_transmission``); displays and every other asset part do not."""
    see_through = np.array(palette.SEE_THROUGH, np.uint8)
    doors = set()
    for seed in (0, 1, 2):
        for cls in ASSET_CLASSES:
            for index in range(DEFAULT_INSTANCES):
                variant, params = procedural_params(cls, index, seed)
                colors = instance_from_params(cls, variant, params).mesh_arrays()[2]
                glass = (colors[:, None] == see_through[None]).all(axis=2).any(axis=1)
                door = params.get('door') if cls == '3dprinter' else None
                assert glass.any() == (door in ('glass', 'swung')), (cls, variant, door)
                if variant in ('enclosed', 'boxframe'):
                    assert (colors == palette.DISPLAY).all(axis=1).any(), variant
                    doors.add(door)
    assert doors >= {'glass', 'swung', 'open', 'none'}


def test_yumi_poses_span_the_joint_ranges_and_mountings(library):
    instances = library.instances('yumi')
    for joint, (low, high) in yumi.JOINT_LIMITS.items():
        values = [inst.params['joints'][side][joint] for inst in instances for side in yumi.SIDES]
        assert max(values) - min(values) >= 0.75 * (high - low), joint
    for inst in instances:
        vertices, triangles, colors = inst.mesh_arrays()
        heights = vertices[triangles][:, :, 2]
        floor = {tuple(c) for c in colors[np.all(heights < 1e-6, axis=1)]}
        body = np.all(colors == inst.params['body_color'], axis=1)
        if inst.asset == 'yumi/irb14000_plate':
            plate_depth, plate_width, thickness = inst.params['plate']
            assert inst.size[0] >= plate_width - 1e-5 and inst.size[1] >= plate_depth - 1e-5
            assert inst.size[2] >= yumi.HEIGHT + thickness - 1e-5
            assert floor == {yumi.PLATE_COLOR}  # the robot stands on its plate
            assert heights[body].min() == pytest.approx(thickness, abs=1e-5)
        else:
            assert inst.asset == 'yumi/irb14000' and 'plate' not in inst.params
            assert floor == {tuple(inst.params['body_color'])}
        if inst.params['pose'] == 'onearm':  # one arm folded at rest, the other working
            rest_like = []
            for side in yumi.SIDES:
                rest = {
                    j: math.radians(v) * (-1 if side == 'left' and j in yumi.MIRRORED else 1)
                    for j, v in yumi.REST_DEG.items()
                }
                offsets = [abs(inst.params['joints'][side][j] - rest[j]) for j in yumi.JOINTS]
                rest_like.append(max(offsets) < math.radians(20))
            assert rest_like.count(True) == 1, inst.name


def test_build_load_round_trip_is_exact(library):
    for inst in all_instances(library):
        index = int(inst.name.rsplit('_', 1)[1])
        variant, params = procedural_params(inst.cls, index, 0)
        assert inst.asset == f'{inst.cls}/{variant}' and inst.params == params
        fresh = instance_from_params(inst.cls, variant, params, inst.name)
        assert fresh == inst
        for a, b in zip(fresh.mesh_arrays(), inst.mesh_arrays()):
            assert a.dtype == b.dtype and np.array_equal(a, b)


def test_same_seed_same_bytes_other_seed_differs(library, tmp_path):
    again = load_library(build_library(tmp_path / 'a', seed=0)[0].parent)
    other = load_library(build_library(tmp_path / 'b', 12, seed=1, classes=['yumi'])[0].parent)
    for cls in ASSET_CLASSES:
        assert ([mesh_digest(i) for i in again.instances(cls)
                 ] == [mesh_digest(i) for i in library.instances(cls)])
    assert other.classes() == ('yumi', )
    assert ({mesh_digest(i)
             for i in other.instances('yumi')
             }.isdisjoint(mesh_digest(i) for i in library.instances('yumi')))


def _user_object(name, verts, faces, materials, collection, material_index=None):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    for material in materials:
        mesh.materials.append(material)
    if material_index is not None:
        mesh.polygons.foreach_set('material_index', material_index)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def _box(lo, hi):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    verts = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1),
             (x1, y1, z1), (x0, y1, z1)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return verts, faces


def _save_user_file(path, cls, build):
    collection = bpy.data.collections.new(cls)
    build(collection)
    bpy.data.libraries.write(str(path), {collection}, fake_user=True)
    for obj in list(collection.objects):
        bpy.data.meshes.remove(obj.data)
    bpy.data.collections.remove(collection)


def test_user_made_blend_without_custom_properties_loads(tmp_path):
    grey = bpy.data.materials.new('user_grey')  # Principled base color: linear 0.214 = sRGB 128
    grey.node_tree.nodes['Principled BSDF'].inputs['Base Color'].default_value = (0.21404114, 1.0,
                                                                                  0.0, 1.0)
    plain = bpy.data.materials.new('user_plain')  # no BSDF node: the viewport color counts
    plain.node_tree.nodes.remove(plain.node_tree.nodes['Principled BSDF'])
    plain.diffuse_color = (0.0, 0.0, 1.0, 1.0)

    def chairs(collection):
        verts, faces = _box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
        obj = _user_object(
            'MyChair', verts, faces, [grey, plain], collection, material_index=[0, 0, 1, 1, 1, 1])
        obj.scale = (0.4, 0.6, 0.9)
        obj.rotation_euler = (0.0, 0.0, math.pi / 2)
        obj.location = (3.0, 4.0, 5.0)

    def tables(collection):
        top_v, top_f = _box((-0.6, -0.3, 0.72), (0.6, 0.3, 0.76))
        leg_v, leg_f = _box((-0.05, -0.05, 0.0), (0.05, 0.05, 0.72))
        faces = top_f + [tuple(i + 8 for i in f) for f in leg_f]
        _user_object('Desk', top_v + leg_v, faces, [], collection)

    _save_user_file(tmp_path / 'chair.blend', 'chair', chairs)
    _save_user_file(tmp_path / 'table.blend', 'table', tables)
    bpy.data.materials.remove(grey)
    bpy.data.materials.remove(plain)
    library = load_library(tmp_path)
    assert library.classes() == ('table', 'chair')
    [user_chair] = library.instances('chair')
    assert user_chair.asset == 'chair/MyChair' and user_chair.params == {}
    assert np.allclose(user_chair.size, (0.6, 0.4, 0.9))  # rotated by 90 degrees, then scaled
    vertices, triangles, colors = user_chair.mesh_arrays()
    assert len(triangles) == 12 and vertices[:, 2].min() == 0.0
    assert {tuple(c) for c in colors} == {(128, 255, 0), (0, 0, 255)}
    [desk] = library.instances('table')
    assert desk.top_z == pytest.approx(0.76)
    assert desk.top_size == pytest.approx((1.2, 0.6))
    assert {tuple(c) for c in desk.mesh_arrays()[2]} == {(128, 128, 128)}  # no material
    with pytest.raises(KeyError, match='sofa'):
        library.instances('sofa')


def test_bad_library_files_get_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match='no asset library file'):
        load_library(tmp_path)
    with pytest.raises(FileNotFoundError, match='does not exist'):
        load_library(tmp_path / 'missing')
    verts, faces = _box((0, 0, 0), (1, 1, 1))
    _save_user_file(tmp_path / 'sofa.blend', 'Sofas',
                    lambda c: _user_object('S', verts, faces, [], c))
    with pytest.raises(ValueError, match=r"sofa\.blend: no collection named 'sofa'"):
        load_library(tmp_path)

    def bad_params(collection):
        _user_object('S', verts, faces, [], collection)['synthdet_params'] = '{not json'

    _save_user_file(tmp_path / 'sofa.blend', 'sofa', bad_params)
    with pytest.raises(ValueError, match="object 'S': synthdet_params is not valid JSON"):
        load_library(tmp_path)
    with pytest.raises(ValueError, match='unknown asset class'):
        build_library(tmp_path / 'x', classes=['robot'])
    with pytest.raises(ValueError, match='instances_per_class'):
        build_library(tmp_path / 'x', instances_per_class=0)


def test_default_library_is_built_once_and_cached(tmp_path, library):
    first = default_library(tmp_path, seed=0)
    [folder] = [p for p in tmp_path.iterdir()]
    stamps = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
    assert sorted(stamps) == sorted(f'{c}.blend' for c in ASSET_CLASSES)
    second = default_library(tmp_path, seed=0)
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} == stamps
    for cls in ASSET_CLASSES:
        assert ([mesh_digest(i)
                 for i in first.instances(cls)] == [mesh_digest(i) for i in second.instances(cls)]
                == [mesh_digest(i) for i in library.instances(cls)])
    default_library(tmp_path, seed=3)
    assert len(list(tmp_path.iterdir())) == 2  # another seed, another cache entry


def test_cli_builds_files_and_previews(tmp_path, library):
    result = run_tool('-m', 'generator.assets', '--out', tmp_path / 'lib', '--instances', '6',
                      '--classes', 'chair', '3dprinter', '--preview', tmp_path / 'png', timeout=300)
    assert sorted(p.name
                  for p in (tmp_path / 'lib').iterdir()) == ['3dprinter.blend', 'chair.blend']
    assert 'chair.blend: 6 instances' in result.stdout
    # another process, same seed: the same first 6 instances, byte for byte
    built = load_library(tmp_path / 'lib')
    for cls in ('chair', '3dprinter'):
        assert ([mesh_digest(i) for i in built.instances(cls)
                 ] == [mesh_digest(i) for i in library.instances(cls) if int(i.name[-2:]) < 6])
    for name in ('chair.png', '3dprinter.png'):
        png = (tmp_path / 'png' / name).read_bytes()
        assert png[:8] == b'\x89PNG\r\n\x1a\n' and len(png) > 20_000
    bad = subprocess.run(
        [sys.executable, '-m', 'generator.assets', '--out',
         str(tmp_path), '--classes', 'robot'],
        cwd=REPO,
        capture_output=True,
        text=True)
    assert bad.returncode == 2 and 'robot' in bad.stderr
