"""The robustness augmentations (projects/synthdet/datasets/transforms.py) on hand-made scenes
of real DepthPoints and DepthInstance3DBoxes, ``with_robustness`` on the base config's train
pipeline, that pipeline through the registered dataset on a room of the real generator, and one
training iteration of the tiny config with it through tools/train.py."""
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from mmdet3d.registry import DATASETS, TRANSFORMS
from mmdet3d.structures import DepthInstance3DBoxes, DepthPoints
from mmengine.config import Config
from mmengine.dataset import Compose
from mmengine.registry import init_default_scope
from mmengine.runner import set_random_seed

import projects.synthdet.datasets.synthdet_s3dis  # noqa: F401  (registers the transforms)
from generator.__main__ import main as generate
from projects.synthdet.config_helpers import with_robustness, without_robustness
from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.datasets.transforms import (RandomColorJitter, RandomDensityFalloff,
                                                   RandomPointDropout, RandomQuarterTurn,
                                                   ThinRoomStructure, VoxelGridSample)
from tests.s3dis_fixtures import S3DIS_DIR
from tests.tool_process import train_tiny

CONFIGS = Path(__file__).resolve().parents[2] / 'configs' / 'tr3d'
# gravity centre and sizes (S3DIS ground truth: axis-aligned, built with box_dim=6)
BOXES = np.array([[1.3, -0.7, 0.45, 1.2, 0.7, 0.9], [-2.1, 3.4, 0.6, 0.5, 0.65, 1.2],
                  [0.25, 0.35, 1.1, 0.33, 1.9, 0.4]])
ROBUST_TYPES = [
    'RandomQuarterTurn', 'RandomDensityFalloff', 'RandomPointDropout', 'RandomJitterPoints',
    'RandomColorJitter', 'RandomDropPointsColor'
]


def base_config() -> Config:
    return Config.fromfile(CONFIGS / '_base_' / 's3dis-synthdet.py', import_custom_modules=False)


def at_full_strength(steps: list[dict]) -> list[dict]:
    """``steps`` with every probability (``prob``, ``drop_ratio``) set to 1."""
    return [
        dict(step, **{key: 1.0
                      for key in ('prob', 'drop_ratio') if key in step}) for step in steps
    ]


def make_scene(xyz: np.ndarray,
               rgb: np.ndarray,
               boxes: np.ndarray = BOXES,
               with_yaw: bool = False) -> dict:
    """An mmdet3d results dict as LoadPointsFromFile and LoadAnnotations3D leave it."""
    points = DepthPoints(
        torch.tensor(np.column_stack([xyz, rgb]), dtype=torch.float32),
        points_dim=6,
        attribute_dims=dict(color=[3, 4, 5]))
    gt = DepthInstance3DBoxes(
        torch.tensor(boxes, dtype=torch.float32),
        box_dim=boxes.shape[1],
        with_yaw=with_yaw,
        origin=(0.5, 0.5, 0.5))
    return dict(points=points, gt_bboxes_3d=gt, gt_labels_3d=np.arange(len(boxes)))


def box_bounds(boxes: DepthInstance3DBoxes) -> tuple[torch.Tensor, torch.Tensor]:
    """(K, 3) low and high corners of axis-aligned boxes (bottom-centre tensors)."""
    t = boxes.tensor
    half = torch.stack([t[:, 3] / 2, t[:, 4] / 2, torch.zeros_like(t[:, 5])], dim=1)
    top = torch.stack([t[:, 3] / 2, t[:, 4] / 2, t[:, 5]], dim=1)
    return t[:, :3] - half, t[:, :3] + top


def membership(scene: dict) -> torch.Tensor:
    """(N, K): point n lies in box k, faces included."""
    low, high = box_bounds(scene['gt_bboxes_3d'])
    xyz = scene['points'].coord[:, None, :]
    return ((xyz >= low[None]) & (xyz <= high[None])).all(dim=2)


