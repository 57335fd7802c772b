"""SynthdetS3DISDataset through mmdet3d's registry and pipeline, class subsets, ConcatDataset."""
import numpy as np
import pytest
import torch
from mmdet3d.registry import DATASETS
from mmengine.registry import init_default_scope

import projects.synthdet.datasets.synthdet_s3dis  # noqa: F401  (registers SynthdetS3DISDataset)
from synthdet.classes import DETECTION_CLASSES, S3DIS_DETECTION_CLASSES, SEMANTIC_CLASSES
from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from tests.s3dis_fixtures import write_synthetic_area

EXP2_CLASSES = ('table', 'chair', 'sofa', 'yumi', '3dprinter')
NUM_SAMPLED = 1000


def _pipeline() -> list[dict]:
    return [
        dict(
            type='LoadPointsFromFile',
            coord_type='DEPTH',
            shift_height=False,
            use_color=True,
            load_dim=6,
            use_dim=[0, 1, 2, 3, 4, 5]),
        dict(
            type='LoadAnnotations3D',
            with_bbox_3d=True,
            with_label_3d=True,
            with_mask_3d=True,
            with_seg_3d=True),
        dict(type='PointSegClassMapping'),
        dict(type='PointSample', num_points=NUM_SAMPLED),
        dict(
            type='Pack3DDetInputs',
            keys=[
                'points', 'gt_bboxes_3d', 'gt_labels_3d', 'pts_semantic_mask', 'pts_instance_mask'
            ]),
    ]


def _dataset_cfg(root, area: int, classes=None, **kwargs) -> dict:
    cfg = dict(
        type='SynthdetS3DISDataset',
        data_root=str(root),
        ann_file=f's3dis_infos_Area_{area}.pkl',
        data_prefix=dict(
            pts='points', pts_instance_mask='instance_mask', pts_semantic_mask='semantic_mask'),
        pipeline=_pipeline(),
        **kwargs)
    if classes is not None:
        cfg['metainfo'] = dict(classes=classes)
    return cfg


@pytest.fixture(scope='module')
def data_root(tmp_path_factory):
    """Real area 1 with the 5 S3DIS classes, synthetic areas 7 and 8 with all 7 classes."""
    root = tmp_path_factory.mktemp('s3dis')
    truth = {
        1:
        write_synthetic_area(root, 1, 2, seed=1, points_per_object=120,
                             classes=S3DIS_DETECTION_CLASSES),
        7:
        write_synthetic_area(root, 7, 2, seed=7, points_per_object=120, classes=DETECTION_CLASSES),
        8:
        write_synthetic_area(root, 8, 1, seed=8, points_per_object=120, classes=DETECTION_CLASSES)
    }
    convert_s3dis(root, root)
    init_default_scope('mmdet3d')
    return root, truth


def _room_arrays(root, info) -> tuple[np.ndarray, np.ndarray]:
    """Raw points and semantic mask of a room from the converter's files."""
    name = info['lidar_points']['lidar_path'].split('/')[-1]
    points = np.fromfile(root / 'points' / name, dtype=np.float32).reshape(-1, 6)
    semantic = np.fromfile(root / 'semantic_mask' / name, dtype=np.int64)
    return points, semantic


def _expected_boxes(info: dict, classes: tuple[str, ...]) -> list[tuple[int, list[float]]]:
    """The pickle's boxes of the selected classes, relabelled in the subset's order."""
    return [(classes.index(DETECTION_CLASSES[inst['bbox_label_3d']]), inst['bbox_3d'])
            for inst in info['instances'] if DETECTION_CLASSES[inst['bbox_label_3d']] in classes]


