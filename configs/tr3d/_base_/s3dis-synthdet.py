# S3DIS-format data for TR3D: real areas 1-6 and generated areas 7-9, converted to info pickles
# by tools/create_data.py (data/s3dis/s3dis_infos_Area_N.pkl). The pipelines are TR3D's
# published S3DIS ones: 100,000 sampled points, RGB, random flips, +-5 % scaling and 0.1 m
# translation jitter, no rotation (the boxes are axis-aligned). The test pipeline is the flat
# equivalent of mmdet3d's single-scale, no-flip MultiScaleFlipAug3D.
# Experiments pick the areas and classes: they fill `train_dataloader.dataset.dataset.datasets`
# with `area_datasets(_base_.train_area_dataset, train_area, metainfo)` (one dataset per training
# area, projects/synthdet/config_helpers.py) and set the test area's ann_file and metainfo in
# val/test_dataloader. Configs that sample another number of points derive the pipelines with
# `with_num_points(_base_.train_pipeline, n)`.
_base_ = ['mmdet3d::_base_/datasets/s3dis-3d.py']
from projects.synthdet.config_helpers import with_test_time_augmentation  # noqa: E402

dataset_type = 'SynthdetS3DISDataset'
data_root = 'data/s3dis/'
num_points = 100000

load_points = dict(
    type='LoadPointsFromFile',
    coord_type='DEPTH',
    shift_height=False,
    use_color=True,
    load_dim=6,
    use_dim=[0, 1, 2, 3, 4, 5])

train_pipeline = [
    load_points,
    dict(type='LoadAnnotations3D', with_bbox_3d=True, with_label_3d=True),
    dict(type='PointSample', num_points=num_points),
    dict(
        type='RandomFlip3D',
        sync_2d=False,
        flip_ratio_bev_horizontal=0.5,
        flip_ratio_bev_vertical=0.5),
    dict(
        type='GlobalRotScaleTrans',
        rot_range=[0, 0],
        scale_ratio_range=[0.95, 1.05],
        translation_std=[0.1, 0.1, 0.1],
        shift_height=False),
    dict(type='NormalizePointsColor', color_mean=None),
    dict(type='Pack3DDetInputs', keys=['points', 'gt_bboxes_3d', 'gt_labels_3d'])
]
test_pipeline = [
    load_points,
    dict(type='PointSample', num_points=num_points),
    dict(type='NormalizePointsColor', color_mean=None),
    dict(type='Pack3DDetInputs', keys=['points'])
]
# `tools/test.py --tta` (tta_model in tr3d.py); every config that changes the test pipeline
# derives this from its own.
tta_pipeline = with_test_time_augmentation(test_pipeline)

# Augmentations that make real scans look less foreign (other colors, sparser, partial), off
# here: a config inserts them after PointSample with `with_robustness(_base_.train_pipeline,
# _base_.robust_augmentations)`. docs/training.md, "Robustness augmentations", explains them.
robust_augmentations = [
    dict(type='RandomQuarterTurn', prob=0.75),
    dict(
        type='RandomDensityFalloff',
        prob=0.3,
        full_density_range=2.0,
        power=2.0,
        min_keep=0.1,
        sensor_height=(1.0, 1.8),
        min_points=2000),
    dict(type='RandomPointDropout', prob=0.3, ratio_range=(0.1, 0.5), min_points=2000),
    dict(type='RandomJitterPoints', jitter_std=[0.005, 0.005, 0.005], clip_range=[-0.015, 0.015]),
    dict(type='RandomColorJitter', prob=0.8, brightness=20.0, contrast=0.2, channel_gain=0.1),
    dict(type='RandomDropPointsColor', drop_ratio=0.2),
]

# One training area; experiments add `ann_file` and `metainfo`.
train_area_dataset = dict(
    type=dataset_type,
    data_root=data_root,
    pipeline=train_pipeline,
    filter_empty_gt=False,
    box_type_3d='Depth')

# TR3D's S3DIS loader: batch 16, the concatenated training areas repeated 13 times per epoch.
train_dataloader = dict(
    batch_size=16,
    num_workers=8,
    persistent_workers=True,
    sampler=dict(type='DefaultSampler', shuffle=True),
    dataset=dict(type='RepeatDataset', times=13, dataset=dict(type='ConcatDataset', datasets=[])))
val_dataloader = dict(dataset=dict(type=dataset_type, data_root=data_root, pipeline=test_pipeline))
test_dataloader = val_dataloader
# mmdet3d's IndoorMetric, except that classes without ground truth in the test area are left
# out (the paper's "-"; otherwise their NaN AP makes mAP NaN and no best epoch is kept).
val_evaluator = dict(type='SynthdetIndoorMetric')
test_evaluator = val_evaluator

# Whole-hall detection (tools/predict.py, tools/scan2cad.py): a scan larger than a window is cut
# into overlapping square windows, each sampled like a training room, and the detections merged.
# The rule of projects/synthdet/inference/windows.py applied to the generator's default rooms
# (6-11 m x 5-9 m: median floor area 59 m^2 -> 8.0 m) and to the largest object of its library
# (a 3-seat sofa, 2.54 m footprint diagonal -> 2.6 m overlap).
inference_window = dict(size=8.0, overlap=2.6)
# The trained point density (points per m^2 of floor) is the test pipeline's sampled points
# over this median training floor area (density_from_config in windows.py); tools/predict.py and
# tools/scan2cad.py resample denser scans down to it.
inference_density = dict(floor_area=59.0)
# One box for an object detected as several overlapping boxes of its class (an L-shaped sofa as
# three sofas), among the detections a user gets (projects/synthdet/inference/fragments.py): a
# box overlapping a higher-scoring one by 30 % of the smaller one's volume is merged into it.
# Tables and sofas only: chairs stand close together.
fragment_merge = dict(classes=('table', 'sofa'), min_share=0.3)
