"""TR3D's anchor-free sparse detection head (axis-aligned boxes)."""
from typing import Optional, Sequence

import MinkowskiEngine as ME
import torch
from mmdet3d.models.dense_heads.base_3d_dense_head import Base3DDenseHead
from mmdet3d.registry import MODELS
from mmdet3d.structures import BaseInstance3DBoxes, DepthInstance3DBoxes
from mmengine.model import bias_init_with_prob
from mmengine.structures import InstanceData
from torch import Tensor, nn

from synthdet.classes import IGNORED_REGION_LABEL

from ..core.box_ops import center_size_to_corners
from ..core.nms import multiclass_axis_aligned_nms3d
from .tr3d_assigner import tr3d_assign

PerLevelPerScene = list[list[Tensor]]


def _scene(per_level: PerLevelPerScene, index: int) -> list[Tensor]:
    """The tensors of scene ``index`` from per-level, per-scene lists."""
    return [level[index] for level in per_level]


def inside_boxes(points: Tensor, boxes: BaseInstance3DBoxes) -> Tensor:
    """(N,) whether each of ``points`` (N, 3) lies in one of the axis-aligned ``boxes``
    (their yaw is not used: the boxes of these rooms are axis-aligned)."""
    if len(boxes) == 0:
        return torch.zeros(len(points), dtype=torch.bool, device=points.device)
    centers = boxes.gravity_center.to(points)
    half = boxes.dims.to(points) / 2
    offsets = (points[:, None, :] - centers[None, :, :]).abs()
    return (offsets <= half[None, :, :]).all(dim=-1).any(dim=1)