@pytest.mark.parametrize('classes', [None, EXP2_CLASSES, ('yumi', 'chair')])
def test_pipeline_labels_boxes_and_masks(data_root, classes):
    root, truth = data_root
    np.random.seed(0)
    dataset = DATASETS.build(_dataset_cfg(root, 7, classes))
    selected = DETECTION_CLASSES if classes is None else classes
    assert dataset.metainfo['classes'] == selected
    assert len(dataset.metainfo['palette']) == len(selected)
    assert len(dataset) == len(truth[7])
    n_checked = 0
    for index in range(len(dataset)):
        info = dataset.get_data_info(index)
        sample = dataset[index]
        points = sample['inputs']['points']
        assert points.shape == (NUM_SAMPLED, 6)
        gt = sample['data_samples'].gt_instances_3d
        boxes = gt.bboxes_3d
        got = sorted(
            zip(gt.labels_3d.tolist(),
                torch.cat([boxes.gravity_center, boxes.dims], dim=1).tolist()))
        expected = sorted(_expected_boxes(info, selected))
        assert [label for label, _ in got] == [label for label, _ in expected]
        assert np.allclose([b for _, b in got], [b for _, b in expected], atol=1e-5)
        n_checked += len(expected)
        # the sampled points are rows of the room, with their masks mapped to the subset
        room_points, room_semantic = _room_arrays(root, info)
        row_of = {row.tobytes(): k for k, row in enumerate(room_points)}
        rows = np.array([row_of[p.numpy().tobytes()] for p in points])
        seg = sample['data_samples'].gt_pts_seg.pts_semantic_mask
        expected_seg = [
            selected.index(SEMANTIC_CLASSES[s])
            if SEMANTIC_CLASSES[s] in selected else len(selected) for s in room_semantic[rows]
        ]
        assert np.array_equal(np.asarray(seg), expected_seg)
    assert n_checked > 0


def test_subset_drops_other_classes(data_root):
    root, truth = data_root
    dataset = DATASETS.build(_dataset_cfg(root, 1, EXP2_CLASSES))
    for index in range(len(dataset)):
        ann = dataset.get_ann_info(index)
        labels = ann['gt_labels_3d']
        assert labels.min() >= 0 and labels.max() < len(EXP2_CLASSES)
        assert len(ann['gt_bboxes_3d']) == len(labels)
    counts = np.bincount(
        np.concatenate([dataset.get_ann_info(i)['gt_labels_3d'] for i in range(len(dataset))]),
        minlength=5)
    written = [
        sum(b['class'] == c for boxes in truth[1].values() for b in boxes) for c in EXP2_CLASSES
    ]
    assert counts.tolist() == written and written[3:] == [0, 0]  # no yumi/printer in area 1


def test_test_mode_keeps_eval_annotations_of_the_subset(data_root):
    root, truth = data_root
    cfg = _dataset_cfg(root, 8, EXP2_CLASSES, test_mode=True)
    cfg['pipeline'] = cfg['pipeline'][:1] + [dict(type='Pack3DDetInputs', keys=['points'])]
    dataset = DATASETS.build(cfg)
    eval_ann = dataset.get_data_info(0)['eval_ann_info']
    written = sorted(
        EXP2_CLASSES.index(b['class']) for b in truth[8]['office_1'] if b['class'] in EXP2_CLASSES)
    assert sorted(eval_ann['gt_labels_3d'].tolist()) == written
    assert dataset[0]['inputs']['points'].shape[1] == 6


def test_concat_dataset_of_areas(data_root):
    root, truth = data_root
    cfg = dict(
        type='ConcatDataset',
        datasets=[_dataset_cfg(root, area, EXP2_CLASSES) for area in (1, 7, 8)])
    dataset = DATASETS.build(cfg)
    assert len(dataset) == sum(len(truth[a]) for a in (1, 7, 8))
    assert dataset.metainfo['classes'] == EXP2_CLASSES
    labels = np.concatenate([
        dataset[i]['data_samples'].gt_instances_3d.labels_3d.numpy() for i in range(len(dataset))
    ])
    written = [
        sum(b['class'] == c for a in (1, 7, 8) for boxes in truth[a].values() for b in boxes)
        for c in EXP2_CLASSES
    ]
    assert np.bincount(labels, minlength=5).tolist() == written


def test_unknown_subset_class_is_rejected(data_root):
    root, _ = data_root
    with pytest.raises(ValueError, match=r"unknown classes \['stairs'\]"):
        DATASETS.build(_dataset_cfg(root, 7, ('chair', 'stairs')))
