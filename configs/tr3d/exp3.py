# Experiment 3: real and generated data. Train the real areas 1, 2, 3, 4, 6 and the generated
# areas 7, 8, 9, test the real area 5, on exp2.py's classes table, chair, sofa, yumi and
# 3dprinter (the synthetic classes replace bookcase and board) with its label2level.
_base_ = ['./exp2.py']
from projects.synthdet.config_helpers import area_loaders  # noqa: E402

train_area = [1, 2, 3, 4, 6, 7, 8, 9]
test_area = 5

train_dataloader, val_dataloader = area_loaders(_base_.train_area_dataset, train_area, test_area,
                                                _base_.metainfo)
test_dataloader = val_dataloader
