# Experiment 2 at CPU scale (`make exp2-cpu`): the data, classes, model and optimiser of exp2.py,
# shrunk to train on 2 x 50 generated rooms (areas 7, 8; test area 9) on 2 CPU cores.
# Differences from exp2.py:
# - 2 cm voxels instead of 1 cm (TR3D's output levels become 32 and 64 cm);
# - a third head level of 16 cm on the first backbone stage (`backbone_fine_level`, not in TR3D)
#   for the 3D printers, sofas on the 32 cm level: label2level (2, 1, 1, 1, 0) for table, chair,
#   sofa, yumi, printer; on coarser levels small printers came out at their class's mean size;
# - 40,000 sampled points per room instead of 100,000;
# - `ThinRoomStructure` keeps 10 % of the floor, wall and ceiling points before the sampling,
#   so that the objects keep their points (benchmarks/bench_structure_thinning.py);
# - the base config's robustness augmentations in training (quarter turns, density falloff,
#   point dropout, jitter, color jitter, color-less rooms), for real scans' colors and density;
# - TR3D's 1x schedule: 12 epochs of the training areas repeated 5 times, the learning rate
#   dropping 10x after epochs 8 and 11; batch 4, 1 loader worker, log every 10 iterations;
# - the neck keeps the voxels that TR3D's generative upsampling creates only within one voxel
#   of the backbone's own (`generated_reach=1`, not in TR3D): unpruned they fill the room's
#   volume and cost a third of an iteration (benchmarks/bench_train_recipe.py);
# - the training loader finds each room's floor, walls and ceiling once (`cached_rooms`), the
#   10 % it keeps are drawn afresh every time;
# - one validation, after the last epoch; the final epoch is the tested model (no best-epoch
#   checkpoint: area 9 is both the validation and the test set);
# - exp2.py's AdamW in torch's fused implementation (CPU and CUDA): the same update in one pass
#   over the weights, about a third of the time of the loop over them.
# Nothing here selects a device: the Runner uses a GPU when there is one.
_base_ = ['./exp2.py']
from projects.synthdet.config_helpers import area_datasets, with_num_points  # noqa: E402
from projects.synthdet.config_helpers import with_robustness  # noqa: E402
from projects.synthdet.config_helpers import with_structure_thinning  # noqa: E402
from projects.synthdet.config_helpers import with_test_time_augmentation  # noqa: E402

num_points = 40000
voxel_size = 0.02
model = dict(
    voxel_size=voxel_size,
    neck=dict(backbone_fine_level=True, generated_reach=1),
    bbox_head=dict(label2level=(2, 1, 1, 1, 0)))

structure_thinning = dict(type='ThinRoomStructure', keep=0.1)
train_pipeline = with_structure_thinning(
    with_num_points(_base_.train_pipeline, num_points), dict(structure_thinning, cached_rooms=1000))
test_pipeline = with_structure_thinning(
    with_num_points(_base_.test_pipeline, num_points), structure_thinning)
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

train_cfg = dict(max_epochs=12, val_interval=12)
optim_wrapper = dict(optimizer=dict(fused=True))
param_scheduler = dict(
    type='MultiStepLR', begin=0, end=12, by_epoch=True, milestones=[8, 11], gamma=0.1)

default_hooks = dict(logger=dict(interval=10), checkpoint=dict(save_best=None, rule=None))
