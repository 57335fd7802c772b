"""The TR3D single-stage sparse 3D detector."""
from typing import Optional

import MinkowskiEngine as ME
from mmdet3d.models.detectors.base import Base3DDetector
from mmdet3d.registry import MODELS
from mmdet3d.structures.det3d_data_sample import SampleList
from torch import Tensor


@MODELS.register_module()
class TR3DDetector(Base3DDetector):
    """TR3D (Rukhovich et al., 2023): sparse ResNet, sparse FPN neck, anchor-free head.

    Points (N, 3 + C) are voxelised at ``voxel_size`` metres (the mean of the point features of
    every voxel is its feature; coordinates are floored) on the points' own device; the
    remaining columns, RGB in 0-1 for TR3D, are the input features.

    Args:
        backbone: backbone config, e.g. ``TR3DMinkResNet``.
        neck: neck config, e.g. ``TR3DNeck``.
        bbox_head: head config, e.g. ``TR3DHead``; its ``voxel_size`` is set from this one.
        voxel_size: voxel edge in metres.
        data_preprocessor: mmdet3d data preprocessor config.
        train_cfg: passed to the head.
        test_cfg: passed to the head (``nms_pre``, ``iou_thr``, ``score_thr``).
    """

    def __init__(self,
                 backbone: dict,
                 neck: dict,
                 bbox_head: dict,
                 voxel_size: float,
                 data_preprocessor: Optional[dict] = None,
                 train_cfg: Optional[dict] = None,
                 test_cfg: Optional[dict] = None,
                 init_cfg: Optional[dict] = None):
        super().__init__(
            data_preprocessor=data_preprocessor or dict(type='Det3DDataPreprocessor'),
            init_cfg=init_cfg)
        if 'voxel_size' in bbox_head and bbox_head['voxel_size'] != voxel_size:
            raise ValueError(f"bbox_head voxel_size {bbox_head['voxel_size']} differs from the "
                             f'detector voxel_size {voxel_size}')
        self.voxel_size = voxel_size
        self.backbone = MODELS.build(backbone)
        self.neck = MODELS.build(neck)
        self.bbox_head = MODELS.build(
            dict(bbox_head, voxel_size=voxel_size, train_cfg=train_cfg, test_cfg=test_cfg))
        self.train_cfg = train_cfg
        self.test_cfg = test_cfg

    def voxelize(self, points: list[Tensor]) -> ME.SparseTensor:
        """Every scene's (N, 3 + C) points as one batched sparse tensor of averaged features."""
        coordinates, features = ME.utils.batch_sparse_collate(
            [(p[:, :3] / self.voxel_size, p[:, 3:]) for p in points], device=points[0].device)
        return ME.SparseTensor(
            features=features,
            coordinates=coordinates,
            quantization_mode=ME.SparseTensorQuantizationMode.UNWEIGHTED_AVERAGE)

    def extract_feat(self, batch_inputs_dict: dict) -> list[ME.SparseTensor]:
        """Voxelise every scene's points into one batched sparse tensor; backbone and neck."""
        return self.neck(self.backbone(self.voxelize(batch_inputs_dict['points'])))

    def loss(self, batch_inputs_dict: dict, batch_data_samples: SampleList,
             **kwargs) -> dict[str, Tensor]:
        """Losses (``bbox_loss``, ``cls_loss``) of a batch."""
        return self.bbox_head.loss(self.extract_feat(batch_inputs_dict), batch_data_samples)

    def predict(self, batch_inputs_dict: dict, batch_data_samples: SampleList,
                **kwargs) -> SampleList:
        """Samples with ``pred_instances_3d`` (``bboxes_3d`` in metres, ``scores_3d``, ``labels_3d``)."""
        results = self.bbox_head.predict(self.extract_feat(batch_inputs_dict), batch_data_samples)
        return self.add_pred_to_datasample(batch_data_samples, results)

    def _forward(self,
                 batch_inputs_dict: dict,
                 batch_data_samples: Optional[SampleList] = None,
                 **kwargs) -> tuple:
        """Raw head outputs (box parameters, class logits, locations per level and scene)."""
        return self.bbox_head.forward(self.extract_feat(batch_inputs_dict))
