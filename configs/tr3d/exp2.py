# Experiment 2: generated data only. Train the generated areas 7 and 8, test the generated area 9,
# on table, chair, sofa and the two synthetic classes yumi and 3dprinter.
# Without the real areas 1, 2, 3 of the paper's Table 2, so that it runs without the S3DIS
# download (exp2_paper.py adds them). label2level: table and sofa on the coarse level as in
# TR3D's S3DIS config; chair, YuMi and 3D printer (chair-sized) on the fine level.
_base_ = ['./tr3d.py', './_base_/s3dis-synthdet.py']
from projects.synthdet.config_helpers import area_loaders  # noqa: E402

metainfo = dict(classes=('table', 'chair', 'sofa', 'yumi', '3dprinter'))
train_area = [7, 8]
test_area = 9

model = dict(bbox_head=dict(num_classes=5, label2level=(1, 0, 1, 0, 0)))

train_dataloader, val_dataloader = area_loaders(_base_.train_area_dataset, train_area, test_area,
                                                metainfo)
test_dataloader = val_dataloader