@pytest.fixture
def boxed_scene() -> dict:
    """Points inside each box (the eight corners exactly on its faces, the rest uniform) and
    points outside all of them."""
    rng = np.random.default_rng(0)
    low, high = box_bounds(make_scene(np.zeros((0, 3)), np.zeros((0, 3)))['gt_bboxes_3d'])
    chunks = []
    for lo, hi in zip(low.numpy(), high.numpy()):
        corners = np.array([[hi[i] if (c >> i) & 1 else lo[i] for i in range(3)]
                            for c in range(8)])
        chunks += [corners, lo + rng.random((200, 3)) * (hi - lo)]
    chunks.append(rng.uniform(-5.0, 5.0, (500, 3)))
    xyz = np.concatenate(chunks)
    return make_scene(xyz, rng.integers(0, 256, (len(xyz), 3)))


def uniform_floor(n: int, seed: int = 0, size: float = 12.0) -> dict:
    rng = np.random.default_rng(seed)
    xyz = np.column_stack([rng.uniform(0.0, size, (n, 2)), np.zeros(n)])
    return make_scene(xyz, rng.integers(0, 256, (n, 3)))


@pytest.mark.parametrize('quarters', [1, 2, 3])
def test_quarter_turn_keeps_every_point_in_its_exactly_turned_box(boxed_scene, quarters):
    before = membership(boxed_scene)
    assert before.sum(dim=0).min() >= 208  # every box holds its corners and its points
    boxes = boxed_scene['gt_bboxes_3d'].clone()
    points = boxed_scene['points'].clone()
    RandomQuarterTurn.turn(boxed_scene, quarters)
    turned = boxed_scene['gt_bboxes_3d']
    assert torch.equal(membership(boxed_scene), before)
    # axis-aligned, heights and z untouched, the x and y sizes swapped exactly on odd turns
    assert not turned.with_yaw and torch.equal(turned.tensor[:, 6], boxes.tensor[:, 6])
    assert torch.equal(turned.tensor[:, [2, 5]], boxes.tensor[:, [2, 5]])
    sizes = boxes.tensor[:, [4, 3]] if quarters % 2 else boxes.tensor[:, [3, 4]]
    assert torch.equal(turned.tensor[:, 3:5], sizes)
    # the same turn as mmdet3d's own (float) rotation, which encloses the turned boxes
    angle = quarters * math.pi / 2
    boxes.rotate(angle, points)
    assert torch.allclose(boxed_scene['points'].tensor, points.tensor, atol=1e-5)
    assert torch.allclose(turned.tensor, boxes.tensor, atol=1e-5)


def test_quarter_turn_turns_yaw_boxes_like_mmdet3d():
    boxes = np.column_stack([BOXES, [0.3, -1.0, 2.0]])
    scene = make_scene(np.random.default_rng(1).random((50, 3)), np.zeros((50, 3)), boxes, True)
    reference = make_scene(scene['points'].coord.numpy(), np.zeros((50, 3)), boxes, True)
    RandomQuarterTurn.turn(scene, 3)
    reference['gt_bboxes_3d'].rotate(3 * math.pi / 2, reference['points'])
    assert torch.allclose(
        scene['gt_bboxes_3d'].tensor, reference['gt_bboxes_3d'].tensor, atol=1e-5)
    assert torch.allclose(scene['points'].tensor, reference['points'].tensor, atol=1e-5)


def _turns_drawn(prob: float, draws: int) -> np.ndarray:
    """How many quarter turns ``RandomQuarterTurn(prob)`` made in ``draws`` seeded scenes (a
    marker point at (1, 0) ends at (0, 1), (-1, 0) or (0, -1))."""
    ends = {(1, 0): 0, (0, 1): 1, (-1, 0): 2, (0, -1): 3}
    transform = RandomQuarterTurn(prob=prob)
    np.random.seed(0)
    turns = []
    for _ in range(draws):
        scene = transform(make_scene(np.array([[1.0, 0.0, 0.5]]), np.zeros((1, 3))))
        turns.append(ends[tuple(int(v) for v in scene['points'].coord[0, :2].tolist())])
    return np.bincount(turns, minlength=4)


def test_quarter_turn_probability():
    assert _turns_drawn(0.0, 50).tolist() == [50, 0, 0, 0]
    counts = _turns_drawn(0.75, 800)  # all four orientations equally likely
    assert np.all(np.abs(counts / 800 - 0.25) < 0.05), counts


