"""TR3D model: registry build, parameter count, forward/backward, assigner, losses, prediction."""
import math
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample, DepthInstance3DBoxes
from mmdet3d.utils import register_all_modules
from mmengine.structures import InstanceData

from projects.synthdet.models import TR3DDetector, tr3d_assign
from projects.synthdet.models.tr3d_neck import voxel_keys
from synthdet.classes import IGNORED_REGION_LABEL
from tests.s3dis_fixtures import read_room_scene, write_synthetic_area

REPO = Path(__file__).resolve().parents[2]
CLASSES = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
# Parameters of the published TR3D S3DIS model (5 classes), computed layer by layer from the
# published architecture in docs/tr3d.md; the TR3D paper rounds it to 14.7M.
PUBLISHED_S3DIS_PARAMS = 14_659_787
VOXEL = 0.04  # coarse voxels keep the model tests fast; the architecture is the published one

register_all_modules(init_default_scope=True)


def tr3d_config(num_classes=5, label2level=(1, 0, 1, 1, 0), voxel_size=0.01):
    """The published TR3D S3DIS model as a config dict."""
    return dict(
        type='TR3DDetector',
        voxel_size=voxel_size,
        data_preprocessor=dict(type='Det3DDataPreprocessor'),
        backbone=dict(
            type='TR3DMinkResNet', in_channels=3, depth=34, num_planes=(64, 128, 128, 128)),
        neck=dict(type='TR3DNeck', in_channels=(64, 128, 128, 128), out_channels=128),
        bbox_head=dict(
            type='TR3DHead',
            num_classes=num_classes,
            in_channels=128,
            num_reg_outs=6,
            pts_center_threshold=6,
            label2level=label2level,
            bbox_loss=dict(type='TR3DAxisAlignedIoULoss', mode='diou', reduction='none'),
            cls_loss=dict(type='mmdet.FocalLoss', reduction='none')),
        train_cfg=dict(),
        test_cfg=dict(nms_pre=1000, iou_thr=0.5, score_thr=0.01))


@pytest.fixture(scope='module')
def scenes(tmp_path_factory):
    """Two small generated S3DIS rooms: (N, 6) points with RGB in 0-1, boxes and labels."""
    root = tmp_path_factory.mktemp('s3dis')
    truth = write_synthetic_area(
        root, area=7, n_rooms=2, seed=5, classes=CLASSES, points_per_object=250)
    result = []
    for room, boxes in truth.items():
        points, box_array, labels = read_room_scene(root, 7, room, boxes, CLASSES)
        result.append(dict(points=torch.from_numpy(points), boxes=box_array, labels=labels))
    return result


def make_batch(model, scenes):
    samples = []
    for scene in scenes:
        sample = Det3DDataSample(metainfo=dict(box_type_3d=DepthInstance3DBoxes))
        sample.gt_instances_3d = InstanceData(
            bboxes_3d=DepthInstance3DBoxes(
                torch.tensor(scene['boxes'], dtype=torch.float32),
                box_dim=6,
                with_yaw=False,
                origin=(0.5, 0.5, 0.5)),
            labels_3d=torch.tensor(scene['labels'], dtype=torch.long))
        samples.append(sample)
    data = dict(inputs=dict(points=[s['points'] for s in scenes]), data_samples=samples)
    return model.data_preprocessor(data, training=model.training)


def test_scenes_hold_their_boxes_in_the_shifted_frame(scenes):
    """Each scene starts at the origin, its colors are 0-1 and every true box is tight around
    points of the scene (the fixture's boxes are the written min/max, rounded to 1 mm)."""
    for scene in scenes:
        points = scene['points'].numpy()
        assert np.allclose(points[:, :3].min(axis=0), 0.0)
        assert points[:, 3:].min() >= 0.0 and points[:, 3:].max() <= 1.0
        assert len(scene['boxes']) == len(scene['labels']) > 0
        for centre, size in zip(scene['boxes'][:, :3], scene['boxes'][:, 3:]):
            lo, hi = centre - size / 2, centre + size / 2
            inside = np.all((points[:, :3] >= lo - 1e-3) & (points[:, :3] <= hi + 1e-3), axis=1)
            assert np.allclose(points[inside, :3].min(axis=0), lo, atol=2e-3)
            assert np.allclose(points[inside, :3].max(axis=0), hi, atol=2e-3)


