"""What the false positives of a test hit, per class (``tools/test.py --false-positives``).

Average precision drops when a prediction outranks true boxes without matching one. The
predictions are matched as mmdet3d's ``indoor_eval`` matches them (per class, by descending
score, each to the true box of its class it overlaps most, a true box at most once, a match
needing an IoU above the threshold), and every prediction left unmatched gets a cause:

- ``duplicate``: its best true box was already matched by a higher-scoring prediction;
- ``as <class>``: it overlaps a true box of another class by an IoU of at least 0.25;
- ``loose``: it overlaps a true box of its own class, by an IoU from 0.1 up to the threshold;
- ``score < S``: it scores below ``min_score`` (not looked into further);
- otherwise what the scan's points inside the box belong to: the annotation with the most of
  them (S3DIS's ``Annotations/<class>_<k>.txt``, found through the converter's instance mask),
  named by the generator's asset (``clutter/crate``) when the room has a ``meta.json``, else by
  its class (``clutter``, ``wall``); ``empty`` when no point of the scan lies in the box,
  ``unlabelled points`` when its points have no annotation.

Per class and threshold, :class:`SynthdetFalsePositives` reports the AP (mmdet3d's, the same
numbers as Table 3), and for each cause the number of its false positives and the AP the class
would have without them: what a model that never made that mistake could gain at most.
The scans are read from the converter's layout next to the prediction's ``lidar_path``
(``points/``, ``instance_mask/``, ``Stanford3dDataset_v1.2_Aligned_Version/Area_N/<room>/``).
"""
import math
from collections import Counter, defaultdict
from functools import cached_property
from pathlib import Path
from typing import Sequence

import numpy as np
from mmdet3d.evaluation.functional.indoor_eval import average_precision
from mmdet3d.registry import METRICS
from mmdet3d.structures import BaseInstance3DBoxes
from mmengine.evaluator import BaseMetric

from synthdet.contracts import read_room
from synthdet.info_files import RAW_DIR, InfoFileError, raw_room_dir
from synthdet.room_data import annotation_class, annotation_files

FALSE_POSITIVES_FORMAT = 'synthdet.false_positives/1'
IOU_THRESHOLDS = (0.25, 0.5)
CONFUSION_IOU = 0.25  # a prediction overlapping another class's true box this much is confused
LOOSE_IOU = 0.1  # ... its own class's true box this much, a loose box of it
MATCHED = 'matched'
SEPARATOR = '|'  # in metric keys: <class>|<threshold>|<cause>|<count or ap_without>


class ScanFiles:
    """The converted points, instance mask and annotation names of one scan; the points and
    the mask are read once, when a box is first looked into."""

    def __init__(self, lidar_path: str) -> None:
        self.path = Path(lidar_path)
        data_root = self.path.parent.parent
        self.mask_path = data_root / 'instance_mask' / self.path.name
        if not self.mask_path.is_file():
            raise InfoFileError(f'{self.mask_path}: no instance mask; --false-positives needs '
                                'the converter\'s instance_mask/ next to points/')
        room_dir = raw_room_dir(data_root, self.path.name)
        if room_dir is None or not (room_dir / 'Annotations').is_dir():
            raise InfoFileError(f'{room_dir / "Annotations" if room_dir else self.path}: no S3DIS '
                                f'Annotations folder for {self.path.name}; --false-positives '
                                f'needs the raw rooms in {data_root / RAW_DIR}')
        self.names = self._instance_names(room_dir)

    @cached_property
    def points(self) -> np.ndarray:
        """The scan's xyz (N, 3)."""
        return np.fromfile(self.path, dtype=np.float32).reshape(-1, 6)[:, :3]

    @cached_property
    def instances(self) -> np.ndarray:
        """The instance id of each point (0: none, k: the k-th annotation file)."""
        instances = np.fromfile(self.mask_path, dtype=np.int64)
        if len(instances) != len(self.points):
            raise InfoFileError(f'{self.mask_path}: {len(instances)} ids for '
                                f'{len(self.points)} points of {self.path}')
        return instances

    @staticmethod
    def _instance_names(room_dir: Path) -> list[str]:
        """Name of instance k + 1 at index k: the generator's asset of the annotation, or the
        annotation's class (the converter numbers the annotation files in this order)."""
        files = annotation_files(room_dir / 'Annotations')
        assets = {}
        if (room_dir / 'meta.json').is_file():
            room = read_room(room_dir / 'meta.json')
            assets = {o['instance']: o['asset'] for o in room['objects'] if 'asset' in o}
        return [assets.get(path.stem, annotation_class(path) or path.stem) for path in files]

    def content(self, center: np.ndarray, dims: np.ndarray, yaw: float) -> str:
        """What most of the scan's points inside the box (gravity centre, size, yaw) are."""
        reach = float(np.linalg.norm(dims[:2])) / 2
        near = np.flatnonzero(np.all(np.abs(self.points[:, :2] - center[:2]) <= reach, axis=1))
        local = self.points[near] - center
        cos, sin = math.cos(yaw), math.sin(yaw)
        x = local[:, 0] * cos + local[:, 1] * sin
        y = -local[:, 0] * sin + local[:, 1] * cos
        inside = near[(np.abs(x) <= dims[0] / 2) & (np.abs(y) <= dims[1] / 2)
                      & (np.abs(local[:, 2]) <= dims[2] / 2)]
        ids = self.instances[inside]
        ids = ids[(ids >= 1) & (ids <= len(self.names))]
        if len(ids) == 0:
            return 'empty' if len(inside) == 0 else 'unlabelled points'
        return self.names[int(np.bincount(ids).argmax()) - 1]