def _color_jitter(colors: np.ndarray, seed: int = 0, **strengths) -> torch.Tensor:
    """Colors after RandomColorJitter(prob=1, **strengths); the xyz must not change."""
    xyz = np.random.default_rng(seed).random((len(colors), 3))
    scene = make_scene(xyz, colors)
    np.random.seed(seed)
    out = RandomColorJitter(prob=1.0, **strengths)(scene)['points']
    assert torch.equal(out.coord, torch.tensor(xyz, dtype=torch.float32))
    return out.color


def test_color_jitter_clips_to_0_255():
    colors = np.random.default_rng(2).integers(0, 256, (2000, 3))
    jittered = torch.cat([
        _color_jitter(colors, seed, brightness=120.0, contrast=0.9, channel_gain=0.5)
        for seed in range(6)
    ])
    assert jittered.min() == 0 and jittered.max() == 255  # clipping happened, nothing beyond


def test_color_jitter_brightness_contrast_and_gain():
    colors = np.random.default_rng(3).uniform(80, 170, (500, 3))
    original = torch.tensor(colors, dtype=torch.float32)
    shift = _color_jitter(colors, brightness=30.0, contrast=0.0, channel_gain=0.0) - original
    assert torch.allclose(shift, shift[0, 0], atol=1e-4) and 0 < abs(float(shift[0, 0])) <= 30

    stretched = _color_jitter(colors, seed=1, brightness=0.0, contrast=0.2, channel_gain=0.0)
    factor = (stretched - stretched.mean()) / (original - original.mean())
    assert torch.allclose(stretched.mean(), original.mean(), atol=1e-3)
    assert torch.allclose(factor, factor[0, 0], atol=1e-3) and 0.8 <= factor[0, 0] <= 1.2
    assert abs(float(factor[0, 0]) - 1.0) > 1e-3

    gains = _color_jitter(
        colors, seed=2, brightness=0.0, contrast=0.0, channel_gain=0.1) / original
    assert torch.allclose(gains, gains[0], atol=1e-4)
    assert (gains[0] >= 0.9).all() and (gains[0] <= 1.1).all() and gains[0].std() > 1e-3


def test_color_jitter_leaves_scans_without_color_black():
    assert not _color_jitter(np.zeros((100, 3)), brightness=50.0).any()


@pytest.mark.parametrize('drop_ratio', [0.0, 1.0])
def test_color_dropout_gives_zeros_after_normalisation(drop_ratio):
    steps = base_config().robust_augmentations
    [dropout] = [step for step in steps if step.type == 'RandomDropPointsColor']
    pipeline = Compose([
        TRANSFORMS.build(dict(dropout, drop_ratio=drop_ratio)),
        TRANSFORMS.build(dict(type='NormalizePointsColor', color_mean=None))
    ])
    rng = np.random.default_rng(4)
    colors = rng.integers(1, 256, (300, 3))
    out = pipeline(make_scene(rng.random((300, 3)), colors))['points'].color
    expected = np.zeros((300, 3)) if drop_ratio else colors / 255.0
    assert np.allclose(out.numpy(), expected)


def test_point_dropout_keeps_the_share_and_the_masks():
    n = 1000
    scene = uniform_floor(n)
    scene['pts_semantic_mask'] = np.arange(n)
    scene['pts_instance_mask'] = np.arange(n) * 2
    original = scene['points'].tensor.clone()
    out = RandomPointDropout(prob=1.0, ratio_range=(0.3, 0.3), min_points=10)(scene)
    assert len(out['points']) == 700
    rows = out['pts_semantic_mask']
    assert np.all(np.diff(rows) > 0)  # distinct rows in the original order
    assert torch.equal(out['points'].tensor, original[rows])
    assert np.array_equal(out['pts_instance_mask'], rows * 2)


@pytest.mark.parametrize('n, prob, expected', [(1000, 1.0, 500), (300, 1.0, 300),
                                               (1000, 0.0, 1000)])
