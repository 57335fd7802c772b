"""Axis-aligned 3D box operations in plain torch (any device).

Boxes are ``(x, y, z, dx, dy, dz)`` with ``(x, y, z)`` the box centre, in metres, unless a
function says it takes corner form ``(x1, y1, z1, x2, y2, z2)``.
"""
import torch
from torch import Tensor


def center_size_to_corners(boxes: Tensor) -> Tensor:
    """Convert ``(..., 6)`` centre-size boxes to min/max corner form ``(x1, y1, z1, x2, y2, z2)``."""
    half = boxes[..., 3:6] / 2
    return torch.cat((boxes[..., :3] - half, boxes[..., :3] + half), dim=-1)


def pairwise_bev_iou(boxes_a: Tensor, boxes_b: Tensor) -> Tensor:
    """Bird's-eye-view (x-y) IoU of every box in ``boxes_a`` (N, >=6) with every box in ``boxes_b``.

    This is the overlap that mmcv's ``nms3d_normal`` kernel uses for axis-aligned 3D NMS (z is
    ignored); returns an (N, M) tensor.
    """
    a = center_size_to_corners(boxes_a[:, :6])
    b = center_size_to_corners(boxes_b[:, :6])
    low = torch.maximum(a[:, None, 0:2], b[None, :, 0:2])
    high = torch.minimum(a[:, None, 3:5], b[None, :, 3:5])
    inter = (high - low).clamp(min=0).prod(dim=-1)
    area_a = (boxes_a[:, 3] * boxes_a[:, 4])[:, None]
    area_b = (boxes_b[:, 3] * boxes_b[:, 4])[None, :]
    return inter / (area_a + area_b - inter).clamp(min=1e-8)


def aligned_iou_3d(corners_a: Tensor, corners_b: Tensor, eps: float = 1e-6) -> Tensor:
    """Element-wise 3D IoU of two (..., 6) tensors of corner-form boxes (broadcast)."""
    low = torch.maximum(corners_a[..., :3], corners_b[..., :3])
    high = torch.minimum(corners_a[..., 3:], corners_b[..., 3:])
    inter = (high - low).clamp(min=0).prod(dim=-1)
    vol_a = (corners_a[..., 3:] - corners_a[..., :3]).prod(dim=-1)
    vol_b = (corners_b[..., 3:] - corners_b[..., :3]).prod(dim=-1)
    return inter / (vol_a + vol_b - inter).clamp(min=eps)


def aligned_diou_3d(corners_a: Tensor, corners_b: Tensor, eps: float = 1e-6) -> Tensor:
    """Element-wise 3D Distance-IoU of (N, 6) corner-form boxes: IoU - d^2 / c^2.

    ``d`` is the distance between the box centres and ``c`` the diagonal of the smallest box
    enclosing both (Zheng et al., 2020).
    """
    iou = aligned_iou_3d(corners_a, corners_b, eps)
    center_a = (corners_a[:, :3] + corners_a[:, 3:]) / 2
    center_b = (corners_b[:, :3] + corners_b[:, 3:]) / 2
    center_dist2 = (center_a - center_b).pow(2).sum(dim=-1)
    enclose_low = torch.minimum(corners_a[:, :3], corners_b[:, :3])
    enclose_high = torch.maximum(corners_a[:, 3:], corners_b[:, 3:])
    diag2 = (enclose_high - enclose_low).pow(2).sum(dim=-1)
    return iou - center_dist2 / diag2.clamp(min=eps)


def pairwise_iou_3d(boxes_a: Tensor, boxes_b: Tensor, eps: float = 1e-6) -> Tensor:
    """3D IoU of every centre-size box in ``boxes_a`` (N, >=6) with every box in ``boxes_b``
    (M, >=6), axis-aligned (a yaw column is ignored); returns an (N, M) tensor."""
    return aligned_iou_3d(center_size_to_corners(boxes_a[:, None, :6]),
                          center_size_to_corners(boxes_b[None, :, :6]), eps)
