"""synthdet core: axis-aligned box ops and device-agnostic 3D NMS."""
from .box_ops import (aligned_diou_3d, aligned_iou_3d, center_size_to_corners, pairwise_bev_iou)
from .nms import (axis_aligned_nms3d, axis_aligned_nms3d_cpu, mmcv_nms3d_arguments,
                  multiclass_axis_aligned_nms3d, uses_mmcv_kernel)

__all__ = [
    'aligned_diou_3d', 'aligned_iou_3d', 'center_size_to_corners', 'pairwise_bev_iou',
    'axis_aligned_nms3d', 'axis_aligned_nms3d_cpu', 'mmcv_nms3d_arguments',
    'multiclass_axis_aligned_nms3d', 'uses_mmcv_kernel'
]