def test_point_dropout_keeps_at_least_min_points(n, prob, expected):
    out = RandomPointDropout(prob=prob, ratio_range=(0.9, 0.9), min_points=500)(uniform_floor(n))
    assert len(out['points']) == expected


def _kept_share_by_distance(scene: dict, out: dict, edges: list[float]) -> np.ndarray:
    """Share of the points in each distance band from the sensor that were kept."""
    sensor = out['density_sensor_xyz']
    before = np.linalg.norm(scene['points'].coord.numpy() - sensor, axis=1)
    after = np.linalg.norm(out['points'].coord.numpy() - sensor, axis=1)
    return np.histogram(after, edges)[0] / np.histogram(before, edges)[0]


def test_density_falloff_keeps_near_points_more_often_than_far_ones():
    np.random.seed(5)
    transform = RandomDensityFalloff(
        prob=1.0, full_density_range=2.0, power=2.0, min_keep=0.1, sensor_height=(1.0, 1.8))
    scene = uniform_floor(60000)
    original = scene['points'].clone()
    out = transform(scene)
    sensor = out['density_sensor_xyz']
    assert np.all(sensor[:2] >= 0) and np.all(sensor[:2] <= 12) and 1.0 <= sensor[2] <= 1.8
    edges = [0.0, 2.0, 3.0, 4.0, 6.0, 20.0]
    share = _kept_share_by_distance(dict(points=original), out, edges)
    assert share[0] == 1.0  # within full_density_range everything stays
    assert np.all(np.diff(share) < 0), share  # sparser with every band further out
    # the measured shares follow the keep probability (the far band is held at min_keep)
    distance = np.linalg.norm(original.coord.numpy() - sensor, axis=1)
    expected = [
        transform.keep_probability(original.coord.numpy(), sensor)[(distance >= lo)
                                                                   & (distance < hi)].mean()
        for lo, hi in zip(edges[:-1], edges[1:])
    ]
    assert np.allclose(share, expected, atol=0.03), (share, expected)
    assert abs(share[-1] - 0.1) < 0.03


def test_density_falloff_tops_up_to_min_points():
    np.random.seed(6)
    transform = RandomDensityFalloff(
        prob=1.0, full_density_range=0.1, min_keep=0.0, min_points=3000)
    assert len(transform(uniform_floor(20000))['points']) == 3000
    assert len(transform(uniform_floor(2000))['points']) == 2000


def test_augmentations_repeat_under_mmengine_seed():
    pipeline = Compose(
        [TRANSFORMS.build(step) for step in at_full_strength(base_config().robust_augmentations)])

    def run(seed: int) -> torch.Tensor:
        set_random_seed(seed)
        return pipeline(uniform_floor(5000))['points'].tensor

    first = run(3)
    assert torch.equal(first, run(3))
    assert not torch.equal(first, run(4))


def test_every_transform_describes_its_parameters():
    base = base_config()
    assert [step.type for step in base.robust_augmentations] == ROBUST_TYPES
    for step in base.robust_augmentations:
        text = repr(TRANSFORMS.build(step))
        assert text.startswith(f'{step.type}(')
        for key, value in step.items():
            if key != 'type':
                assert f'{key}={value}' in text, (text, key)


def test_invalid_strengths_are_refused():
    with pytest.raises(ValueError, match='prob'):
        RandomQuarterTurn(prob=1.5)
    with pytest.raises(ValueError, match='contrast'):
        RandomColorJitter(contrast=-0.1)
    with pytest.raises(ValueError, match='ratio_range'):
        RandomPointDropout(ratio_range=(0.5, 1.0))
    with pytest.raises(ValueError, match='sensor_height'):
        RandomDensityFalloff(sensor_height=(2.0, 1.0))


