"""How well the predicted boxes fit the true ones, per class (``tools/test.py --box-fit``).

Average precision says how many true boxes a model finds at an IoU threshold, not why it misses
the others. For every true box, :func:`best_fits` takes the prediction of its class with the
highest 3D IoU (mmdet3d's ``DepthInstance3DBoxes.overlaps``, the IoU of IndoorMetric), at any
score, and records that IoU, the prediction's size per axis as a ratio of the true size and the
distance between their centres. :class:`SynthdetBoxFit` (registered as a metric, prefix
``fit``) summarizes them per class: the median IoU, the share of true boxes whose best IoU is
below 0.25 and 0.5 (no prediction at all counts as IoU 0), and the median size ratios and
centre distance over the true boxes that have a prediction. A share below 0.5 of 0.4 caps the
recall at IoU 0.5 at 0.6, whatever the scores; size ratios far from 1 show a box that is too
small or too large along one axis, a large centre distance a box in the wrong place.
"""
import math
from typing import Sequence

import numpy as np
from mmdet3d.registry import METRICS
from mmdet3d.structures import BaseInstance3DBoxes
from mmengine.evaluator import BaseMetric

BOX_FIT_FORMAT = 'synthdet.box_fit/1'
BOX_FIT_THRESHOLDS = (0.25, 0.5)
# per true box: class index, best IoU, size ratio x / y / z (pred / truth), centre distance
FIT_FIELDS = ('label', 'iou', 'size_x', 'size_y', 'size_z', 'offset')
SUMMARY_COLUMNS = ('boxes', 'iou_median', *(f'below_{thr:.2f}' for thr in BOX_FIT_THRESHOLDS),
                   'size_x', 'size_y', 'size_z', 'offset')


def best_fits(gt_boxes: BaseInstance3DBoxes, gt_labels: Sequence[int],
              pred_boxes: BaseInstance3DBoxes, pred_labels: Sequence[int]) -> np.ndarray:
    """One row per true box (:data:`FIT_FIELDS`): its best-IoU prediction of the same class.

    A true box without a prediction of its class has IoU 0 and NaN ratios and distance.
    """
    gt_labels = np.asarray(gt_labels, dtype=np.int64).reshape(-1)
    pred_labels = np.asarray(pred_labels, dtype=np.int64).reshape(-1)
    rows = np.full((len(gt_labels), len(FIT_FIELDS)), np.nan)
    rows[:, 0], rows[:, 1] = gt_labels, 0.0
    if len(gt_labels) == 0 or len(pred_labels) == 0:
        return rows
    ious = type(gt_boxes).overlaps(gt_boxes, pred_boxes.to(gt_boxes.device)).cpu().numpy()
    ious[gt_labels[:, None] != pred_labels[None, :]] = -1.0
    best = ious.argmax(axis=1)
    found = ious[np.arange(len(gt_labels)), best] >= 0
    gt_dims, pred_dims = gt_boxes.dims.cpu().numpy(), pred_boxes.dims.cpu().numpy()[best]
    gt_centers = gt_boxes.gravity_center.cpu().numpy()
    pred_centers = pred_boxes.gravity_center.cpu().numpy()[best]
    rows[found, 1] = ious[np.arange(len(gt_labels)), best][found]
    rows[found, 2:5] = (pred_dims / gt_dims)[found]
    rows[found, 5] = np.linalg.norm(pred_centers - gt_centers, axis=1)[found]
    return rows


def summarize_fits(fits: np.ndarray, classes: Sequence[str]) -> dict[str, float]:
    """Flat per-class summary ``<class>_<column>`` (:data:`SUMMARY_COLUMNS`) of the rows of
    :func:`best_fits`; a class without true boxes is left out."""
    summary = {}
    for label, name in enumerate(classes):
        rows = fits[fits[:, 0] == label]
        if len(rows) == 0:
            continue
        found = rows[~np.isnan(rows[:, 2])]
        values = [len(rows), float(np.median(rows[:, 1]))]
        values += [float(np.mean(rows[:, 1] < thr)) for thr in BOX_FIT_THRESHOLDS]
        values += [float(np.median(found[:, k])) if len(found) else math.nan for k in range(2, 6)]
        summary.update({f'{name}_{column}': value
                        for column, value in zip(SUMMARY_COLUMNS, values)})
    return summary


@METRICS.register_module()
class SynthdetBoxFit(BaseMetric):
    """Per-class box fit of the test predictions (see the module doc); results are
    ``fit/<class>_<column>`` for the :data:`SUMMARY_COLUMNS`."""

    default_prefix = 'fit'

    def process(self, data_batch: dict, data_samples: Sequence[dict]) -> None:
        for sample in data_samples:
            truth, pred = sample['eval_ann_info'], sample['pred_instances_3d']
            self.results.append(
                best_fits(truth['gt_bboxes_3d'], truth['gt_labels_3d'], pred['bboxes_3d'],
                          pred['labels_3d'].cpu().numpy()))

    def compute_metrics(self, results: list) -> dict[str, float]:
        fits = np.concatenate(results) if results else np.zeros((0, len(FIT_FIELDS)))
        return summarize_fits(fits, self.dataset_meta['classes'])


def box_fit_document(metrics: dict, classes: Sequence[str], config: str, checkpoint: str,
                     test_set: str) -> dict:
    """The ``fit/`` results of a test as a JSON-able document, one row per class with boxes."""
    rows = {
        name: {column: metrics[f'fit/{name}_{column}'] for column in SUMMARY_COLUMNS}
        for name in classes if f'fit/{name}_boxes' in metrics
    }
    return {
        'format': BOX_FIT_FORMAT,
        'config': config,
        'checkpoint': checkpoint,
        'test_set': test_set,
        'rows': {
            name: {k: (None if math.isnan(v) else float(v)) for k, v in row.items()}
            for name, row in rows.items()
        },
    }


def format_box_fit(document: dict) -> str:
    """A box-fit document as aligned text: a row per class, '-' where nothing was predicted."""
    header = 'class'.ljust(11) + ''.join(c.rjust(11) for c in SUMMARY_COLUMNS)
    lines = [header]
    for name, row in document['rows'].items():
        cells = [f'{int(row["boxes"])}'] + [
            '-' if row[c] is None else f'{row[c]:.2f}' for c in SUMMARY_COLUMNS[1:]
        ]
        lines.append(name.ljust(11) + ''.join(cell.rjust(11) for cell in cells))
    return '\n'.join(lines)