def match_scan(gt_boxes: BaseInstance3DBoxes, gt_labels: Sequence[int],
               pred_boxes: BaseInstance3DBoxes, pred_labels: Sequence[int],
               pred_scores: Sequence[float], iou_thr: float, min_score: float,
               scan: ScanFiles) -> list[str]:
    """The outcome of each prediction of one scan at ``iou_thr``: ``matched`` or its cause
    (see the module doc)."""
    gt_labels = np.asarray(gt_labels, dtype=np.int64).reshape(-1)
    pred_labels = np.asarray(pred_labels, dtype=np.int64).reshape(-1)
    pred_scores = np.asarray(pred_scores, dtype=np.float64).reshape(-1)
    if len(pred_labels) == 0:
        return []
    if len(gt_labels):
        ious = type(gt_boxes).overlaps(gt_boxes, pred_boxes.to(gt_boxes.device)).cpu().numpy()
    else:
        ious = np.zeros((0, len(pred_labels)))
    centers = pred_boxes.gravity_center.cpu().numpy()
    dims, yaws = pred_boxes.dims.cpu().numpy(), pred_boxes.yaw.cpu().numpy()
    outcomes = [''] * len(pred_labels)
    taken: set[int] = set()
    for j in np.argsort(-pred_scores, kind='stable'):
        same = np.where(gt_labels == pred_labels[j], ious[:, j], -1.0)
        other = np.where(gt_labels != pred_labels[j], ious[:, j], -1.0)
        best = int(same.argmax()) if len(same) else -1
        best_iou = same[best] if best >= 0 else -1.0
        if best_iou > iou_thr and best not in taken:
            taken.add(best)
            outcomes[j] = MATCHED
        elif best_iou > iou_thr:
            outcomes[j] = 'duplicate'
        elif len(other) and other.max() >= CONFUSION_IOU:
            outcomes[j] = f'as {int(gt_labels[other.argmax()])}'
        elif best_iou >= LOOSE_IOU:
            outcomes[j] = 'loose'
        elif pred_scores[j] < min_score:
            outcomes[j] = f'score < {min_score:g}'
        else:
            outcomes[j] = scan.content(centers[j], dims[j], float(yaws[j]))
    return outcomes


def class_precision(scores: np.ndarray,
                    outcomes: Sequence[str],
                    n_truth: int,
                    leave_out: str | None = None) -> float:
    """mmdet3d's AP ('area') of one class's predictions, optionally without one cause's."""
    keep = np.array([o != leave_out for o in outcomes], dtype=bool)
    order = np.argsort(-scores[keep], kind='stable')
    hits = (np.asarray(outcomes)[keep][order] == MATCHED).astype(np.float64)
    if n_truth == 0 or len(hits) == 0:
        return 0.0
    tp, fp = np.cumsum(hits), np.cumsum(1.0 - hits)
    precision = tp / np.maximum(tp + fp, np.finfo(np.float64).eps)
    return float(average_precision(tp / n_truth, precision, mode='area')[0])


