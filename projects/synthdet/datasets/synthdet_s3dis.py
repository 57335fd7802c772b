"""S3DIS detection dataset with the synthetic classes yumi and 3dprinter (areas 1-9).

Importing it also registers the robustness augmentations of ``transforms.py``.
"""
from typing import Optional

import numpy as np
import torch
from mmdet3d.datasets import S3DISDataset
from mmdet3d.registry import DATASETS
from mmdet3d.structures import DepthInstance3DBoxes

from projects.synthdet.datasets import transforms  # noqa: F401  (registers the augmentations)
from synthdet.classes import (CLASS_COLORS, DETECTION_CLASSES, DETECTION_SEMANTIC_IDS,
                              IGNORED_REGION_LABEL, SEMANTIC_CLASSES)
from synthdet.info_files import InfoFileError, load_info_pickle


@DATASETS.register_module()
class SynthdetS3DISDataset(S3DISDataset):
    """mmdet3d's ``S3DISDataset`` with 7 detection classes, for the pickles of
    ``tools/create_data.py``.

    ``metainfo=dict(classes=...)`` selects a subset: labels are renumbered in the subset's
    order and instances of the other classes are dropped (mmdet3d's parent keeps them with
    label -1). The palette and the semantic-mask mapping used by ``PointSegClassMapping``
    follow the subset too. The ``ann_file`` is read as plain data (``load_info_pickle``): a
    pickle that would run code is refused with ``InfoFileError`` naming the file.
    """
    METAINFO = {
        'classes':
        DETECTION_CLASSES,
        'seg_valid_class_ids':
        DETECTION_SEMANTIC_IDS,
        'seg_all_class_ids':
        tuple(range(len(SEMANTIC_CLASSES))),
        'palette': [CLASS_COLORS[name] for name in DETECTION_CLASSES],
    }

    def __init__(self,
                 data_root: str,
                 ann_file: str,
                 metainfo: Optional[dict] = None,
                 **kwargs) -> None:
        metainfo = dict(metainfo) if metainfo is not None else None
        classes = tuple((metainfo or {}).get('classes', DETECTION_CLASSES))
        unknown = [name for name in classes if name not in DETECTION_CLASSES]
        if unknown:
            raise ValueError(f'{type(self).__name__}: unknown classes {unknown} in metainfo; '
                             f'known: {DETECTION_CLASSES}')
        if metainfo is not None and 'palette' not in metainfo:
            metainfo['palette'] = [
                self.METAINFO['palette'][DETECTION_CLASSES.index(name)] for name in classes
            ]
        self.subset_seg_label_mapping = self._seg_label_mapping(classes)
        super().__init__(data_root=data_root, ann_file=ann_file, metainfo=metainfo, **kwargs)
        self.seg_label_mapping = self.subset_seg_label_mapping

    @staticmethod
    def _seg_label_mapping(classes: tuple[str, ...]) -> np.ndarray:
        """Semantic id -> class index in ``classes``; every other id -> len(classes)."""
        mapping = np.full(len(SEMANTIC_CLASSES) + 1, len(classes), dtype=np.int64)
        for index, name in enumerate(classes):
            mapping[SEMANTIC_CLASSES.index(name)] = index
        return mapping

    def load_data_list(self) -> list[dict]:
        """The parsed infos of ``ann_file``, read by the project's plain-data unpickler
        (mmengine's ``load``, which the parent uses, unpickles anything); the pickle's
        ``metainfo`` fills what the class and the config leave unset, as in the parent."""
        annotations = load_info_pickle(self.ann_file)
        for key, value in annotations['metainfo'].items():
            self._metainfo.setdefault(key, value)
        data_list = []
        for index, info in enumerate(annotations['data_list']):
            try:
                data_list.append(self.parse_data_info(info))
            except (KeyError, TypeError, ValueError, IndexError) as error:
                raise InfoFileError(f'{self.ann_file}: data_list[{index}] is not an info of '
                                    f'tools/create_data.py ({type(error).__name__}: '
                                    f'{" ".join(str(error).split())[:200]})') from None
        return data_list

    def parse_data_info(self, info: dict) -> dict:
        info = super().parse_data_info(info)
        info['seg_label_mapping'] = self.subset_seg_label_mapping
        return info

    def parse_ann_info(self, info: dict) -> dict:
        """Annotations with labels in the selected classes only, then the info's
        ``ignored_regions`` (``[{'bbox_3d': [x, y, z, dx, dy, dz]}]``, gravity centres, as the
        instances) labelled ``IGNORED_REGION_LABEL``: they go through the pipeline's transforms
        with the true boxes, and the head leaves the locations inside them out of its class
        loss."""
        ann_info = super().parse_ann_info(info)
        keep = ann_info['gt_labels_3d'] > -1
        boxes = ann_info['gt_bboxes_3d'][torch.from_numpy(keep)]
        labels = ann_info['gt_labels_3d'][keep]
        regions = info.get('ignored_regions') or []
        if regions:
            ignored = DepthInstance3DBoxes(
                np.array([region['bbox_3d'] for region in regions], dtype=np.float32),
                box_dim=6, with_yaw=False, origin=(0.5, 0.5, 0.5))
            boxes = DepthInstance3DBoxes.cat([boxes, ignored])
            labels = np.concatenate(
                [labels, np.full(len(regions), IGNORED_REGION_LABEL, dtype=labels.dtype)])
        ann_info['gt_bboxes_3d'], ann_info['gt_labels_3d'] = boxes, labels
        return ann_info
