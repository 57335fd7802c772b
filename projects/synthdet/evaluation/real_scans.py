"""The evaluation of labelled real scans: a user's scans, their truth, and what a model finds.

A labelled scan is a scan file ``X.<suffix>`` (any format of ``synthdet.scan_io``) with its
truth ``X.labels.json`` beside it (``synthdet.labels/1``: boxes in the scan's own coordinates,
``size`` the full extents before the turn ``yaw`` about z). Each scan takes exactly the path of
``tools/predict.py``: ``load_scan``, ``prepare_scan`` (resampled to the config's training
density), detection window by window through the config's test pipeline
(``projects.synthdet.inference``); the detections come back in the scan's own coordinates.

Counting rule (the paper's Table 4, with rotated boxes), per scan and class: detections scoring
at least the score threshold are taken in order of decreasing score; each is matched to the not
yet matched true box of its class with which it has the highest 3D IoU of the boxes turned by
their yaws (``projects.synthdet.core.rotated_iou``, on any device). It is *found* (a true
positive) at IoU >= 0.25, otherwise
*false*. Only the classes the labels file lists count: a class missing from its ``classes`` is
unknown in that scan, and its detections there are neither found nor false. A false YuMi or 3D
printer (in a scan listing those classes) is a *phantom*.

The figures: per scan and in total a Table-4 layout (columns the model's classes, YuMi and 3D
printer always shown; cells ``truth found(false)``, ``-`` for a class the scan does not list),
recall per class at IoU 0.25, false positives per room (all counted classes), phantoms, and the
average precision per class at IoU 0.25 and 0.5 over the folder, as ``IndoorMetric`` computes it
(the detections of all scans by decreasing score, each taking the true box it overlaps most, a
true positive if that box is not yet taken; mmdet3d's ``average_precision`` of the
precision-recall curve) on the rotated boxes, with every detection the model keeps after its
own score threshold and NMS; mAP is the mean over the classes with at least one true box.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np
import torch
from mmdet3d.evaluation.functional.indoor_eval import average_precision
from mmengine.config import Config

from projects.synthdet.core.rotated_iou import box_tensor
from projects.synthdet.core.rotated_iou import rotated_iou_3d as rotated_iou_tensor
from projects.synthdet.inference.detector import ModelDetector, load_model
from projects.synthdet.inference.windows import inference_settings
from synthdet.contracts import (LABELS_SUFFIX, labels_path, read_labels, write_json_atomic,
                                write_predictions, write_text_atomic)
from synthdet.prepare import PreparedScan, prepare_scan
from synthdet.room_data import Box, Scan
from synthdet.scan_io import SCAN_SUFFIXES, load_scan

REAL_SCANS_FORMAT = 'synthdet.real_scans/1'
IOU_THR = 0.25
MAP_IOU_THRS = (0.25, 0.5)
# classes that are always shown; their false detections are the phantoms
PHANTOM_CLASSES = ('yumi', '3dprinter')


class LabelsError(ValueError):
    """A scan, labels file or folder that cannot be evaluated; the message names the file."""


@dataclass(frozen=True)
class LabelledScan:
    """A scan file and its validated ``synthdet.labels/1`` document."""

    scan: Path
    labels: dict


def _labelled(scan: Path) -> LabelledScan:
    try:
        return LabelledScan(scan, read_labels(labels_path(scan)))
    except ValueError as error:  # SchemaError: names the labels file (and line)
        raise LabelsError(str(error)) from None


def find_labelled_scans(paths: Iterable[str | os.PathLike]) -> tuple[list[LabelledScan],
                                                                    list[str]]:
    """The labelled scans of ``paths`` (scan files, or folders: every scan file in them) and
    one line for each scan of a folder skipped for want of a labels file (and each labels file
    without a scan).

    Raises :class:`LabelsError` for a named scan without labels, a path that does not exist, a
    folder without any labelled scan, an invalid labels file, or two scans of one name.
    """
    found: list[LabelledScan] = []
    skipped: list[str] = []
    for path in map(Path, paths):
        if path.is_dir():
            scans = sorted(p for p in path.iterdir()
                           if p.is_file() and p.suffix.lower() in SCAN_SUFFIXES)
            labelled = [scan for scan in scans if labels_path(scan).is_file()]
            if not labelled:
                raise LabelsError(f'{path}: no scan with a <scan stem>{LABELS_SUFFIX} beside it')
            skipped += [
                f'{scan}: no {labels_path(scan).name} beside it, skipped' for scan in scans
                if scan not in labelled
            ]
            stems = {scan.stem for scan in scans}
            skipped += [
                f'{labels}: no scan {labels.name[:-len(LABELS_SUFFIX)]}.* beside it, skipped'
                for labels in sorted(path.glob(f'*{LABELS_SUFFIX}'))
                if labels.name[:-len(LABELS_SUFFIX)] not in stems
            ]
            found += [_labelled(scan) for scan in labelled]
        elif path.is_file():
            if not labels_path(path).is_file():
                raise LabelsError(f'{path}: no labels file {labels_path(path)} beside it')
            found.append(_labelled(path))
        else:
            raise LabelsError(f'{path}: no such scan or folder')
    seen: dict[str, Path] = {}
    for item in found:
        other = seen.setdefault(item.scan.stem, item.scan)
        if other != item.scan:
            raise LabelsError(f'{item.scan} and {other} have the same name: their labels and '
                              'outputs would be the same files; evaluate them separately')
    return found, skipped


# --------------------------------------------------------------------------- counting


def box_array(items: Sequence[dict]) -> np.ndarray:
    """``(K, 7)`` boxes ``x y z dx dy dz yaw`` (gravity centres) of contract box dicts."""
    return box_tensor(items).numpy()


def rotated_iou_3d(boxes_a: np.ndarray,
                   boxes_b: np.ndarray,
                   device: str | torch.device = 'cpu') -> np.ndarray:
    """``(N, M)`` 3D IoU of ``(N, 7)`` and ``(M, 7)`` gravity-centre boxes turned by their yaw
    (counter-clockwise about z), computed on ``device``."""
    tensors = (torch.as_tensor(np.asarray(b, dtype=np.float64).reshape(-1, 7), device=device)
               for b in (boxes_a, boxes_b))
    return rotated_iou_tensor(*tensors).cpu().numpy()


def assign_greedy(truth: np.ndarray, detections: np.ndarray, iou_thr: float = IOU_THR,
                  device: str | torch.device = 'cpu') -> np.ndarray:
    """The true box ``(M, 7)`` each of ``detections`` ``(N, 7)`` takes, in their order (of
    decreasing score): the unmatched one it overlaps most, at IoU >= ``iou_thr``; -1 for none."""
    taken = np.full(len(detections), -1, dtype=np.int64)
    if len(truth) == 0 or len(detections) == 0:
        return taken
    ious = rotated_iou_3d(detections, truth, device)
    matched = np.zeros(len(truth), dtype=bool)
    for index, row in enumerate(ious):
        candidates = np.where(matched, -1.0, row)
        best = int(np.argmax(candidates))
        if candidates[best] >= iou_thr:
            matched[best] = True
            taken[index] = best
    return taken


def match_greedy(truth: np.ndarray, detections: np.ndarray, iou_thr: float = IOU_THR,
                 device: str | torch.device = 'cpu') -> np.ndarray:
    """Which of ``detections`` ``(N, 7)``, in order of decreasing score, are found
    (:func:`assign_greedy`)."""
    return assign_greedy(truth, detections, iou_thr, device) >= 0


def table_classes(model_classes: Sequence[str]) -> list[str]:
    """The columns: the model's classes, then the phantom classes it does not predict."""
    return list(model_classes) + [c for c in PHANTOM_CLASSES if c not in model_classes]