def test_registry_builds_detector_with_published_parameter_count():
    model = MODELS.build(tr3d_config())
    assert isinstance(model, TR3DDetector)
    assert type(model.backbone).__name__ == 'TR3DMinkResNet'
    assert type(model.neck).__name__ == 'TR3DNeck'
    assert type(model.bbox_head).__name__ == 'TR3DHead'
    assert model.bbox_head.voxel_size == 0.01
    assert sum(p.numel() for p in model.parameters()) == PUBLISHED_S3DIS_PARAMS


def test_head_config_errors():
    with pytest.raises(ValueError, match='label2level'):
        MODELS.build(tr3d_config(num_classes=4))
    config = tr3d_config()
    config['bbox_head']['voxel_size'] = 0.02
    with pytest.raises(ValueError, match='voxel_size'):
        MODELS.build(config)


def test_count_params_tool(tmp_path, monkeypatch, capsys):
    config = tmp_path / 'tr3d_s3dis.py'
    config.write_text("custom_imports = dict(imports=['projects.synthdet.models'])\n"
                      f'model = {tr3d_config()!r}\n')
    monkeypatch.setattr(sys, 'argv', ['count_params.py', str(config)])
    with pytest.raises(SystemExit) as exit_info:
        runpy.run_path(str(REPO / 'tools' / 'count_params.py'), run_name='__main__')
    assert exit_info.value.code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1].split() == ['total', str(PUBLISHED_S3DIS_PARAMS)]
    counts = {line.split()[0]: int(line.split()[1]) for line in lines}
    assert counts['backbone'] == 12_002_624 and counts['backbone.layer3'] == 5_328_128
    assert counts['neck'] == 2_655_744 and counts['bbox_head'] == 1_419
    assert counts['bbox_head.conv_cls'] == 128 * 5 + 5


@pytest.mark.parametrize('name, text, message', [
    ('model.txt', 'model = 1\n', 'not a config file'),
    ('broken.py', 'model = dict(\n', 'broken.py:1: not a config file (invalid Python'),
])
def test_count_params_tool_refuses_a_config_in_one_line(tmp_path, monkeypatch, capsys, name,
                                                        text, message):
    config = tmp_path / name
    config.write_text(text)
    monkeypatch.setattr(sys, 'argv', ['count_params.py', str(config)])
    with pytest.raises(SystemExit) as exit_info:
        runpy.run_path(str(REPO / 'tools' / 'count_params.py'), run_name='__main__')
    assert exit_info.value.code == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f'count_params.py: error: {config}') and message in line


def test_forward_backward_reaches_backbone(scenes):
    torch.manual_seed(0)
    model = MODELS.build(tr3d_config(voxel_size=VOXEL))
    model.init_weights()
    model.train()
    losses = model(**make_batch(model, scenes), mode='loss')
    assert set(losses) == {'bbox_loss', 'cls_loss'}
    for value in losses.values():
        assert torch.isfinite(value) and value > 0
    sum(losses.values()).backward()
    for parameter in (model.backbone.conv1.kernel, model.backbone.layer1[0].conv1.kernel,
                      model.neck.up_block_1[0].kernel, model.bbox_head.conv_cls.kernel,
                      model.bbox_head.conv_reg.kernel):
        assert parameter.grad is not None and parameter.grad.abs().sum() > 0


def test_scene_without_objects_gives_finite_losses(scenes):
    model = MODELS.build(tr3d_config(voxel_size=VOXEL)).train()
    empty = dict(scenes[0], boxes=np.zeros((0, 6)), labels=np.zeros(0, dtype=np.int64))
    losses = model(**make_batch(model, [empty]), mode='loss')
    assert losses['bbox_loss'].item() == 0 and losses['bbox_loss'].requires_grad
    assert torch.isfinite(losses['cls_loss']) and losses['cls_loss'] > 0
    sum(losses.values()).backward()
    assert model.backbone.conv1.kernel.grad.abs().sum() > 0


