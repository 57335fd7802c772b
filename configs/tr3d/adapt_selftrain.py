# Self-training a synthetic model on the user's unlabelled scans (tools/adapt.py, docs/teach.md
# "Adapt to your scans without labels"): exp2_cpu.py's model, pipelines and classes, started
# from its checkpoint (the tool's --checkpoint), trained on pseudo-labelled scans mixed with the
# generated training areas 7 and 8.
# - The pseudo-labelled scans are area `adapt_area` (11: the real S3DIS areas are 1-6, the
#   generated ones 7-9, teach_finetune.py's user rooms 10), written and converted by the tool
#   into its --work folder, which it sets as that area's data_root. The tool lists the area
#   as often as makes `adapt_share` of the samples (half: as many as the generated rooms).
# - The generated areas stay in every run, so the classes the scans never show keep their
#   training data.
# - The teacher that makes the pseudo-labels is an exponential moving average of the student's
#   weights (`MeanTeacherEMAHook`: mmengine's EMAHook carried from one run to the next),
#   momentum 0.01 (each iteration moves it 1 % of the way to the student). The pseudo-labels
#   are refreshed from it every `refresh_iters` iterations (the tool's --refresh): each run
#   trains that many iterations and saves one checkpoint, without validation.
# - exp2_cpu.py's AdamW at a tenth of its learning rate, constant.
_base_ = ['./exp2_cpu.py']
from projects.synthdet.config_helpers import areas_once  # noqa: E402

adapt_area = 11
adapt_share = 0.5
refresh_iters = 50

train_dataloader = areas_once(_base_.train_area_dataset, _base_.train_pipeline,
                              [*_base_.train_area, adapt_area], _base_.metainfo)
custom_hooks = [dict(type='MeanTeacherEMAHook', momentum=0.01, update_buffers=True)]
optim_wrapper = dict(optimizer=dict(lr=0.0001))
param_scheduler = []
train_cfg = dict(_delete_=True, type='IterBasedTrainLoop', max_iters=refresh_iters)
default_hooks = dict(checkpoint=dict(by_epoch=False, interval=refresh_iters, max_keep_ckpts=1))
log_processor = dict(by_epoch=False)
