"""The paper's Table 4: per scan, true objects and correct (incorrect) detections per class.

Counting rule, per scan and class: detections with score >= the score threshold are taken in
order of decreasing score; each is matched to the not yet matched true box of its class with
which it has the highest 3D IoU (mmdet3d's ``DepthInstance3DBoxes.overlaps``, the IoU of
IndoorMetric). It is correct if that IoU is >= the IoU threshold, otherwise incorrect (a
duplicate of a matched object is incorrect). A class the model does not predict is ``None``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from synthdet.classes import DETECTION_CLASSES
from synthdet.info_files import InfoFileError, labelled_boxes

if TYPE_CHECKING:
    from mmdet3d.structures import DepthInstance3DBoxes

TABLE4_FORMAT = 'synthdet.table4/1'

# (class, [cx, cy, cz, dx, dy, dz]): an axis-aligned true box with its gravity centre
TrueBox = tuple[str, list[float]]


def truth_from_infos(paths: list[str]) -> dict[str, list[TrueBox]]:
    """Map points file name (e.g. ``Area_9_lab_3.bin``) to its true boxes; ``InfoFileError``
    naming the pickle for one that is not the converter's (``labelled_boxes``)."""
    truth = {}
    for path in paths:
        for index, (scan, boxes) in enumerate(labelled_boxes(path, DETECTION_CLASSES)):
            if scan is None:
                raise InfoFileError(f'{path}: data_list[{index}]: no "lidar_points"')
            try:
                truth[scan] = [(name, [float(v) for v in box[:6]]) for name, box in boxes]
            except (TypeError, ValueError):
                raise InfoFileError(f'{path}: {scan}: a bbox_3d that is not 6 or more '
                                    'numbers') from None
    return truth


def _depth_boxes(boxes: list[list[float]], yaws: list[float]) -> DepthInstance3DBoxes:
    """Gravity-centre boxes ``[cx, cy, cz, dx, dy, dz]`` with yaws as mmdet3d depth boxes
    (torch and mmdet3d load here, once there are boxes to match: the inputs are checked
    without them)."""
    import torch
    from mmdet3d.structures import DepthInstance3DBoxes
    tensor = torch.tensor([[*b, y] for b, y in zip(boxes, yaws)], dtype=torch.float32)
    return DepthInstance3DBoxes(tensor.reshape(-1, 7), origin=(0.5, 0.5, 0.5))


def count_class(truth: list[list[float]], detections: list[dict],
                iou_thr: float) -> tuple[int, int]:
    """``(correct, incorrect)`` for one class of one scan under the rule in the module doc."""
    if not detections:
        return 0, 0
    if not truth:
        return 0, len(detections)
    detections = sorted(detections, key=lambda d: -d['score'])
    pred = _depth_boxes([[*d['center'], *d['size']] for d in detections],
                        [d.get('yaw', 0.0) for d in detections])
    gt = _depth_boxes(truth, [0.0] * len(truth))
    ious = type(gt).overlaps(pred, gt).numpy()
    matched = np.zeros(len(truth), dtype=bool)
    correct = 0
    for row in ious:
        candidates = np.where(matched, -1.0, row)
        best = int(np.argmax(candidates))
        if candidates[best] >= iou_thr:
            matched[best] = True
            correct += 1
    return correct, len(detections) - correct


def table4(predictions: list[tuple[str, dict]], truth_of: dict[str, list[TrueBox]],
           score_thr: float, iou_thr: float) -> dict:
    """Table 4 as a JSON-able document from ``(scan key, predictions document)`` pairs and the
    true boxes of every scan key; one row per scan with a cell per model and class."""
    models = list(dict.fromkeys(d['model'] for _, d in predictions))
    known = {m: set() for m in models}
    for _, d in predictions:
        known[d['model']].update(d['classes'])
    classes = [c for c in DETECTION_CLASSES if any(c in k for k in known.values())]
    scans: dict[str, dict] = {}
    for key, d in predictions:
        row = scans.setdefault(key, {'scan': d['scan'], 'truth': {}, 'models': {}})
        boxes = truth_of[key]
        row['truth'] = {c: sum(name == c for name, _ in boxes) for c in classes}
        cells = {}
        for c in classes:
            if c not in d['classes']:
                cells[c] = None
                continue
            dets = [x for x in d['detections'] if x['class'] == c and x['score'] >= score_thr]
            correct, incorrect = count_class([b for name, b in boxes if name == c], dets, iou_thr)
            cells[c] = {'correct': correct, 'incorrect': incorrect}
        row['models'][d['model']] = cells
    return {
        'format': TABLE4_FORMAT,
        'score_thr': score_thr,
        'iou_thr': iou_thr,
        'classes': classes,
        'models': models,
        'scans': list(scans.values())
    }


def format_table4(table: dict) -> str:
    """A Table 4 document as aligned text: per scan the true objects, then
    ``correct(incorrect)`` per model; '-' marks a class the model does not predict."""
    classes, models = table['classes'], table['models']
    width = max(10, *(len(c) + 2 for c in classes))
    label = max(12, *(len(m) + 2 for m in models))
    lines = ['model'.ljust(label) + ''.join(c.rjust(width) for c in classes)]
    for row in table['scans']:
        lines.append(f'scan {row["scan"]}')
        lines.append('truth'.ljust(label) +
                     ''.join(str(row['truth'][c]).rjust(width) for c in classes))
        for model in models:
            if model not in row['models']:
                continue
            cells = row['models'][model]
            lines.append(
                model.ljust(label) + ''.join(
                    ('-' if cells[c] is None else f'{cells[c]["correct"]}({cells[c]["incorrect"]})'
                     ).rjust(width) for c in classes))
    return '\n'.join(lines)
