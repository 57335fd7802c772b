"""Axis-aligned 3D NMS that runs on any device.

On CUDA tensors the work goes to mmcv's ``nms3d_normal`` kernel (what the published TR3D uses);
mmcv has no CPU kernel for it, so CPU tensors use :func:`axis_aligned_nms3d_cpu`, a torch
implementation with the same semantics: boxes are visited in descending score order and a box is
suppressed when its bird's-eye-view (x-y) IoU with a kept box is strictly greater than
``iou_thr``. Heights are ignored by the overlap, as in mmcv.
"""
import numpy as np
import torch
from mmcv.ops import nms3d_normal
from torch import Tensor

from .box_ops import pairwise_bev_iou


def uses_mmcv_kernel(device: torch.device) -> bool:
    """Whether :func:`axis_aligned_nms3d` sends tensors on ``device`` to mmcv's CUDA kernel."""
    return device.type == 'cuda'


def _check_inputs(boxes: Tensor, scores: Tensor) -> None:
    if boxes.dim() != 2 or boxes.shape[1] not in (6, 7):
        raise ValueError(f'boxes must be (N, 6) or (N, 7), got {tuple(boxes.shape)}')
    if scores.shape != boxes.shape[:1]:
        raise ValueError(f'scores must be ({boxes.shape[0]},), got {tuple(scores.shape)}')


def axis_aligned_nms3d_cpu(boxes: Tensor, scores: Tensor, iou_thr: float) -> Tensor:
    """Greedy axis-aligned NMS in torch; returns kept indices sorted by descending score.

    Args:
        boxes: (N, 6) or (N, 7) boxes ``(x, y, z, dx, dy, dz[, yaw])``; yaw is ignored.
        scores: (N,) scores.
        iou_thr: a box is dropped when its BEV IoU with a higher-scored kept box exceeds this.

    Memory is O(N^2); the TR3D head calls it with at most ``nms_pre`` boxes per class.
    """
    _check_inputs(boxes, scores)
    order = torch.sort(scores, descending=True, stable=True).indices
    if len(order) == 0:
        return order
    sorted_boxes = boxes[order]
    overlaps = (pairwise_bev_iou(sorted_boxes, sorted_boxes) > iou_thr).cpu().numpy()
    suppressed = np.zeros(len(order), dtype=bool)
    keep = []
    for i in range(len(order)):
        if suppressed[i]:
            continue
        keep.append(i)
        suppressed |= overlaps[i]
    return order[torch.as_tensor(keep, dtype=torch.long, device=order.device)]


def mmcv_nms3d_arguments(boxes: Tensor, scores: Tensor,
                         iou_thr: float) -> tuple[Tensor, Tensor, float]:
    """The arguments :func:`axis_aligned_nms3d` passes to mmcv's ``nms3d_normal``.

    The kernel takes (N, 7) boxes ``(x, y, z, dx, dy, dz, yaw)`` (it ignores the yaw), so (N, 6)
    boxes get a zero yaw column; boxes and scores become contiguous float32 on their device.
    """
    if boxes.shape[1] == 6:
        boxes = torch.cat((boxes, boxes.new_zeros((len(boxes), 1))), dim=1)
    return boxes.float().contiguous(), scores.float().contiguous(), float(iou_thr)


def axis_aligned_nms3d(boxes: Tensor, scores: Tensor, iou_thr: float) -> Tensor:
    """Axis-aligned 3D NMS on the tensors' own device; returns kept indices (descending score).

    CUDA tensors use mmcv's ``nms3d_normal`` (arguments from :func:`mmcv_nms3d_arguments`);
    others use :func:`axis_aligned_nms3d_cpu`.
    """
    _check_inputs(boxes, scores)
    if not uses_mmcv_kernel(boxes.device):
        return axis_aligned_nms3d_cpu(boxes, scores, iou_thr)
    return nms3d_normal(*mmcv_nms3d_arguments(boxes, scores, iou_thr))


def multiclass_axis_aligned_nms3d(boxes: Tensor, scores: Tensor, score_thr: float,
                                  iou_thr: float) -> tuple[Tensor, Tensor, Tensor]:
    """Per-class NMS over (N, C) class scores, as in the TR3D head.

    For every class the boxes scoring above ``score_thr`` go through :func:`axis_aligned_nms3d`.

    Args:
        boxes: (N, 6) or (N, 7) boxes shared by all classes.
        scores: (N, C) per-class scores.
        score_thr: boxes with a class score at or below this are dropped for that class.
        iou_thr: NMS IoU threshold.

    Returns:
        Kept boxes (K, box_dim), their scores (K,) and labels (K,), grouped by class.
    """
    if scores.dim() != 2 or scores.shape[0] != boxes.shape[0]:
        raise ValueError(f'scores must be ({boxes.shape[0]}, C), got {tuple(scores.shape)}')
    kept_boxes, kept_scores, kept_labels = [], [], []
    for label in range(scores.shape[1]):
        candidates = scores[:, label] > score_thr
        if not candidates.any():
            continue
        class_boxes = boxes[candidates]
        class_scores = scores[candidates, label]
        keep = axis_aligned_nms3d(class_boxes, class_scores, iou_thr)
        kept_boxes.append(class_boxes[keep])
        kept_scores.append(class_scores[keep])
        kept_labels.append(torch.full_like(keep, label))
    if not kept_boxes:
        no_labels = torch.zeros((0, ), dtype=torch.long, device=boxes.device)
        return boxes.new_zeros((0, boxes.shape[1])), scores.new_zeros((0, )), no_labels
    return torch.cat(kept_boxes), torch.cat(kept_scores), torch.cat(kept_labels)
