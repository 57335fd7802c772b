# The domain-shift benchmark's paper-profile model (benchmarks/bench_domain_shift.py): exp2.py's
# classes, model and label2level at CPU scale (2 cm voxels, so head levels of 32 and 64 cm;
# 40,000 sampled points; batch 4), trained on one generator profile's rooms and tested on the
# test rooms of every profile. No structure thinning and no robustness augmentations: the
# benchmark refuses kept models whose config changed. The benchmark writes each model's config
# with its own data root and areas; areas 11 and 21 are the paper profile's training and test
# rooms. An iteration schedule (InfiniteSampler; the learning rate drops 10x for the last fifth),
# no validation (every profile is tested with the final checkpoint) and a checkpoint every
# quarter, so a stopped training resumes. domain_shift_mixed_cpu.py overrides what differs.
_base_ = ['./exp2.py']
from projects.synthdet.config_helpers import area_datasets, area_info_file  # noqa: E402
from projects.synthdet.config_helpers import with_num_points  # noqa: E402
from projects.synthdet.config_helpers import with_test_time_augmentation  # noqa: E402

data_root = 'work_dirs/domain_shift/data/'
train_area = [11]
test_area = 21
num_points = 40000
voxel_size = 0.02
max_iters = 200
robustness = False  # read by the benchmark's report
# TR3D's two head levels, 32 and 64 cm (exp2_cpu.py adds a 16 cm one)
model = dict(voxel_size=voxel_size, neck=dict(backbone_fine_level=False))

train_pipeline = with_num_points(_base_.train_pipeline, num_points)
test_pipeline = with_num_points(_base_.test_pipeline, num_points)
tta_pipeline = with_test_time_augmentation(test_pipeline)

train_dataloader = dict(
    batch_size=4,
    num_workers=1,
    sampler=dict(type='InfiniteSampler', shuffle=True),
    dataset=dict(
        times=1,
        dataset=dict(
            datasets=area_datasets(
                dict(
                    _base_.train_area_dataset, data_root=data_root,
                    pipeline=train_pipeline), train_area, _base_.metainfo))))
test_dataloader = dict(
    dataset=dict(data_root=data_root, ann_file=area_info_file(test_area), pipeline=test_pipeline))
val_dataloader = None
val_cfg = None
val_evaluator = None

train_cfg = dict(_delete_=True, type='IterBasedTrainLoop', max_iters=max_iters)
param_scheduler = dict(
    _delete_=True,
    type='MultiStepLR',
    begin=0,
    end=max_iters,
    by_epoch=False,
    milestones=[max_iters * 4 // 5],
    gamma=0.1)
default_hooks = dict(
    logger=dict(interval=10),
    checkpoint=dict(
        by_epoch=False,
        interval=max(1, max_iters // 4),
        max_keep_ckpts=1,
        save_best=None,
        rule=None))
log_processor = dict(by_epoch=False)
