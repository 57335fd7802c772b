"""synthdet mmdet3d plugin: datasets, TR3D model, box ops and the paper's tables.

Importing the package loads nothing heavy, so data tools (``tools/create_data.py``,
``tools/dataset_stats.py``) run without torch or mmcv. The modules that register with mmdet3d
are imported by the configs' ``custom_imports`` (see ``configs/tr3d/tr3d.py``):
``projects.synthdet.datasets.synthdet_s3dis`` (``SynthdetS3DISDataset``) and
``projects.synthdet.models`` (TR3D detector, backbone, neck, head and loss).
"""