def count_scan(labels: dict,
               detections: Sequence[dict],
               classes: Sequence[str],
               score_thr: float,
               iou_thr: float = IOU_THR) -> dict:
    """One scan's row: per column class ``{"truth", "found", "false"}`` or ``None`` when the
    labels do not list the class; ``detections`` are ``synthdet.predictions/1`` dicts."""
    cells: dict[str, dict | None] = {}
    for name in classes:
        if name not in labels['classes']:
            cells[name] = None
            continue
        truth = box_array([b for b in labels['boxes'] if b['class'] == name])
        mine = sorted((d for d in detections if d['class'] == name and d['score'] >= score_thr),
                      key=lambda d: -d['score'])
        found = int(match_greedy(truth, box_array(mine), iou_thr).sum())
        cells[name] = {'truth': len(truth), 'found': found, 'false': len(mine) - found}
    return {
        'cells': cells,
        'false_positives': sum(c['false'] for c in cells.values() if c),
        'phantoms': sum(cells[c]['false'] for c in PHANTOM_CLASSES if cells.get(c)),
    }


def average_precisions(entries: Sequence[tuple[dict, Sequence[dict]]],
                       classes: Sequence[str],
                       iou_thrs: Sequence[float] = MAP_IOU_THRS) -> dict[str, dict[str, float]]:
    """``{"0.25": {class: AP}, ...}`` over scans ``(labels, detections)`` for the classes with
    a true box in some scan; a scan counts for a class only if its labels list it. Each
    detection, by decreasing score over all scans, takes the true box of its scan it overlaps
    most; it is a true positive at IoU >= the threshold if no higher-scoring one took that box
    (``IndoorMetric``'s rule)."""
    aps: dict[str, dict[str, float]] = {f'{thr:g}': {} for thr in iou_thrs}
    for name in classes:
        listed = [(labels, detections) for labels, detections in entries
                  if name in labels['classes']]
        truth = [box_array([b for b in labels['boxes'] if b['class'] == name])
                 for labels, _ in listed]
        total = sum(len(t) for t in truth)
        if total == 0:
            continue
        scores, scans, overlaps = [], [], []
        for index, (_, detections) in enumerate(listed):
            mine = [d for d in detections if d['class'] == name]
            ious = rotated_iou_3d(box_array(mine), truth[index])
            scores += [d['score'] for d in mine]
            scans += [index] * len(mine)
            overlaps += list(ious)
        order = np.argsort(-np.asarray(scores, dtype=np.float64), kind='stable')
        for thr in iou_thrs:
            taken = [np.zeros(len(t), dtype=bool) for t in truth]
            hits = np.zeros(len(order))
            for rank, detection in enumerate(order):
                row = overlaps[detection]
                if len(row) == 0:
                    continue
                best = int(np.argmax(row))
                if row[best] >= thr and not taken[scans[detection]][best]:
                    taken[scans[detection]][best] = True
                    hits[rank] = 1.0
            true_positives = np.cumsum(hits)
            recall = true_positives / total
            precision = true_positives / np.maximum(np.arange(1, len(order) + 1), 1)
            aps[f'{thr:g}'][name] = float(average_precision(recall, precision)[0])
    return aps


