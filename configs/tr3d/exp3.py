# Experiment 3: real and generated data. Train the real areas 1, 2, 3, 4, 6 and the generated
# areas 7, 8, 9, test the real area 5, on table, chair, sofa, yumi and 3dprinter (the synthetic
# classes replace bookcase and board). label2level as in exp2.py.
_base_ = ['./tr3d.py', './_base_/s3dis-synthdet.py']
from projects.synthdet.config_helpers import area_datasets, area_info_file  # noqa: E402

metainfo = dict(classes=('table', 'chair', 'sofa', 'yumi', '3dprinter'))
train_area = [1, 2, 3, 4, 6, 7, 8, 9]
test_area = 5

model = dict(bbox_head=dict(num_classes=5, label2level=(1, 0, 1, 0, 0)))

train_dataloader = dict(
    dataset=dict(
        dataset=dict(datasets=area_datasets(_base_.train_area_dataset, train_area, metainfo))))
val_dataloader = dict(dataset=dict(ann_file=area_info_file(test_area), metainfo=metainfo))
test_dataloader = val_dataloader
