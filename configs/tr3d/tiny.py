# Tiny TR3D for the tests (tests/test_models/test_tr3d_overfit.py,
# tests/test_tools/test_tr3d_tools.py): exp2.py's model and classes, made to learn a few rooms of
# area 1 by heart on one CPU core (set the datasets' data_root with --cfg-options): trained and
# tested on the same rooms, 2 cm voxels, 10,000 sampled points, no augmentation, batch 1, a
# constant learning rate for 24 epochs.
_base_ = ['./exp2.py']
from projects.synthdet.config_helpers import area_datasets, area_info_file  # noqa: E402
from projects.synthdet.config_helpers import with_num_points  # noqa: E402
from projects.synthdet.config_helpers import with_test_time_augmentation  # noqa: E402

data_root = 'data/s3dis_tiny/'
train_area = [1]
test_area = 1
num_points = 10000
voxel_size = 0.02
model = dict(voxel_size=voxel_size)

train_pipeline = [
    step for step in with_num_points(_base_.train_pipeline, num_points)
    if step['type'] not in ('RandomFlip3D', 'GlobalRotScaleTrans')
]
test_pipeline = with_num_points(_base_.test_pipeline, num_points)
tta_pipeline = with_test_time_augmentation(test_pipeline)
train_dataloader = dict(
    batch_size=1,
    num_workers=0,
    persistent_workers=False,
    dataset=dict(
        times=1,
        dataset=dict(
            datasets=area_datasets(
                dict(_base_.train_area_dataset, data_root=data_root, pipeline=train_pipeline),
                train_area, _base_.metainfo))))
val_dataloader = dict(
    num_workers=0,
    dataset=dict(data_root=data_root, ann_file=area_info_file(test_area), pipeline=test_pipeline))
test_dataloader = val_dataloader

train_cfg = dict(max_epochs=24, val_interval=24)
param_scheduler = []
default_hooks = dict(logger=dict(interval=5), checkpoint=dict(interval=24))