def test_with_robustness_inserts_after_point_sample():
    base = Config.fromfile(CONFIGS / 'exp2.py', import_custom_modules=False)
    original = [dict(step) for step in base.train_pipeline]
    robust = with_robustness(base.train_pipeline, base.robust_augmentations)
    types = [step['type'] for step in robust]
    assert types == [
        'LoadPointsFromFile', 'LoadAnnotations3D', 'PointSample', *ROBUST_TYPES, 'RandomFlip3D',
        'GlobalRotScaleTrans', 'NormalizePointsColor', 'Pack3DDetInputs'
    ]
    assert [dict(step) for step in base.train_pipeline] == original  # a copy
    assert robust[3:9] == [dict(step) for step in base.robust_augmentations]
    with pytest.raises(ValueError, match='already has'):
        with_robustness(robust, base.robust_augmentations)
    with pytest.raises(ValueError, match='no PointSample'):
        with_robustness(base.train_pipeline[:2], base.robust_augmentations)
    color_first = [
        base.train_pipeline[0],
        dict(type='NormalizePointsColor', color_mean=None), *base.train_pipeline[1:-2]
    ]
    with pytest.raises(ValueError, match='normalises colors before PointSample'):
        with_robustness(color_first, base.robust_augmentations)


def test_experiment_2_trains_with_robustness_and_the_domain_shift_baseline_without():
    exp2_cpu = Config.fromfile(CONFIGS / 'exp2_cpu.py')
    robust = [step['type'] for step in exp2_cpu.train_pipeline]
    assert robust[robust.index('PointSample') + 1:][:len(ROBUST_TYPES)] == ROBUST_TYPES
    assert not set(ROBUST_TYPES) & {step['type'] for step in exp2_cpu.test_pipeline}
    plain = without_robustness(exp2_cpu.train_pipeline, exp2_cpu.robust_augmentations)
    assert [step['type'] for step in plain] == [t for t in robust if t not in ROBUST_TYPES]
    paper = Config.fromfile(CONFIGS / 'domain_shift_cpu.py')
    assert not paper.robustness
    assert not set(ROBUST_TYPES) & {step['type'] for step in paper.train_pipeline}
    mixed = Config.fromfile(CONFIGS / 'domain_shift_mixed_cpu.py')
    assert set(ROBUST_TYPES) <= {step['type'] for step in mixed.train_pipeline}


@pytest.fixture(scope='module')
def generated_room(tmp_path_factory) -> Path:
    """One room of the real generator (bpy, Embree), converted to info pickles."""
    root = tmp_path_factory.mktemp('robust')
    assert generate([
        '--out',
        str(root / 'raw' / S3DIS_DIR), '--areas', '7', '--rooms-per-area', '1', '--points',
        '50000', '--seed', '3', '--asset-cache',
        str(root / 'assets'), '--quiet'
    ]) == 0
    convert_s3dis(root / 'raw', root / 'data', areas=[7])
    return root / 'data'


def _dataset(data_root: Path, pipeline: list[dict]):
    cfg = Config.fromfile(CONFIGS / 'exp2_cpu.py', import_custom_modules=False)
    init_default_scope('mmdet3d')
    return DATASETS.build(
        dict(
            cfg.train_area_dataset,
            data_root=f'{data_root}/',
            ann_file='s3dis_infos_Area_7.pkl',
            metainfo=cfg.metainfo,
            pipeline=pipeline)), cfg


def _check_sample(sample: dict, num_points: int, n_boxes: int,
                  objects_kept: float = 1.0) -> tuple[torch.Tensor, int]:
    """Sampled points and boxes as training expects them, at least ``objects_kept`` of the
    objects with points in their box; returns the colors and the count."""
    points = sample['inputs']['points']
    assert points.shape[1] == 6 and 2000 <= len(points) <= num_points
    colors = points[:, 3:]
    assert colors.min() >= 0 and colors.max() <= 1
    boxes = sample['data_samples'].gt_instances_3d.bboxes_3d
    assert len(boxes) == n_boxes and not boxes.with_yaw and not boxes.tensor[:, 6].any()
    # objects keep points in their box (2 cm: the xyz jitter is clipped at 1.5 cm)
    low, high = box_bounds(boxes)
    inside = ((points[:, None, :3] >= low[None] - 0.02) &
              (points[:, None, :3] <= high[None] + 0.02)).all(dim=2)
    assert inside.any(dim=0).float().mean() >= objects_kept
    return colors, len(points)


