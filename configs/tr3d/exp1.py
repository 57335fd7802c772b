# Experiment 1 (paper Table 2): the baseline. Real S3DIS only: train areas 1, 2, 3, 4, 6 and
# test area 5 on TR3D's 5 S3DIS classes, with TR3D's published S3DIS label2level.
_base_ = ['./tr3d.py', './_base_/s3dis-synthdet.py']
from projects.synthdet.config_helpers import area_loaders  # noqa: E402

metainfo = dict(classes=('table', 'chair', 'sofa', 'bookcase', 'board'))
train_area = [1, 2, 3, 4, 6]
test_area = 5

model = dict(bbox_head=dict(num_classes=5, label2level=(1, 0, 1, 1, 0)))

train_dataloader, val_dataloader = area_loaders(_base_.train_area_dataset, train_area, test_area,
                                                metainfo)
test_dataloader = val_dataloader