def test_training_steps_reduce_loss(scenes):
    torch.manual_seed(0)
    model = MODELS.build(tr3d_config(voxel_size=VOXEL))
    model.init_weights()
    model.train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-3, weight_decay=1e-4)
    batch = make_batch(model, scenes[:1])
    history = []
    for _ in range(4):
        losses = model(**batch, mode='loss')
        loss = sum(losses.values())
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        history.append(loss.item())
    assert history[-1] < 0.8 * history[0], history


def test_predict_returns_depth_boxes_in_metres(scenes):
    model = MODELS.build(tr3d_config(voxel_size=VOXEL))
    model.init_weights()
    head = model.bbox_head
    with torch.no_grad():  # constant predictions: zero offset, 0.5 m cubes, class 2 certain
        head.conv_reg.kernel.zero_()
        head.conv_reg.bias.copy_(torch.tensor([0, 0, 0] + [math.log(0.5)] * 3))
        head.conv_cls.kernel.zero_()
        head.conv_cls.bias.copy_(torch.tensor([-9.0, -9.0, 9.0, -9.0, -9.0]))
    model.eval()
    with torch.no_grad():
        results = model(**make_batch(model, scenes), mode='predict')
    assert len(results) == 2
    for result, scene in zip(results, scenes):
        pred = result.pred_instances_3d
        assert isinstance(pred.bboxes_3d, DepthInstance3DBoxes)
        assert pred.bboxes_3d.tensor.shape[1] == 7 and not pred.bboxes_3d.with_yaw
        assert len(pred.bboxes_3d) > 0
        assert torch.all(pred.labels_3d == 2)
        assert torch.allclose(pred.scores_3d, torch.sigmoid(torch.tensor(9.0)))
        assert torch.allclose(pred.bboxes_3d.dims, torch.full_like(pred.bboxes_3d.dims, 0.5))
        # centres are head locations: multiples of the level strides (16 and 32 voxels) in metres
        centres = pred.bboxes_3d.gravity_center
        steps = centres / (16 * VOXEL)
        assert torch.allclose(steps, steps.round(), atol=1e-4)
        # the two generative upsamplings add locations up to 32 + 16 voxels outside the scene
        extent = scene['points'][:, :3].max(dim=0).values
        margin = 48 * VOXEL + 1e-4
        assert torch.all(centres >= -margin) and torch.all(centres <= extent + margin)
        # NMS at IoU 0.5 leaves no two boxes with the same footprint overlap above 0.5
        assert len(torch.unique(centres[:, :2], dim=0)) == len(centres)


def test_predict_on_empty_scores_gives_empty_boxes(scenes):
    model = MODELS.build(tr3d_config(voxel_size=VOXEL))
    with torch.no_grad():
        model.bbox_head.conv_cls.bias.fill_(-20.0)
        model.bbox_head.conv_cls.kernel.zero_()
    model.eval()
    with torch.no_grad():
        results = model(**make_batch(model, scenes[:1]), mode='predict')
    pred = results[0].pred_instances_3d
    assert len(pred.bboxes_3d) == 0 and pred.labels_3d.dtype == torch.long


def test_forward_mode_tensor_gives_two_levels(scenes):
    model = MODELS.build(tr3d_config(voxel_size=VOXEL)).eval()
    with torch.no_grad():
        bbox_preds, cls_preds, points = model(**make_batch(model, scenes), mode='tensor')
    assert len(bbox_preds) == len(cls_preds) == len(points) == 2  # levels
    assert all(len(level) == 2 for level in points)  # scenes
    assert cls_preds[0][0].shape[1] == 5 and bbox_preds[0][0].shape[1] == 6
    assert torch.all(bbox_preds[0][0][:, 3:] > 0)  # sizes are exp(log size)
    assert len(points[0][0]) > len(points[1][0])  # the first level is the finer one