def test_robust_pipeline_runs_on_a_generated_room(generated_room):
    dataset, cfg = _dataset(generated_room, [])
    num_points = 40000
    n_boxes = len(dataset.get_data_info(0)['ann_info']['gt_labels_3d'])
    assert n_boxes > 0
    default, _ = _dataset(generated_room, cfg.train_pipeline)  # exp2_cpu trains with them
    counts = []
    for seed in range(6):
        set_random_seed(seed)
        counts.append(_check_sample(default[0], num_points, n_boxes)[1])
    assert min(counts) < num_points == max(counts)  # some scenes thinned, some not
    # every augmentation applied at full strength
    strong, _ = _dataset(
        generated_room,
        with_robustness(without_robustness(cfg.train_pipeline, cfg.robust_augmentations),
                        at_full_strength(cfg.robust_augmentations)))
    set_random_seed(0)
    # the room is a laser scan of 50,000 points, whose far objects hold a dozen: at full
    # strength the density falloff keeps 10 % of them and the dropout half the rest
    colors, count = _check_sample(strong[0], num_points, n_boxes, objects_kept=0.8)
    assert not colors.any() and count < 0.9 * num_points


@pytest.mark.slow
def test_one_training_iteration_of_the_tiny_config_with_robustness(generated_room, tmp_path):
    work = tmp_path / 'work'
    [record] = train_tiny(generated_room, 's3dis_infos_Area_7.pkl', work, epochs=1,
                          pipeline=lambda cfg: with_robustness(cfg.train_pipeline,
                                                               cfg.robust_augmentations))
    assert record['iter'] == 1 and math.isfinite(record['loss']) and record['loss'] > 0
    assert (work / 'epoch_1.pth').is_file()


