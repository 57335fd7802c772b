"""synthdet datasets; the package itself imports nothing.

``s3dis_converter`` needs only numpy, numba, tqdm and the light core (``synthdet``);
``synthdet_s3dis`` registers ``SynthdetS3DISDataset`` with mmdet3d (and so imports it), and
imports ``transforms``, which registers the robustness augmentations.
"""