def summarize(rows: list[tuple], n_truth: Counter, classes: Sequence[str]) -> dict[str, float]:
    """Flat results ``<class>|<thr>|AP`` and ``<class>|<thr>|<cause>|count`` / ``ap_without``
    from (label, score, threshold, outcome) rows; classes without true boxes are left out."""
    grouped = defaultdict(list)
    for label, score, thr, outcome in rows:
        grouped[label, thr].append((score, outcome))
    results = {}
    for label, name in enumerate(classes):
        if n_truth[label] == 0:
            continue
        for thr in IOU_THRESHOLDS:
            mine = grouped[label, thr]
            scores = np.array([score for score, _ in mine], dtype=np.float64)
            outcomes = [_named(outcome, classes) for _, outcome in mine]
            key = f'{name}{SEPARATOR}{thr:.2f}'
            results[f'{key}{SEPARATOR}AP'] = class_precision(scores, outcomes, n_truth[label])
            for cause, count in Counter(o for o in outcomes if o != MATCHED).items():
                results[f'{key}{SEPARATOR}{cause}{SEPARATOR}count'] = float(count)
                results[f'{key}{SEPARATOR}{cause}{SEPARATOR}ap_without'] = class_precision(
                    scores, outcomes, n_truth[label], leave_out=cause)
    return results


def _named(outcome: str, classes: Sequence[str]) -> str:
    """``as <label>`` with the label's class name."""
    return f'as {classes[int(outcome[3:])]}' if outcome.startswith('as ') else outcome


@METRICS.register_module()
class SynthdetFalsePositives(BaseMetric):
    """Per class and IoU threshold: the AP and, per cause of the false positives, their number
    and the AP without them (see the module doc); results are ``fp/<class>|<thr>|...``.

    Args:
        min_score: false positives scoring below it are not looked into (cause ``score < S``).
    """

    default_prefix = 'fp'

    def __init__(self, min_score: float = 0.1, **kwargs) -> None:
        super().__init__(**kwargs)
        self.min_score = min_score

    def process(self, data_batch: dict, data_samples: Sequence[dict]) -> None:
        for sample in data_samples:
            truth, pred = sample['eval_ann_info'], sample['pred_instances_3d']
            labels = pred['labels_3d'].cpu().numpy()
            scores = pred['scores_3d'].cpu().numpy()
            rows = []
            if len(labels):
                scan = ScanFiles(sample['lidar_path'])
                for thr in IOU_THRESHOLDS:
                    outcomes = match_scan(truth['gt_bboxes_3d'], truth['gt_labels_3d'],
                                          pred['bboxes_3d'], labels, scores, thr, self.min_score,
                                          scan)
                    rows += [(int(lab), float(score), thr, outcome)
                             for lab, score, outcome in zip(labels, scores, outcomes)]
            self.results.append((np.asarray(truth['gt_labels_3d']).tolist(), rows))

    def compute_metrics(self, results: list) -> dict[str, float]:
        n_truth = Counter(int(label) for truth, _ in results for label in truth)
        rows = [row for _, scan_rows in results for row in scan_rows]
        return summarize(rows, n_truth, self.dataset_meta['classes'])


def false_positives_document(metrics: dict, classes: Sequence[str], config: str, checkpoint: str,
                             test_set: str) -> dict:
    """The ``fp/`` results of a test as a JSON-able document: per class and threshold the AP and
    the causes, those whose removal gains the most AP first."""
    rows: dict = {}
    for key, value in metrics.items():
        if not key.startswith('fp/'):
            continue
        name, thr, *rest = key[3:].split(SEPARATOR)
        if name not in classes:
            continue
        entry = rows.setdefault(name, {}).setdefault(thr, {'AP': math.nan, 'causes': {}})
        if rest == ['AP']:
            entry['AP'] = float(value)
        else:
            entry['causes'].setdefault(rest[0], {})[rest[1]] = float(value)
    for per_thr in rows.values():
        for entry in per_thr.values():
            entry['causes'] = dict(
                sorted(
                    entry['causes'].items(),
                    key=lambda item: (-item[1]['ap_without'], -item[1]['count'], item[0])))
            for cause in entry['causes'].values():
                cause['count'] = int(cause['count'])
    return {
        'format': FALSE_POSITIVES_FORMAT,
        'config': config,
        'checkpoint': checkpoint,
        'test_set': test_set,
        'rows': {
            name: rows[name]
            for name in classes if name in rows
        },
    }


def format_false_positives(document: dict, causes_shown: int = 4) -> str:
    """A false-positives document as text: a line per class and threshold with its AP and the
    causes that cost it most, as ``cause count -> AP without``."""
    lines = []
    for name, per_thr in document['rows'].items():
        for thr, entry in per_thr.items():
            causes = list(entry['causes'].items())[:causes_shown]
            listed = ', '.join(f'{cause} {c["count"]} -> {c["ap_without"]:.3f}'
                               for cause, c in causes)
            lines.append(f'{name:<10} @{thr}  AP {entry["AP"]:.3f}  {listed or "none"}')
    return '\n'.join(lines)
