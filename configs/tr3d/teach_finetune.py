# Fine-tuning a synthetic model on the user's corrected rooms (docs/teach.md): exp2_cpu.py's
# model, pipelines and classes, started from its checkpoint, trained on the user's rooms mixed
# with the generated training areas 7 and 8.
# - The user's rooms: `python -m configurator labels` rooms converted by tools/create_data.py
#   into data/s3dis/ beside the generated areas, as area `user_area` (10: the real S3DIS areas
#   are 1-6, the generated ones 7-9), i.e. s3dis_infos_Area_10.pkl. They are
#   repeated `user_repeat` times per epoch: 3 rooms x 33 = 99 samples against the 100 generated
#   rooms, so a batch of 4 holds two of them on average.
# - The generated areas stay in every epoch, so the classes a user never labels (and the
#   generated rooms' variety) keep their training data.
# - exp2_cpu.py's optimiser for 6 epochs of 50 iterations (batch 4), the learning rate dropping
#   10x after epoch 4; validation on generated area 9 at the end only (the final epoch is the
#   model, as in exp2_cpu.py). Its training time: docs/teach.md, "5. Fine-tune".
# Another synthetic checkpoint: --cfg-options load_from=work_dirs/exp2_cpu/epoch_12.pth
_base_ = ['./exp2_cpu.py']
from projects.synthdet.config_helpers import areas_once  # noqa: E402

load_from = 'work_dirs/exp2_cpu/epoch_12.pth'
user_area = 10
user_repeat = 33
epochs = 6

# the user's area listed `user_repeat` times: every entry is a plain area dataset
train_dataloader = areas_once(_base_.train_area_dataset, _base_.train_pipeline,
                              [*_base_.train_area, *[user_area] * user_repeat], _base_.metainfo)
train_cfg = dict(max_epochs=epochs, val_interval=epochs)
param_scheduler = dict(
    type='MultiStepLR', begin=0, end=epochs, by_epoch=True, milestones=[4], gamma=0.1)