@MODELS.register_module()
class TR3DHead(Base3DDenseHead):
    """Two 1x1x1 sparse convolutions per level: class logits and 6 box parameters.

    The box parameters of a location ``p`` are a centre offset ``(dx, dy, dz)`` and log sizes:
    the box is ``centre = p + offset``, ``size = exp(log_size)``. Training assigns locations to
    boxes with :func:`tr3d_assign` (level by ``label2level``, ``pts_center_threshold`` nearest
    locations), uses a focal loss (summed, divided by the number of positives) for the classes
    and ``bbox_loss`` (axis-aligned DIoU by default) on decoded positive boxes. Inference keeps
    the ``nms_pre`` locations with the highest class score over all levels and runs per-class
    NMS (``iou_thr``, ``score_thr``).

    Args:
        num_classes: number of classes; must equal ``len(label2level)``.
        in_channels: channels of every neck level.
        num_reg_outs: box parameters per location; only 6 (axis-aligned) is supported.
        voxel_size: voxel edge in metres, converts sparse coordinates to metres.
        pts_center_threshold: positive locations per box.
        label2level: output level of every class.
        bbox_loss: box loss config.
        cls_loss: classification loss config.
        train_cfg: unused, kept for the mmdet3d interface.
        test_cfg: ``nms_pre``, ``iou_thr`` and ``score_thr``.
    """

    def __init__(self,
                 num_classes: int,
                 label2level: Sequence[int],
                 in_channels: int = 128,
                 num_reg_outs: int = 6,
                 voxel_size: float = 0.01,
                 pts_center_threshold: int = 6,
                 bbox_loss: dict = dict(
                     type='TR3DAxisAlignedIoULoss', mode='diou', reduction='none'),
                 cls_loss: dict = dict(type='mmdet.FocalLoss', reduction='none'),
                 train_cfg: Optional[dict] = None,
                 test_cfg: Optional[dict] = None,
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg)
        if len(label2level) != num_classes:
            raise ValueError(f'label2level {tuple(label2level)} must have one level per class '
                             f'(num_classes={num_classes})')
        if num_reg_outs != 6:
            raise ValueError(f'only axis-aligned boxes (num_reg_outs=6) are supported, got '
                             f'{num_reg_outs}')
        self.num_classes = num_classes
        self.label2level = tuple(label2level)
        self.voxel_size = voxel_size
        self.pts_center_threshold = pts_center_threshold
        self.bbox_loss = MODELS.build(bbox_loss)
        self.cls_loss = MODELS.build(cls_loss)
        self.train_cfg = train_cfg
        self.test_cfg = dict(nms_pre=1000, iou_thr=0.5, score_thr=0.01)
        self.test_cfg.update(test_cfg or {})
        self.conv_reg = ME.MinkowskiConvolution(
            in_channels, num_reg_outs, kernel_size=1, bias=True, dimension=3)
        self.conv_cls = ME.MinkowskiConvolution(
            in_channels, num_classes, kernel_size=1, bias=True, dimension=3)

    def init_weights(self) -> None:
        """Small normal kernels; class bias set for a 1% prior probability."""
        nn.init.normal_(self.conv_reg.kernel, std=0.01)
        nn.init.normal_(self.conv_cls.kernel, std=0.01)
        nn.init.constant_(self.conv_cls.bias, bias_init_with_prob(0.01))

    def _forward_single(self, x: ME.SparseTensor) -> tuple[list[Tensor], ...]:
        reg = self.conv_reg(x).features
        bbox_pred = torch.cat((reg[:, :3], torch.exp(reg[:, 3:6])), dim=1)
        cls_pred = self.conv_cls(x).features
        bbox_preds, cls_preds, points = [], [], []
        for permutation in x.decomposition_permutations:
            bbox_preds.append(bbox_pred[permutation])
            cls_preds.append(cls_pred[permutation])
            points.append(x.coordinates[permutation][:, 1:] * self.voxel_size)
        return bbox_preds, cls_preds, points

    def forward(self, x: Sequence[ME.SparseTensor]) -> tuple[PerLevelPerScene, ...]:
        """Per level and per scene: box parameters (offset, size), class logits, locations."""
        bbox_preds, cls_preds, points = [], [], []
        for level_tensor in x:
            bbox_pred, cls_pred, point = self._forward_single(level_tensor)
            bbox_preds.append(bbox_pred)
            cls_preds.append(cls_pred)
            points.append(point)
        return bbox_preds, cls_preds, points

    @staticmethod
    def decode_boxes(points: Tensor, bbox_pred: Tensor) -> Tensor:
        """(N, 6) centre-size boxes from locations and (offset, size) predictions."""
        return torch.cat((points + bbox_pred[:, :3], bbox_pred[:, 3:6]), dim=1)

    def get_targets(self, points: Sequence[Tensor], gt_bboxes: BaseInstance3DBoxes,
                    gt_labels: Tensor) -> tuple[Tensor, Tensor]:
        """Box targets (N, 6, centre-size) and class targets (N,) for one scene's locations.

        Negatives get class ``num_classes``; their box targets are undefined.
        """
        device = points[0].device
        boxes = torch.cat((gt_bboxes.gravity_center, gt_bboxes.dims), dim=1).to(device)
        assigned = tr3d_assign(points, boxes[:, :3], gt_labels.to(device), self.label2level,
                               self.pts_center_threshold)
        positive = assigned >= 0
        bbox_targets = boxes[assigned.clamp(min=0)] if len(boxes) else \
            boxes.new_zeros((len(assigned), 6))
        cls_targets = torch.full_like(assigned, self.num_classes)
        cls_targets[positive] = gt_labels.to(device)[assigned[positive]]
        return bbox_targets, cls_targets

    def loss_by_feat(self,
                     bbox_preds: PerLevelPerScene,
                     cls_preds: PerLevelPerScene,
                     points: PerLevelPerScene,
                     batch_gt_instances_3d: list[InstanceData],
                     batch_input_metas: list[dict],
                     batch_gt_instances_ignore: Optional[list] = None,
                     **kwargs) -> dict[str, Tensor]:
        """Focal class loss over all locations and box loss over positive locations.

        Boxes labelled ``IGNORED_REGION_LABEL`` are no objects: a location inside one is left
        out of the class loss unless it is a positive of a true box."""
        bbox_losses, cls_losses, num_positive = [], [], 0
        for i, gt_instances in enumerate(batch_gt_instances_3d):
            scene_points = _scene(points, i)
            ignored = gt_instances.labels_3d == IGNORED_REGION_LABEL
            bbox_targets, cls_targets = self.get_targets(scene_points,
                                                         gt_instances.bboxes_3d[~ignored],
                                                         gt_instances.labels_3d[~ignored])
            positive = cls_targets < self.num_classes
            counted = positive | ~inside_boxes(torch.cat(scene_points),
                                               gt_instances.bboxes_3d[ignored])
            scene_cls = torch.cat(_scene(cls_preds, i))
            cls_losses.append(self.cls_loss(scene_cls[counted], cls_targets[counted]).sum())
            num_positive += int(positive.sum())
            if positive.any():
                scene_bbox = torch.cat(_scene(bbox_preds, i))[positive]
                decoded = self.decode_boxes(torch.cat(scene_points)[positive], scene_bbox)
                bbox_losses.append(
                    self.bbox_loss(
                        center_size_to_corners(decoded),
                        center_size_to_corners(bbox_targets[positive])))
        if bbox_losses:
            bbox_loss = torch.cat(bbox_losses).mean()
        else:  # no positive location in the batch: zero loss that still touches the graph
            bbox_loss = sum(pred.sum() for level in bbox_preds for pred in level) * 0
        cls_loss = torch.stack(cls_losses).sum() / max(num_positive, 1)
        return dict(bbox_loss=bbox_loss, cls_loss=cls_loss)

    def _predict_single(self, bbox_preds: list[Tensor], cls_preds: list[Tensor],
                        points: list[Tensor], input_meta: dict) -> InstanceData:
        scores = torch.cat(cls_preds).sigmoid()
        bbox_pred = torch.cat(bbox_preds)
        locations = torch.cat(points)
        nms_pre = self.test_cfg['nms_pre']
        if 0 < nms_pre < len(scores):
            top = scores.max(dim=1).values.topk(nms_pre).indices
            scores, bbox_pred, locations = scores[top], bbox_pred[top], locations[top]
        boxes, box_scores, labels = multiclass_axis_aligned_nms3d(
            self.decode_boxes(locations, bbox_pred), scores, self.test_cfg['score_thr'],
            self.test_cfg['iou_thr'])
        box_type = input_meta.get('box_type_3d', DepthInstance3DBoxes)
        results = InstanceData()
        results.bboxes_3d = box_type(boxes, box_dim=6, with_yaw=False, origin=(0.5, 0.5, 0.5))
        results.scores_3d = box_scores
        results.labels_3d = labels
        return results

    def predict_by_feat(self, bbox_preds: PerLevelPerScene, cls_preds: PerLevelPerScene,
                        points: PerLevelPerScene, batch_input_metas: list[dict],
                        **kwargs) -> list[InstanceData]:
        """Detections per scene: ``bboxes_3d`` (metres, yaw 0), ``scores_3d``, ``labels_3d``."""
        return [
            self._predict_single(
                _scene(bbox_preds, i), _scene(cls_preds, i), _scene(points, i), meta)
            for i, meta in enumerate(batch_input_metas)
        ]
