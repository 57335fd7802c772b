# Experiment 3 fine-tuned from TR3D's published S3DIS model (mmdetection3d's projects/TR3D,
# tr3d_1xb16_s3dis-3d-5class: trained on the S3DIS areas 1, 2, 3, 4, 6, so test area 5 stays
# unseen). Everything else is exp3.py: the same data, classes, schedule and best-epoch rule.
# The synthdet TR3D keeps mmdetection3d's parameter names and shapes, so the checkpoint loads whole
# (tests/test_models/test_finetune.py checks a checkpoint of that layout loads strictly): both
# models have 5 classes, and the output rows of TR3D's bookcase and board start yumi and 3dprinter.
# mmengine downloads the URL on first use (into the torch hub cache); offline, download it
# once and pass the file: --cfg-options load_from=checkpoints/tr3d_1xb16_s3dis-3d-5class.pth
_base_ = ['./exp3.py']

load_from = ('https://download.openmmlab.com/mmdetection3d/v1.1.0_models/tr3d/'
             'tr3d_1xb16_s3dis-3d-5class/tr3d_1xb16_s3dis-3d-5class.pth')