def test_backbone_fine_level_sits_on_the_first_stage_voxels(scenes):
    """``TR3DNeck(backbone_fine_level=True)``: a third, finest level on the first backbone
    stage's own voxels (no new locations), trained through its own blocks."""
    torch.manual_seed(0)
    config = tr3d_config(label2level=(2, 1, 1, 1, 0), voxel_size=VOXEL)
    config['neck']['backbone_fine_level'] = True
    model = MODELS.build(config)
    model.init_weights()
    batch = make_batch(model, scenes)
    model.eval()
    with torch.no_grad():
        stages = model.backbone(model.voxelize(batch['inputs']['points']))
        levels = model.neck(stages)
    assert len(levels) == 3
    assert [level.tensor_stride[0] for level in levels] == [
        stages[0].tensor_stride[0], stages[1].tensor_stride[0], stages[2].tensor_stride[0]]
    first = {tuple(c) for c in stages[0].coordinates.tolist()}
    assert {tuple(c) for c in levels[0].coordinates.tolist()} == first
    assert levels[0].features.shape[1] == 128

    model.train()
    losses = model(**make_batch(model, scenes), mode='loss')
    sum(losses.values()).backward()
    for parameter in (model.neck.fine_up.kernel, model.neck.fine_out_block[0].kernel,
                      model.neck.up_block_1[0].kernel):
        assert parameter.grad is not None and parameter.grad.abs().sum() > 0


def test_voxel_keys_match_exactly_the_voxels_within_reach_of_an_anchor_of_their_scene():
    """``voxel_keys``: a query's key is among the anchors' keys exactly when a voxel of its
    scene lies within ``reach`` voxels of ``stride`` in every axis (checked by brute force)."""
    generator = torch.Generator().manual_seed(3)
    stride = 4
    anchors = torch.cat((torch.randint(0, 2, (30, 1), generator=generator),
                         torch.randint(-6, 6, (30, 3), generator=generator) * stride), dim=1)
    queries = torch.cat((torch.randint(0, 2, (400, 1), generator=generator),
                         torch.randint(-9, 9, (400, 3), generator=generator) * stride), dim=1)
    for reach in (0, 1, 2):
        query_keys, anchor_keys = voxel_keys(queries, anchors, reach, stride)
        found = torch.isin(query_keys, anchor_keys)
        gap = (queries[:, None, 1:] - anchors[None, :, 1:]).abs().amax(dim=2) // stride
        same_scene = queries[:, None, 0] == anchors[None, :, 0]
        expected = ((gap <= reach) & same_scene).any(dim=1)
        assert torch.equal(found, expected)
        assert 0 < int(expected.sum()) < len(queries)


def test_generated_reach_keeps_generated_voxels_near_the_backbone_stage(scenes):
    """``TR3DNeck(generated_reach=r)``: the level built on a generative upsampling keeps only
    voxels within ``r`` voxels of its backbone stage's own (0: exactly its own), fewer than
    TR3D's neck keeps, and the model still trains through every block."""
    counts = {}
    for reach in (None, 0, 1):
        torch.manual_seed(0)
        config = tr3d_config(voxel_size=VOXEL)
        config['neck']['generated_reach'] = reach
        model = MODELS.build(config)
        model.init_weights()
        model.eval()
        batch = make_batch(model, scenes)
        with torch.no_grad():
            stages = model.backbone(model.voxelize(batch['inputs']['points']))
            levels = model.neck(stages)
        own = {tuple(c) for c in stages[1].coordinates.tolist()}
        kept = {tuple(c) for c in levels[0].coordinates.tolist()}
        assert own <= kept
        if reach == 0:
            assert kept == own
        counts[reach] = len(kept)
    assert counts[0] < counts[1] < counts[None]
    model.train()
    losses = model(**make_batch(model, scenes), mode='loss')
    sum(losses.values()).backward()
    assert model.neck.up_block_1[0].kernel.grad.abs().sum() > 0
    with pytest.raises(ValueError, match='generated_reach'):
        MODELS.build(dict(tr3d_config()['neck'], generated_reach=-1))


