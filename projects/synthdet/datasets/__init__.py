"""synthdet datasets (registered with mmdet3d on import).

``s3dis_converter``, ``point_text``, ``instance_counts`` and ``s3dis_classes`` need only numpy
and numba; ``synthdet_s3dis`` registers ``SynthdetS3DISDataset`` with mmdet3d.
"""
from .instance_counts import count_instances, format_table1, table1_rows
from synthdet.classes import DETECTION_CLASSES, SEMANTIC_CLASSES
from .s3dis_converter import ConversionSummary, convert_s3dis
from .synthdet_s3dis import SynthdetS3DISDataset

__all__ = [
    'DETECTION_CLASSES', 'SEMANTIC_CLASSES', 'ConversionSummary', 'SynthdetS3DISDataset',
    'convert_s3dis', 'count_instances', 'format_table1', 'table1_rows'
]
