"""The paper's Table 3: average precision per class at 3D IoU 0.25 and 0.5, and their mean.

The numbers are mmdet3d's IndoorMetric results, with the paper's rule applied by the configs'
``SynthdetIndoorMetric`` (``indoor_metric.py``, built on :func:`without_classes`): a class
without ground truth in the test set has no AP and is left out of the mean. The table has a row
per IoU threshold and a column per class plus the mean; a class without an AP is ``None`` in the
JSON and "-" in the text, as in the paper.
"""
import math
from typing import Iterable, Sequence

TABLE3_FORMAT = 'synthdet.table3/1'
IOU_THRESHOLDS = (0.25, 0.5)


def without_classes(metrics: dict, classes: Iterable[str],
                    iou_thresholds: Iterable[float]) -> dict:
    """IndoorMetric results without the AP and recall of ``classes``; ``mAP_<thr>`` and
    ``mAR_<thr>`` become the means over the remaining classes (NaN if none remains)."""
    drop = set(classes)
    kept = {
        key: value
        for key, value in metrics.items() if not any(
            key.startswith(f'{name}_AP_') or key.startswith(f'{name}_rec_') for name in drop)
    }
    for thr in iou_thresholds:
        for kind, mean in (('AP', 'mAP'), ('rec', 'mAR')):
            values = [v for k, v in kept.items() if k.endswith(f'_{kind}_{thr:.2f}')]
            kept[f'{mean}_{thr:.2f}'] = sum(values) / len(values) if values else math.nan
    return kept


def table3_rows(metrics: dict,
                classes: Sequence[str],
                iou_thresholds: Sequence[float] = IOU_THRESHOLDS) -> dict[str, dict]:
    """Arrange IndoorMetric results as ``{'mAP@0.25': {class: AP, ..., 'mean': mAP}, ...}``.

    A class without an ``<class>_AP_<thr>`` entry (no ground truth in the test set) gets
    ``None``. Raises ``KeyError`` if the metrics lack the mean for a threshold.
    """
    rows = {}
    for thr in iou_thresholds:
        key = f'{thr:.2f}'
        if f'mAP_{key}' not in metrics:
            raise KeyError(f'IndoorMetric results have no mAP_{key}: {sorted(metrics)}')
        row = {name: metrics.get(f'{name}_AP_{key}') for name in classes}
        row['mean'] = metrics[f'mAP_{key}']
        rows[f'mAP@{thr:g}'] = {k: None if v is None else float(v) for k, v in row.items()}
    return rows


def table3(metrics: dict, classes: Sequence[str], config: str, checkpoint: str,
           test_set: str) -> dict:
    """Table 3 as a JSON-able document: the rows, the raw metrics and what was tested."""
    return {
        'format': TABLE3_FORMAT,
        'config': config,
        'checkpoint': checkpoint,
        'test_set': test_set,
        'classes': list(classes),
        'rows': table3_rows(metrics, classes),
        'metrics': {
            k: float(v)
            for k, v in metrics.items()
        },
    }


def format_table3(table: dict) -> str:
    """The rows of a Table 3 document as aligned text, '-' for missing classes."""
    rows = table['rows']
    columns = list(next(iter(rows.values())))
    width = max(9, *(len(c) + 1 for c in columns))
    lines = ['metric'.ljust(10) + ''.join(c.rjust(width) for c in columns)]
    for name, row in rows.items():
        cells = ('-' if row[c] is None else f'{row[c]:.3f}' for c in columns)
        lines.append(name.ljust(10) + ''.join(cell.rjust(width) for cell in cells))
    return '\n'.join(lines)