def _ratio(numerator: float, denominator: float) -> float | None:
    return numerator / denominator if denominator else None


def evaluate_detections(entries: Sequence[tuple[str, dict, Sequence[dict]]],
                        model_classes: Sequence[str],
                        score_thr: float,
                        iou_thr: float = IOU_THR) -> dict:
    """All figures (module doc) from ``(scan name, labels, detections)`` triples, where the
    detections are every box the model keeps (the counting takes those >= ``score_thr``)."""
    classes = table_classes(model_classes)
    rows = []
    for name, labels, detections in entries:
        rows.append({'scan': name, **count_scan(labels, detections, classes, score_thr,
                                                iou_thr)})
    total: dict[str, dict | None] = {}
    for name in classes:
        cells = [row['cells'][name] for row in rows if row['cells'][name] is not None]
        total[name] = {key: sum(c[key] for c in cells)
                       for key in ('truth', 'found', 'false')} if cells else None
    truth = sum(c['truth'] for c in total.values() if c)
    found = sum(c['found'] for c in total.values() if c)
    false = sum(row['false_positives'] for row in rows)
    aps = average_precisions([(labels, dets) for _, labels, dets in entries], classes)
    return {
        'format': REAL_SCANS_FORMAT,
        'score_thr': score_thr,
        'iou_thr': iou_thr,
        'classes': classes,
        'rooms': len(rows),
        'scans': rows,
        'total': total,
        'recall': {
            name: _ratio(cell['found'], cell['truth']) if cell else None
            for name, cell in total.items()
        },
        'overall_recall': _ratio(found, truth),
        'found': found,
        'truth': truth,
        'false_positives': false,
        'false_positives_per_room': _ratio(false, len(rows)),
        'phantoms': sum(row['phantoms'] for row in rows),
        'ap': aps,
        'map': {thr: (float(np.mean(list(per_class.values()))) if per_class else None)
                for thr, per_class in aps.items()},
    }


# --------------------------------------------------------------------------- text


def _number(value: float | None, digits: int = 3) -> str:
    return 'n/a' if value is None else f'{value:.{digits}f}'


def summary_line(result: dict) -> str:
    """``real scans: recall R at IoU 0.25, F false positives per room, P phantom yumi/3d
    printer (N rooms)``."""
    return (f'real scans: recall {_number(result["overall_recall"])} at IoU '
            f'{result["iou_thr"]:g}, {_number(result["false_positives_per_room"], 2)} false '
            f'positives per room, {result["phantoms"]} phantom yumi/3d printer '
            f'({result["rooms"]} rooms)')