# --- assigner -----------------------------------------------------------------------------


def grid(step, n):
    axis = torch.arange(n, dtype=torch.float32) * step
    return torch.cartesian_prod(axis, axis, axis)


def test_assigner_positives_are_nearest_points_of_the_assigned_level():
    fine, coarse = grid(0.1, 10), grid(0.3, 4)
    centre = torch.tensor([[0.42, 0.47, 0.51]])
    assigned = tr3d_assign([fine, coarse], centre, torch.tensor([0]), label2level=(1, ), top_k=6)
    assert torch.all(assigned[:len(fine)] == -1)  # the wrong level is never positive
    positive = torch.nonzero(assigned[len(fine):] == 0).flatten()
    distances = (coarse - centre).pow(2).sum(dim=1)
    assert sorted(positive.tolist()) == sorted(distances.argsort()[:6].tolist())

    assigned = tr3d_assign([fine, coarse], centre, torch.tensor([0]), label2level=(0, ), top_k=6)
    assert torch.all(assigned[len(fine):] == -1)
    distances = (fine - centre).pow(2).sum(dim=1)
    assert sorted(torch.nonzero(assigned == 0).flatten().tolist()) == \
        sorted(distances.argsort()[:6].tolist())


def test_assigner_label2level_per_class_and_conflicts():
    fine, coarse = grid(0.1, 10), grid(0.3, 4)
    centres = torch.tensor([[0.41, 0.43, 0.37], [0.46, 0.42, 0.39], [0.52, 0.47, 0.56]])
    labels = torch.tensor([0, 0, 1])
    assigned = tr3d_assign([fine, coarse], centres, labels, label2level=(0, 1), top_k=6)
    fine_assigned, coarse_assigned = assigned[:len(fine)], assigned[len(fine):]
    assert set(coarse_assigned.tolist()) == {-1, 2}  # class 1 lives on level 1 only
    assert set(fine_assigned.tolist()) <= {-1, 0, 1}
    assert (coarse_assigned == 2).sum() == 6
    # boxes 0 and 1 compete for the same fine points: each point goes to the nearer centre
    for index in torch.nonzero(fine_assigned >= 0).flatten():
        distances = (centres[:2] - fine[index]).pow(2).sum(dim=1)
        nearest_candidates = [
            b for b in (0, 1) if index in (fine - centres[b]).pow(2).sum(1).argsort()[:6]
        ]
        assert fine_assigned[index].item() == min(nearest_candidates, key=lambda b: distances[b])


def test_assigner_small_level_and_no_boxes():
    fine, coarse = grid(0.1, 4), grid(0.5, 2)
    assigned = tr3d_assign([fine, coarse],
                           torch.tensor([[0.2, 0.2, 0.2]]),
                           torch.tensor([0]),
                           label2level=(1, ),
                           top_k=20)
    assert torch.all(assigned[len(fine):] == 0) and torch.all(assigned[:len(fine)] == -1)
    empty = tr3d_assign([fine, coarse],
                        torch.zeros((0, 3)),
                        torch.zeros(0, dtype=torch.long),
                        label2level=(1, ),
                        top_k=6)
    assert torch.all(empty == -1) and len(empty) == len(fine) + len(coarse)
    with pytest.raises(ValueError, match='label2level'):
        tr3d_assign([fine], torch.zeros((1, 3)), torch.tensor([3]), label2level=(0, ), top_k=6)


def test_head_targets_are_gravity_centres_and_sizes():
    head = MODELS.build(tr3d_config())  # through the detector so voxel_size is set
    head = head.bbox_head
    boxes = DepthInstance3DBoxes(
        torch.tensor([[1.0, 1.0, 0.5, 0.4, 0.6, 1.0]]),
        box_dim=6,
        with_yaw=False,
        origin=(0.5, 0.5, 0.5))
    points = [grid(0.16, 12), grid(0.32, 6)]
    bbox_targets, cls_targets = head.get_targets(points, boxes, torch.tensor([1]))
    positive = cls_targets == 1
    assert positive.sum() == 6 and torch.all(cls_targets[~positive] == 5)
    assert torch.all(positive[len(points[0]):] == False)  # noqa: E712  chair -> level 0
    assert torch.allclose(bbox_targets[positive],
                          torch.tensor([[1.0, 1.0, 0.5, 0.4, 0.6, 1.0]]).expand(6, 6))


