"""Test-time augmentation for the TR3D detector: several passes over each scene, fused."""
import torch
from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample, bbox3d_mapping_back
from mmengine.model import BaseTTAModel
from mmengine.structures import InstanceData
from torch import nn

from ..core.box_fusion import fuse_passes


@MODELS.register_module()
class SynthdetTTAModel(BaseTTAModel):
    """Wraps a detector for mmengine's test-time augmentation (``tools/test.py --tta``).

    The ``tta_pipeline`` (``projects.synthdet.config_helpers.with_test_time_augmentation``)
    gives every scene in several versions, e.g. flipped and each with its own random point
    sample; the wrapped detector predicts each version, the boxes are flipped back into the
    scene's frame and fused per class (:func:`projects.synthdet.core.box_fusion.fuse_passes`).

    Args:
        module: the detector, or its config (``tools/test.py`` puts the config's ``model``
            here; ``tools/predict.py`` the loaded detector).
        fusion_iou_thr: 3D IoU above which boxes of one class from the passes are fused.
    """

    def __init__(self, module: dict | nn.Module, fusion_iou_thr: float = 0.5, **kwargs) -> None:
        super().__init__(module=module, **kwargs)
        self.fusion_iou_thr = fusion_iou_thr

    def merge_preds(self, data_samples_list: list) -> list:
        """One data sample per scene with the fused ``pred_instances_3d`` of its passes."""
        return [self._merge_scene(list(samples)) for samples in data_samples_list]

    def _merge_scene(self, samples: list) -> Det3DDataSample:
        boxes, scores, labels, passes = [], [], [], []
        for index, sample in enumerate(samples):
            pred = sample.pred_instances_3d
            meta = sample.metainfo
            restored = bbox3d_mapping_back(pred.bboxes_3d, meta.get('pcd_scale_factor', 1.0),
                                           meta.get('pcd_horizontal_flip', False),
                                           meta.get('pcd_vertical_flip', False))
            boxes.append(torch.cat((restored.gravity_center, restored.dims), dim=1))
            scores.append(pred.scores_3d)
            labels.append(pred.labels_3d)
            passes.append(torch.full_like(pred.labels_3d, index))
        fused_boxes, fused_scores, fused_labels = fuse_passes(
            torch.cat(boxes), torch.cat(scores), torch.cat(labels), torch.cat(passes),
            len(samples), self.fusion_iou_thr)
        merged = samples[0]
        box_type = type(merged.pred_instances_3d.bboxes_3d)
        result = InstanceData()
        result.bboxes_3d = box_type(fused_boxes, box_dim=6, with_yaw=False, origin=(0.5, 0.5, 0.5))
        result.scores_3d = fused_scores
        result.labels_3d = fused_labels
        merged.pred_instances_3d = result
        return merged
