# Experiment 2 at CPU scale: the same data, classes, model and optimiser as exp2.py, shrunk so
# that training on 2 x 50 generated rooms (areas 7, 8; test area 9) runs on 2 CPU cores
# (`make exp2-cpu`, resumable; about 2 hours in 2 processes). Differences from exp2.py (all
# others, e.g. validation after each epoch, are unchanged):
# - voxels of 2 cm instead of 1 cm (model.voxel_size; TR3D's output levels become 32 and 64 cm);
# - a third, finest head level of 16 cm (TR3D's finest at 1 cm) on the first backbone stage's
#   own voxels (`TR3DNeck(backbone_fine_level=True)`, not in TR3D) for the 3D printers, and the
#   sofas on the 32 cm level: label2level (2, 1, 1, 1, 0) for table, chair, sofa, yumi, printer
#   (exp2.py: (1, 0, 1, 0, 0)). On 32 and 64 cm levels the small printers and the backless
#   benches were predicted at their class's mean size (docs/results.md);
# - 40,000 sampled points per room instead of 100,000, in training and testing;
# - the robustness augmentations of the base config (`robust_augmentations`: quarter turns,
#   density falloff and point dropout, 5 mm jitter, colour jitter and colour-less rooms) in
#   training, so that real scans (other colours, sparser and partial) look less foreign;
# - before the sampling, `ThinRoomStructure` keeps 10 % of the floor, wall and ceiling points,
#   in training and testing (on a laser-scanned room 90 % of the points lie on the structure, so
#   40,000 sampled points left its objects a median of 71 points; thinned, 519:
#   benchmarks/bench_structure_thinning.py);
# - the training areas are repeated 5 times per epoch instead of 13, for 12 epochs instead of 5:
#   TR3D's published 1x schedule, the learning rate dropping 10x after epochs 8 and 11 (exp2.py
#   stops at 5, before the first drop). 12 epochs x 125 iterations of batch 4 show the model
#   6,000 room samples (exp2.py: 6,500). The 5-epoch schedule of 2,500 samples met the target on
#   the paper-style data but not on the default mix of sensors (docs/results.md);
# - batch 4 instead of 16, 1 loader worker instead of 8; the learning rate is unchanged;
# - log every 10 iterations instead of 50;
# - no best-epoch checkpoint: the final epoch is the model that is tested. Area 9 is both the
#   validation and the test set, so keeping the best validation epoch would pick it on the test
#   set; the run at 946e69b kept epoch 3 by mAP@0.25 (0.999, as at epoch 5) although its
#   mAP@0.5 was 0.896 against 0.988 after the learning-rate drop (docs/results.md).
# Nothing here selects a device: the Runner uses a GPU when there is one.
# Cost measured on generated 1M-point rooms (2 processes of 1 OpenMP thread, 2 rooms each, a
# 2-core machine): 4.2 s per training iteration of 4 rooms on average, 0.6 s per test room.
_base_ = ['./exp2.py']
from projects.synthdet.config_helpers import area_datasets, with_num_points  # noqa: E402
from projects.synthdet.config_helpers import with_robustness  # noqa: E402
from projects.synthdet.config_helpers import with_structure_thinning  # noqa: E402
from projects.synthdet.config_helpers import with_test_time_augmentation  # noqa: E402

num_points = 40000
voxel_size = 0.02
model = dict(
    voxel_size=voxel_size,
    neck=dict(backbone_fine_level=True),
    bbox_head=dict(label2level=(2, 1, 1, 1, 0)))

train_pipeline, test_pipeline = (
    with_structure_thinning(
        with_num_points(pipeline, num_points), dict(type='ThinRoomStructure', keep=0.1))
    for pipeline in (_base_.train_pipeline, _base_.test_pipeline))
train_pipeline = with_robustness(train_pipeline, _base_.robust_augmentations)
tta_pipeline = with_test_time_augmentation(test_pipeline)
train_dataloader = dict(
    batch_size=4,
    num_workers=1,
    dataset=dict(
        times=5,
        dataset=dict(
            datasets=area_datasets(
                dict(_base_.train_area_dataset, pipeline=train_pipeline), _base_.train_area,
                _base_.metainfo))))
val_dataloader = dict(dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader

train_cfg = dict(max_epochs=12)
param_scheduler = dict(
    type='MultiStepLR', begin=0, end=12, by_epoch=True, milestones=[8, 11], gamma=0.1)

default_hooks = dict(logger=dict(interval=10), checkpoint=dict(save_best=None, rule=None))