# --- losses -------------------------------------------------------------------------------


def test_diou_loss_known_values():
    loss = MODELS.build(dict(type='TR3DAxisAlignedIoULoss', mode='diou', reduction='none'))
    cube = torch.tensor([[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]])
    shifted = torch.tensor([[0.5, 0.0, 0.0, 1.5, 1.0, 1.0]])
    far = torch.tensor([[3.0, 0.0, 0.0, 4.0, 1.0, 1.0]])
    assert loss(cube, cube).item() == pytest.approx(0.0, abs=1e-6)
    # IoU 1/3; centre distance^2 0.25; enclosing diagonal^2 1.5^2 + 1 + 1 = 4.25
    assert loss(shifted, cube).item() == pytest.approx(1 - 1 / 3 + 0.25 / 4.25, abs=1e-5)
    # disjoint: IoU 0, centre distance^2 9, enclosing diagonal^2 16 + 1 + 1
    assert loss(far, cube).item() == pytest.approx(1 + 9 / 18, abs=1e-5)
    iou_loss = MODELS.build(dict(type='TR3DAxisAlignedIoULoss', mode='iou'))
    assert iou_loss(torch.cat((shifted, far)), torch.cat((cube, cube))).item() == \
        pytest.approx((2 / 3 + 1) / 2, abs=1e-5)


def test_diou_loss_gradient_moves_box_towards_target():
    loss = MODELS.build(dict(type='TR3DAxisAlignedIoULoss', mode='diou'))
    pred = torch.tensor([[3.0, 0.0, 0.0, 4.0, 1.0, 1.0]], requires_grad=True)
    loss(pred, torch.tensor([[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]])).backward()
    # translating the box towards the target (-x) lowers the loss, even without overlap
    assert pred.grad[0, 0] + pred.grad[0, 3] > 0


def test_focal_loss_sanity():
    focal = MODELS.build(dict(type='mmdet.FocalLoss', reduction='none'))
    logits = torch.tensor([[0.0, 0.0], [6.0, -6.0], [-6.0, 6.0]])
    values = focal(logits, torch.tensor([0, 0, 0]))
    assert values.shape == (3, 2)
    # p = 0.5 for a positive: alpha * (1 - p)^2 * -log p
    assert values[0, 0].item() == pytest.approx(0.25 * 0.25 * math.log(2), rel=1e-4)
    assert values[1].sum() < 1e-3 < values[2].sum()  # confident right << confident wrong
    background = focal(logits, torch.tensor([2, 2, 2]))  # label == num_classes: negative
    assert background[1, 0] > background[1, 1]


# --- losses pinned on hand-computed cases (numpy, independent of the implementation) -------


def np_sigmoid_focal(logits: np.ndarray, targets: np.ndarray, num_classes: int) -> np.ndarray:
    """Sigmoid focal loss (alpha 0.25, gamma 2) per location and class; target ``num_classes``
    is background."""
    p = 1 / (1 + np.exp(-logits))
    positive = targets[:, None] == np.arange(num_classes)[None, :]
    return np.where(positive, -0.25 * (1 - p)**2 * np.log(p), -0.75 * p**2 * np.log(1 - p))


