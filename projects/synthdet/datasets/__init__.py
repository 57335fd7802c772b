"""synthdet datasets; the package itself imports nothing.

``s3dis_converter``, ``point_text``, ``s3dis_classes`` need only numpy, numba and tqdm;
``synthdet_s3dis`` registers ``SynthdetS3DISDataset`` with mmdet3d (and so imports it).
"""