def _room_with_objects(ceiling_points: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 5 x 3 m room: a dense floor, walls, a ceiling of ``ceiling_points`` points, a
    0.4 m high seat denser than the floor, a 1.9 m cabinet 0.2 m from a wall and a table.
    Returns the points and a 0/1 label per point (1 = object)."""
    rng = np.random.default_rng(seed)

    def plane(n, low, high):
        return low + rng.random((n, 3)) * (np.asarray(high) - np.asarray(low))

    structure = [
        plane(30000, [0, 0, -0.005], [6, 5, 0.005]),
        plane(ceiling_points, [0, 0, 2.995], [6, 5, 3.005]),
        plane(6000, [0, 0, 0], [6, 0.01, 3]),
        plane(6000, [0, 4.99, 0], [6, 5, 3]),
        plane(5000, [0, 0, 0], [0.01, 5, 3]),
        plane(5000, [5.99, 0, 0], [6, 5, 3]),
    ]
    objects = [
        plane(40000, [1, 1, 0.39], [3, 2, 0.41]),  # a sofa seat: the fullest slice near the floor
        plane(3000, [4, 4.2, 0.05], [4.6, 4.8, 1.9]),  # a tall cabinet 0.2 m from the wall
        plane(3000, [2, 3, 0.7], [3.2, 3.8, 0.75]),  # a table top
    ]
    xyz = np.concatenate(structure + objects)
    labels = np.repeat([0] * len(structure) + [1] * len(objects),
                       [len(p) for p in structure + objects])
    return xyz, labels


@pytest.mark.parametrize('ceiling_points', [20000, 50])
def test_thin_room_structure_finds_floor_ceiling_and_walls_not_objects(ceiling_points):
    xyz, labels = _room_with_objects(ceiling_points)
    flagged = ThinRoomStructure().structure(xyz)
    assert flagged[labels == 0].mean() > 0.99
    # the seat stays (it is not the floor), the cabinet and the table are not walls, even under
    # a ceiling too sparse to be a plane
    assert flagged[labels == 1].mean() < 0.01


def test_thin_room_structure_keeps_a_share_of_the_structure_and_every_object_point():
    np.random.seed(0)
    xyz, labels = _room_with_objects(20000)
    scene = make_scene(xyz, np.zeros_like(xyz))
    scene['pts_semantic_mask'] = labels
    scene['pts_instance_mask'] = np.arange(len(xyz))
    out = ThinRoomStructure(keep=0.1)(scene)
    rows = out['pts_instance_mask']
    assert np.array_equal(out['pts_semantic_mask'], labels[rows])
    assert torch.equal(out['points'].tensor[:, :3], torch.tensor(xyz, dtype=torch.float32)[rows])
    kept = np.bincount(labels[rows], minlength=2) / np.bincount(labels)
    assert kept[1] > 0.99 and 0.09 < kept[0] < 0.11
    assert len(out['gt_bboxes_3d']) == len(BOXES)  # the boxes are not touched
    with pytest.raises(ValueError, match='keep'):
        ThinRoomStructure(keep=1.5)
    with pytest.raises(ValueError, match='cell'):
        ThinRoomStructure(cell=0.0)


def test_thin_room_structure_cache_gives_the_same_rooms_as_finding_the_structure_anew():
    """``cached_rooms``: a room's structure is found once per file and point count; the thinned
    rooms are the same as without the cache, epoch after epoch, and a room file that now holds
    other points is not given the cached mask."""
    xyz, labels = _room_with_objects(20000)
    cached, fresh = ThinRoomStructure(keep=0.1, cached_rooms=2), ThinRoomStructure(keep=0.1)
    calls = []
    found = cached.structure
    cached.structure = lambda points: calls.append(len(points)) or found(points)

    def room(path, points):
        scene = make_scene(points, np.zeros_like(points))
        scene['lidar_points'] = dict(lidar_path=path)
        return scene

    for epoch in range(3):
        for path in ('a.bin', 'b.bin'):
            np.random.seed(epoch)
            with_cache = cached(room(path, xyz))['points'].tensor
            np.random.seed(epoch)
            assert torch.equal(with_cache, fresh(room(path, xyz))['points'].tensor)
    assert calls == [len(xyz)] * 2  # each room's structure found once
    cached(room('c.bin', xyz))  # beyond cached_rooms: found, not kept
    cached(room('c.bin', xyz))
    assert calls == [len(xyz)] * 4
    cached(room('a.bin', xyz[:-5]))  # the same file with other points
    assert calls[-1] == len(xyz) - 5
    with pytest.raises(ValueError, match='cached_rooms'):
        ThinRoomStructure(cached_rooms=-1)


def test_voxel_grid_sample_keeps_one_random_point_per_cube_with_its_masks():
    rng = np.random.default_rng(3)
    # a dense patch near a sensor (500 points in one 2 cm cube) and 300 points far apart
    dense = np.array([0.101, 0.101, 0.101]) + rng.uniform(0, 0.018, (500, 3))
    sparse = np.column_stack([np.arange(300) * 0.05 + 1.0, np.full(300, 2.01), np.full(300, 0.51)])
    xyz = np.concatenate([dense, sparse])
    grid = VoxelGridSample(voxel_size=0.02)
    assert repr(grid) == 'VoxelGridSample(voxel_size=0.02)'
    kept_dense = set()
    for seed in range(5):
        np.random.seed(seed)
        scene = make_scene(xyz, rng.integers(0, 255, xyz.shape))
        scene['pts_instance_mask'] = np.arange(len(xyz))
        scene['pts_semantic_mask'] = np.arange(len(xyz)) % 7
        out = grid(scene)
        rows = out['pts_instance_mask']
        assert np.all(np.diff(rows) > 0)  # the points keep their order
        assert np.array_equal(out['pts_semantic_mask'], rows % 7)
        xyz_kept = torch.tensor(xyz, dtype=torch.float32)[rows]
        assert torch.equal(out['points'].tensor[:, :3], xyz_kept)
        assert len(rows) == 301 and np.count_nonzero(rows < 500) == 1
        assert np.array_equal(rows[1:], np.arange(500, 800))  # every point of its own cube stays
        assert len(out['gt_bboxes_3d']) == len(BOXES)
        kept_dense.add(int(rows[0]))
    assert len(kept_dense) > 1  # the kept point of a cube is drawn at random
    with pytest.raises(ValueError, match='voxel_size'):
        VoxelGridSample(voxel_size=0.0)