def np_iou_diou(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IoU and DIoU of (N, 6) corner-form boxes (x1, y1, z1, x2, y2, z2), element-wise."""
    inter = np.prod(
        np.clip(np.minimum(a[:, 3:], b[:, 3:]) - np.maximum(a[:, :3], b[:, :3]), 0, None), axis=1)
    union = np.prod(a[:, 3:] - a[:, :3], axis=1) + np.prod(b[:, 3:] - b[:, :3], axis=1) - inter
    iou = inter / union
    centre_distance2 = np.sum(((a[:, :3] + a[:, 3:]) / 2 - (b[:, :3] + b[:, 3:]) / 2)**2, axis=1)
    diagonal2 = np.sum(
        (np.maximum(a[:, 3:], b[:, 3:]) - np.minimum(a[:, :3], b[:, :3]))**2, axis=1)
    return iou, iou - centre_distance2 / diagonal2


def np_corners(centre_size: np.ndarray) -> np.ndarray:
    return np.concatenate(
        [centre_size[:, :3] - centre_size[:, 3:] / 2, centre_size[:, :3] + centre_size[:, 3:] / 2],
        axis=1)


def test_axis_aligned_iou_loss_reductions_match_numpy():
    """Three box pairs overlapping in all axes, apart, and nested: every reduction, a weight,
    an average factor and the loss weight against numpy."""
    pred = np.array([[0.0, 0.0, 0.0, 1.0, 2.0, 1.0], [2.0, 2.0, 0.0, 3.0, 2.5, 0.5],
                     [0.2, 0.3, 0.1, 0.8, 0.9, 0.7]])
    target = np.array([[0.5, 0.5, 0.2, 1.5, 1.5, 1.2], [0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
                       [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]])
    iou, diou = np_iou_diou(pred, target)
    assert iou[0] == pytest.approx(0.5 * 1.0 * 0.8 / (2.0 + 1.0 - 0.4))  # by hand
    weight = np.array([1.0, 0.5, 2.0])
    as_tensor = torch.tensor
    for mode, overlap in (('iou', iou), ('diou', diou)):
        loss = MODELS.build(
            dict(type='TR3DAxisAlignedIoULoss', mode=mode, reduction='none', loss_weight=2.0))
        p, t = as_tensor(pred, dtype=torch.float32), as_tensor(target, dtype=torch.float32)
        np.testing.assert_allclose(loss(p, t).numpy(), 2 * (1 - overlap), rtol=1e-5)
        np.testing.assert_allclose(
            loss(p, t, reduction_override='mean').item(), 2 * (1 - overlap).mean(), rtol=1e-5)
        np.testing.assert_allclose(
            loss(p, t, reduction_override='sum').item(), 2 * (1 - overlap).sum(), rtol=1e-5)
        np.testing.assert_allclose(
            loss(p, t, weight=as_tensor(weight, dtype=torch.float32),
                 reduction_override='mean').item(),
            2 * ((1 - overlap) * weight).mean(),
            rtol=1e-5)
        np.testing.assert_allclose(
            loss(
                p,
                t,
                weight=as_tensor(weight, dtype=torch.float32),
                avg_factor=4.0,
                reduction_override='mean').item(),
            2 * ((1 - overlap) * weight).sum() / 4.0,
            rtol=1e-5)


# ignored regions (centre, size) per scene: scene 0's covers the negatives at x = 2.0 and 2.5 m
# of level 0 and at 2.0 m of level 1; scene 1's covers a positive of its level 1 (x = 2.0 m)
IGNORED = [[((2.25, 0.0, 0.0), (1.0, 1.0, 1.0))], [((2.0, 0.0, 0.0), (0.4, 1.0, 1.0))]]


@pytest.mark.parametrize('ignored', [[[], []], IGNORED], ids=['plain', 'ignored_regions'])
def test_head_loss_matches_a_hand_computed_batch(ignored):
    """Two scenes on two levels through the real head (MinkowskiEngine 1x1x1 convolutions with
    set weights): the focal loss summed over every location and class and divided by the
    positives of the whole batch, the DIoU loss averaged over all positives of the batch. A
    location in an ignored region (a box labelled ``IGNORED_REGION_LABEL``) has no class loss
    unless it is a positive."""
    import MinkowskiEngine as ME
    voxel = 0.5
    head = MODELS.build(
        dict(
            type='TR3DHead',
            num_classes=2,
            label2level=(0, 1),
            in_channels=1,
            voxel_size=voxel,
            pts_center_threshold=2))
    w_reg = np.array([0.1, -0.05, 0.02, 0.2, -0.1, 0.05])
    b_reg = np.array([0.05, 0.1, -0.1, np.log(0.8), np.log(1.1), 0.0])
    w_cls, b_cls = np.array([0.7, -0.4]), np.array([-2.0, -1.0])
    with torch.no_grad():
        head.conv_reg.kernel.copy_(torch.tensor(w_reg).reshape(head.conv_reg.kernel.shape))
        head.conv_reg.bias.copy_(torch.tensor(b_reg))
        head.conv_cls.kernel.copy_(torch.tensor(w_cls).reshape(head.conv_cls.kernel.shape))
        head.conv_cls.bias.copy_(torch.tensor(b_cls))
    # voxel coordinates (x only, y = z = 0) per scene and level, and the feature of each
    levels = [[[0, 1, 4, 5], [0, 1, 2]], [[0, 4], [0, 4, 8]]]  # [level][scene]
    feature = {0: 1.0, 1: -0.5, 2: 0.25, 4: 2.0, 5: -1.0, 8: 0.5}
    # ground truth (centre, size, label) per scene; class 0 lives on level 0, class 1 on level 1
    truth = [[((0.3, 0.0, 0.0), (1.0, 1.0, 1.0), 0)],
             [((0.9, 0.1, 0.0), (0.6, 0.8, 1.2), 0), ((2.2, 0.0, 0.1), (2.0, 1.0, 1.0), 1)]]
    # the 2 nearest locations of each box's level, worked out by hand (metres along x)
    positives = [{(0, 0.0): 0, (0, 0.5): 0}, {(0, 0.5): 0, (0, 1.0): 0, (1, 2.0): 1, (1, 4.0): 1}]

    inputs = []
    for per_scene in levels:
        coordinates = [[scene, x, 0, 0] for scene, xs in enumerate(per_scene) for x in xs]
        features = [[feature[x]] for xs in per_scene for x in xs]
        inputs.append(
            ME.SparseTensor(
                features=torch.tensor(features, dtype=torch.float32),
                coordinates=torch.tensor(coordinates, dtype=torch.int32)))
    samples = []
    for boxes, regions in zip(truth, ignored):
        rows = [centre + size for centre, size, _ in boxes] + [c + s for c, s in regions]
        sample = Det3DDataSample(metainfo=dict(box_type_3d=DepthInstance3DBoxes))
        sample.gt_instances_3d = InstanceData(
            bboxes_3d=DepthInstance3DBoxes(
                torch.tensor(rows), box_dim=6, with_yaw=False, origin=(0.5, 0.5, 0.5)),
            labels_3d=torch.tensor([label for _, _, label in boxes] +
                                   [IGNORED_REGION_LABEL] * len(regions)))
        samples.append(sample)
    losses = head.loss(inputs, samples)

    focal_sum, box_losses, skipped = 0.0, [], 0
    for scene, boxes in enumerate(truth):
        for level, per_scene in enumerate(levels):
            for x in per_scene[scene]:
                f = feature[x]
                location = np.array([x * voxel, 0.0, 0.0])
                label = positives[scene].get((level, x * voxel), 2)
                if label == 2 and any(
                        np.all(np.abs(location - centre) <= np.array(size) / 2)
                        for centre, size in ignored[scene]):
                    skipped += 1
                    continue
                focal_sum += np_sigmoid_focal((f * w_cls + b_cls)[None], np.array([label]),
                                              2).sum()
                if label == 2:
                    continue
                reg = f * w_reg + b_reg
                pred = np.concatenate([location + reg[:3], np.exp(reg[3:])])
                centre, size, _ = next(box for box in boxes if box[2] == label)
                _, diou = np_iou_diou(
                    np_corners(pred[None]), np_corners(np.array([centre + size])))
                box_losses.append(1 - diou[0])
    assert len(box_losses) == 6
    if ignored == IGNORED:  # the three negatives left out
        assert skipped == 3
    assert losses['cls_loss'].item() == pytest.approx(focal_sum / 6, rel=1e-5)
    assert losses['bbox_loss'].item() == pytest.approx(np.mean(box_losses), rel=1e-5)
