"""Axis-aligned IoU / DIoU box loss used by the TR3D head."""
from typing import Optional

from mmdet.models.losses.utils import weight_reduce_loss
from mmdet3d.registry import MODELS
from torch import Tensor, nn

from ..core.box_ops import aligned_diou_3d, aligned_iou_3d


@MODELS.register_module()
class TR3DAxisAlignedIoULoss(nn.Module):
    """``1 - IoU`` (mode 'iou') or ``1 - DIoU`` (mode 'diou') of matched axis-aligned boxes.

    Boxes are in corner form ``(x1, y1, z1, x2, y2, z2)``; prediction ``i`` is compared with
    target ``i``. DIoU also penalises the squared centre distance over the squared diagonal of
    the enclosing box, so it still has a gradient when the boxes do not overlap.

    Args:
        mode: 'iou' or 'diou'.
        reduction: 'none', 'mean' or 'sum'.
        loss_weight: multiplier of the loss.
    """

    def __init__(self, mode: str = 'diou', reduction: str = 'mean', loss_weight: float = 1.0):
        super().__init__()
        if mode not in ('iou', 'diou'):
            raise ValueError(f"mode must be 'iou' or 'diou', got {mode!r}")
        if reduction not in ('none', 'mean', 'sum'):
            raise ValueError(f"reduction must be 'none', 'mean' or 'sum', got {reduction!r}")
        self.mode = mode
        self.reduction = reduction
        self.loss_weight = loss_weight

    def forward(self,
                pred: Tensor,
                target: Tensor,
                weight: Optional[Tensor] = None,
                avg_factor: Optional[float] = None,
                reduction_override: Optional[str] = None) -> Tensor:
        """Loss of (N, 6) predicted boxes against (N, 6) target boxes."""
        if pred.shape != target.shape or pred.shape[-1] != 6:
            raise ValueError(f'pred and target must both be (N, 6), got {tuple(pred.shape)} '
                             f'and {tuple(target.shape)}')
        overlap = aligned_diou_3d if self.mode == 'diou' else aligned_iou_3d
        loss = 1 - overlap(pred, target)
        reduction = reduction_override or self.reduction
        return self.loss_weight * weight_reduce_loss(loss, weight, reduction, avg_factor)