def format_result(result: dict) -> str:
    """The figures as aligned text: the Table-4 layout, recall and AP per class, the summary."""
    classes = result['classes']
    width = max([11] + [len(c) + 2 for c in classes])
    label = max([16] + [len(row['scan']) + 2 for row in result['scans']])

    def cell(value: dict | None) -> str:
        return '-' if value is None else f'{value["truth"]} {value["found"]}({value["false"]})'

    def line(name: str, values: Iterable[str]) -> str:
        return name.ljust(label) + ''.join(v.rjust(width) for v in values)

    lines = [
        f'cells: truth found(false), found at 3D IoU >= {result["iou_thr"]:g} of rotated boxes, '
        f'score >= {result["score_thr"]:g}; - the scan does not list the class',
        line('scan', classes)
    ]
    lines += [line(row['scan'], (cell(row['cells'][c]) for c in classes))
              for row in result['scans']]
    lines.append(line('total', (cell(result['total'][c]) for c in classes)))
    lines.append(line(f'recall@{result["iou_thr"]:g}',
                      (_number(result['recall'][c]) for c in classes)))
    for thr, per_class in result['ap'].items():
        lines.append(line(f'AP@{thr}', (_number(per_class.get(c)) for c in classes)))
    maps = ', '.join(f'mAP@{thr} {_number(value)}' for thr, value in result['map'].items())
    lines.append(f'{maps} (classes with a true box: '
                 f'{", ".join(result["ap"][next(iter(result["ap"]))]) or "none"})')
    lines.append(f'found {result["found"]} of {result["truth"]} objects, '
                 f'{result["false_positives"]} false positives')
    lines.append(summary_line(result))
    return '\n'.join(lines)


# --------------------------------------------------------------------------- the model


def draw_scan(out: Path, prepared: PreparedScan, labels: dict, detections: Sequence[dict],
              score_thr: float, title: str) -> None:
    """A top view (``synthdet.topview.draw_top_view``) of the prepared scan in the scan's own
    coordinates: the labelled boxes solid, the detections >= ``score_thr`` dashed."""
    from synthdet.topview import draw_top_view

    points = prepared.points.copy()
    points[:, :3] = prepared.points_to_scan(prepared.points[:, :3])
    truth = [Box(b['class'], tuple(b['center']), tuple(b['size']), b['yaw'])
             for b in labels['boxes']]
    shown = [Box(d['class'], tuple(d['center']), tuple(d['size']), d['yaw'], d['score'])
             for d in detections if d['score'] >= score_thr]
    draw_top_view(out, Scan(points, None, prepared.source), truth, shown, title=title)


def evaluate_scans(cfg: Config,
                   model: torch.nn.Module | str | os.PathLike,
                   scans: Sequence[LabelledScan],
                   out_dir: str | os.PathLike,
                   *,
                   score_thr: float = 0.3,
                   seed: int = 0,
                   voxel: float | None = None,
                   columns: str | None = None,
                   device: str = 'cpu',
                   tta: bool = False,
                   model_name: str | None = None,
                   report: Callable[[str], None] = print) -> dict:
    """Detect in every labelled scan as ``tools/predict.py`` does and count (module doc).

    ``model`` is a loaded detector (``inference.detector.load_model``) or a checkpoint, then
    loaded on ``device`` (with ``tta``). Writes into ``out_dir`` per scan ``<stem>.pred.json``
    (the detections >= ``score_thr``, as predict writes them) and ``<stem>.png`` (the top view),
    and ``real_scans.json`` / ``real_scans.txt`` with all figures; returns the figures.
    Raises ``ValueError`` naming the config for one without inference settings.
    """
    config = cfg.filename or '<config>'
    spec, density = inference_settings(cfg, config)
    if isinstance(model, (str, os.PathLike)):
        model = load_model(cfg, os.fspath(model), device, tta)
    model_name = model_name or Path(config).stem
    # every box the model keeps (the APs need them); fragments merged among those counted
    detector = ModelDetector(model, 0.0, seed, fragment_thr=score_thr)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = []
    for item in scans:
        prepared = prepare_scan(
            load_scan(item.scan, voxel=voxel, columns=columns), target_density=density,
            seed=seed)
        for line in prepared.report:
            report(f'{item.scan.name}: {line}')
        try:
            document = detector.predictions(prepared, spec, model_name, progress=False)
        except ValueError as error:
            raise RuntimeError(f'{item.scan}: {error}') from None
        detections = document['detections']
        kept = [d for d in detections if d['score'] >= score_thr]
        write_predictions(out_dir / f'{item.scan.stem}.pred.json',
                          {**document, 'detections': kept})
        row = count_scan(item.labels, detections, table_classes(detector.classes), score_thr)
        found = sum(c['found'] for c in row['cells'].values() if c)
        truth = sum(c['truth'] for c in row['cells'].values() if c)
        picture = out_dir / f'{item.scan.stem}.png'
        draw_scan(picture, prepared, item.labels, detections, score_thr,
                  f'{item.scan.name}: truth (solid), detections >= {score_thr:g} (dashed); '
                  f'found {found} of {truth}, {row["false_positives"]} false')
        report(f'{item.scan.name}: {len(kept)} detections >= {score_thr:g}, found {found} of '
               f'{truth}, {row["false_positives"]} false -> {picture}')
        entries.append((item.scan.name, item.labels, detections))
    result = evaluate_detections(entries, detector.classes, score_thr)
    result['model'] = model_name
    write_json_atomic(out_dir / 'real_scans.json', result, indent=1)
    write_text_atomic(out_dir / 'real_scans.txt', format_result(result) + '\n')
    return result
