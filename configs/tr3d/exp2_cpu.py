# Experiment 2 at CPU scale: the same data, classes, model and optimiser as exp2.py, shrunk so
# that training on 2 x 50 generated rooms (areas 7, 8; test area 9) takes about two hours on 2
# CPU cores. Differences from exp2.py (all others, e.g. 5 epochs with validation after each,
# are unchanged):
# - voxels of 2 cm instead of 1 cm (model.voxel_size; TR3D's output levels become 32 and 64 cm);
# - 40,000 sampled points per room instead of 100,000, in training and testing;
# - the training areas are repeated 5 times per epoch instead of 13;
# - batch 4 instead of 16, 1 loader worker instead of 8; the learning rate is unchanged;
# - the learning rate drops 10x for the last epoch (TR3D's step schedule at 1x drops after 8 of
#   12 epochs; exp2.py stops at 5 before its first step);
# - log every 10 iterations instead of 50;
# - no best-epoch checkpoint: the final epoch is the model that is tested. Area 9 is both the
#   validation and the test set, so keeping the best validation epoch would pick it on the test
#   set; the run at 946e69b kept epoch 3 by mAP@0.25 (0.999, as at epoch 5) although its
#   mAP@0.5 was 0.896 against 0.988 after the learning-rate drop (docs/results.md).
# 5 epochs x 125 iterations show the model 2,500 room samples (TR3D's exp2: 6,500). A first
# schedule of 2 repeats and no drop (1,000 samples) left yumi and 3dprinter short of the target
# (docs/results.md).
# Nothing here selects a device: the Runner uses a GPU when there is one.
# Cost measured on generated 1M-point rooms (one OpenMP thread, a busy 2-core machine): about
# 10 CPU-s per training iteration of 4 rooms and 1 CPU-s per test room, 1.7 GB peak memory.
_base_ = ['./exp2.py']
from projects.synthdet.config_helpers import area_datasets, with_num_points  # noqa: E402

num_points = 40000
voxel_size = 0.02
model = dict(voxel_size=voxel_size)

train_pipeline = with_num_points(_base_.train_pipeline, num_points)
test_pipeline = with_num_points(_base_.test_pipeline, num_points)
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

param_scheduler = dict(
    type='MultiStepLR', begin=0, end=5, by_epoch=True, milestones=[4], gamma=0.1)

default_hooks = dict(logger=dict(interval=10), checkpoint=dict(save_best=None, rule=None))
