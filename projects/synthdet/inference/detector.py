"""A model as a detector function of :mod:`projects.synthdet.inference.windows`.

Each call runs the config's test pipeline (``PointSample`` with the training number of points,
color normalisation) through mmdet3d's ``inference_detector`` on the given points, shifted so
that their minimum is at the origin like the converted training data, and shifts the boxes back.
"""
from __future__ import annotations

import copy

import numpy as np
import torch
from mmdet3d.apis import inference_detector, init_model
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.runner import set_random_seed

from projects.synthdet.bootstrap import tta_settings
from projects.synthdet.checkpoint import CheckpointError, load_model_weights
from projects.synthdet.inference.fragments import fragment_rule_from_config, merge_fragments
from projects.synthdet.inference.windows import Detections, WindowSpec, detect_in_windows
from synthdet.contracts import PREDICTIONS_FORMAT, SchemaError, class_names
from synthdet.prepare import PreparedScan


def load_model(cfg: Config, checkpoint: str, device: str, tta: bool = False) -> torch.nn.Module:
    """The config's model with the checkpoint's weights, loaded weights-only; with ``tta``
    wrapped in the config's ``tta_model`` and predicting through its ``tta_pipeline``
    (test-time augmentation, as ``tools/test.py --tta``).

    Raises :class:`CheckpointError` (naming the file) for a checkpoint that is refused, does not
    fit the model or names no classes, and ``TTAConfigError`` for ``tta`` with a config that
    has no test-time augmentation.
    """
    tta_model, tta_pipeline = tta_settings(cfg) if tta else (None, None)
    model = init_model(cfg, None, device=device)
    meta = load_model_weights(model, checkpoint)
    if not isinstance(meta.get('dataset_meta'), dict) or 'classes' not in meta['dataset_meta']:
        raise CheckpointError(f'{checkpoint}: the checkpoint\'s meta names no classes '
                              '(dataset_meta)')
    model.dataset_meta = dict(meta['dataset_meta'],
                              classes=checkpoint_classes(model, meta, checkpoint))
    if not tta:
        return model
    wrapper = MODELS.build(dict(tta_model, module=model))
    wrapper.cfg = copy.deepcopy(model.cfg)  # mmdet3d's inference_detector runs its test pipeline
    wrapper.cfg.test_dataloader.dataset.pipeline = tta_pipeline
    wrapper.dataset_meta = model.dataset_meta
    return wrapper.eval()


def checkpoint_classes(model: torch.nn.Module, meta: dict, checkpoint: str) -> list[str]:
    """The class names of a checkpoint's ``meta.dataset_meta.classes``, one per class the
    model's head predicts; :class:`CheckpointError` naming the file otherwise (a string, a
    name of thousands of characters, fewer names than the head has classes)."""
    try:
        classes = class_names(meta['dataset_meta']['classes'], checkpoint,
                              'meta.dataset_meta.classes')
    except SchemaError as error:
        raise CheckpointError(str(error)) from None
    head = getattr(model, 'bbox_head', None)
    predicted = getattr(head, 'num_classes', len(classes))
    if len(classes) != predicted:
        raise CheckpointError(f'{checkpoint}: meta.dataset_meta.classes: {len(classes)} class '
                              f'names for a model that predicts {predicted} classes')
    return classes


class ModelDetector:
    """``detector(points) -> Detections`` for an initialised mmdet3d model.

    Every call reseeds the point sampling with ``seed``, so a scan (or a window) gives the same
    detections whatever was detected before it. Boxes scoring below ``score_thr`` are dropped.
    :meth:`detect` merges the fragments of one object (the config's ``fragment_merge``,
    ``inference/fragments.py``) among the boxes scoring at least ``fragment_thr`` (default
    ``score_thr``: the boxes the user gets).
    """

    def __init__(self,
                 model: torch.nn.Module,
                 score_thr: float,
                 seed: int = 0,
                 fragment_thr: float | None = None):
        self.model = model
        self.score_thr = score_thr
        self.seed = seed
        self.fragment_thr = score_thr if fragment_thr is None else fragment_thr
        self.fragment_rule = fragment_rule_from_config(model.cfg)

    @property
    def classes(self) -> list[str]:
        return list(self.model.dataset_meta['classes'])

    @property
    def iou_thr(self) -> float:
        """The NMS threshold of the model's head, used to merge windows alike."""
        return float(self.model.cfg.model.test_cfg.iou_thr)

    def __call__(self, points: np.ndarray) -> Detections:
        shift = points[:, :3].min(axis=0)
        shifted = points.astype(np.float32)
        shifted[:, :3] = points[:, :3] - shift
        set_random_seed(self.seed)
        result, _ = inference_detector(self.model, shifted)
        pred = result.pred_instances_3d
        keep = pred.scores_3d >= self.score_thr
        boxes = pred.bboxes_3d[keep]
        centres = boxes.gravity_center.cpu().numpy().astype(np.float64) + shift
        dims = boxes.dims.cpu().numpy().astype(np.float64)
        yaws = boxes.yaw.cpu().numpy().astype(np.float64)[:, None]
        scores = pred.scores_3d[keep].cpu().numpy().astype(np.float64)
        labels = pred.labels_3d[keep].cpu().numpy().astype(np.int64)
        order = np.argsort(-scores, kind='stable')
        return Detections(np.hstack([centres, dims, yaws])[order], scores[order], labels[order])

    def detect(self, points: np.ndarray, spec: WindowSpec, progress: bool = True) -> Detections:
        """Detect in ``points`` by windows of ``spec`` (one window for a room-sized scan), with
        the fragments of one object merged."""
        detections, _ = detect_in_windows(points, self, spec, self.iou_thr, progress)
        if self.fragment_rule is None:
            return detections
        return merge_fragments(detections, self.classes, self.fragment_rule, self.fragment_thr)

    def predictions(self,
                    prepared: PreparedScan,
                    spec: WindowSpec,
                    model_name: str,
                    progress: bool = True) -> dict:
        """The ``synthdet.predictions/1`` document of a prepared scan, detected by windows."""
        return {
            'format': PREDICTIONS_FORMAT,
            'scan': prepared.source,
            'model': model_name,
            'classes': self.classes,
            'detections': self.detect_scan(prepared, spec, progress),
        }

    def detect_scan(self,
                    prepared: PreparedScan,
                    spec: WindowSpec,
                    progress: bool = True) -> list[dict]:
        """Detect in a prepared scan by windows; the ``synthdet.predictions/1`` detections in
        the scan's own coordinates (centres moved back exactly, yaws turned by the scan's)."""
        found = self.detect(prepared.points, spec, progress)
        centres, sizes, yaws = prepared.boxes_to_scan(found.boxes[:, :3], found.boxes[:, 3:6],
                                                      found.boxes[:, 6])
        classes = self.classes
        return [{
            'class': classes[label],
            'score': round(float(score), 6),
            'center': [round(float(v), 6) for v in centre],
            'size': [round(float(v), 6) for v in size],
            'yaw': round(float(yaw), 6),
        } for label, score, centre, size, yaw in zip(found.labels, found.scores, centres, sizes,
                                                     yaws)]
