"""Fusion of the detections of several passes over one scene (test-time augmentation).

Each pass (another random point sample, another flip) gives its own boxes after NMS. Per class,
:func:`fuse_passes` groups them as greedy NMS would, leader first in descending score, but the
boxes a leader would suppress vote instead of vanishing (as in weighted boxes fusion, Solovyev et
al., 2021): the group's box is the score-weighted mean of its members and its score the mean over
all passes of each pass's best score in the group, a pass without a member adding 0. A box that
only some passes find is kept with a score scaled by the share of passes that found it, so a
false positive that one random sample produces ranks below an object every pass sees.
"""
import torch
from torch import Tensor

from .box_ops import pairwise_iou_3d


def _group(boxes: Tensor, iou_thr: float) -> Tensor:
    """Group index of each box of ``boxes`` (sorted by descending score): a box not yet grouped
    leads a new group with every ungrouped box whose 3D IoU with it exceeds ``iou_thr``."""
    overlaps = pairwise_iou_3d(boxes, boxes) > iou_thr
    group = torch.full((len(boxes), ), -1, dtype=torch.long, device=boxes.device)
    groups = 0
    for leader in range(len(boxes)):
        if group[leader] >= 0:
            continue
        members = (group < 0) & overlaps[leader]
        members[leader] = True
        group[members] = groups
        groups += 1
    return group


def fuse_passes(boxes: Tensor, scores: Tensor, labels: Tensor, passes: Tensor, num_passes: int,
                iou_thr: float) -> tuple[Tensor, Tensor, Tensor]:
    """Fuse the detections of ``num_passes`` passes over one scene, per class.

    Args:
        boxes: (N, 6) centre-size boxes of all passes, in the scene's frame.
        scores: (N,) their scores.
        labels: (N,) their class labels.
        passes: (N,) the pass (0 .. num_passes - 1) each box comes from.
        num_passes: the number of passes, including those that found nothing.
        iou_thr: 3D IoU above which a box votes for a higher-scored box of its class.

    Returns:
        Fused boxes (K, 6), scores (K,) and labels (K,), grouped by class.
    """
    if not len(boxes) == len(scores) == len(labels) == len(passes):
        raise ValueError(f'boxes, scores, labels and passes differ in length: {len(boxes)}, '
                         f'{len(scores)}, {len(labels)}, {len(passes)}')
    fused_boxes, fused_scores, fused_labels = [], [], []
    for label in labels.unique(sorted=True):
        order = torch.nonzero(labels == label).squeeze(1)
        order = order[torch.argsort(scores[order], descending=True, stable=True)]
        ordered = boxes[order]
        group = _group(ordered, iou_thr)
        groups = int(group.max()) + 1
        weights = scores[order]
        box_sums = boxes.new_zeros((groups, 6)).index_add_(0, group, ordered * weights[:, None])
        weight_sums = weights.new_zeros(groups).index_add_(0, group, weights)
        best_per_pass = scores.new_zeros(groups * num_passes).scatter_reduce_(
            0, group * num_passes + passes[order], weights, reduce='amax')
        fused_boxes.append(box_sums / weight_sums.clamp(min=1e-12)[:, None])
        fused_scores.append(best_per_pass.view(groups, num_passes).sum(dim=1) / num_passes)
        fused_labels.append(
            torch.full((groups, ), int(label), dtype=labels.dtype, device=labels.device))
    if not fused_boxes:
        return boxes.new_zeros((0, 6)), scores.new_zeros((0, )), labels.new_zeros((0, ))
    return torch.cat(fused_boxes), torch.cat(fused_scores), torch.cat(fused_labels)
