"""The paper's Table 4: per scan, true objects and correct (incorrect) detections per class.

Usage: python tools/count_table.py PRED... [--infos PKL...] [--scan-root DIR]
                                   [--score-thr 0.3] [--iou-thr 0.25] [--out table4.json]

PRED are ``<scan>.pred.json`` files (``synthdet.predictions/1``, from tools/predict.py) or
directories holding them; files of several models (their ``"model"`` field) give one row per
model, as the paper compares Baseline and TR3D-sd. Ground truth comes from
- ``--infos`` info pickles (``s3dis_infos_Area_N.pkl``): a scan is the converted points file
  of the same name (predict on ``data/s3dis/points/Area_N_<room>.bin``, the pickle's frame), or
- otherwise the generator's ``meta.json`` next to the scan (``Area_N/<room>/<room>.txt``), in the
  raw room frame; its oriented boxes are replaced by their axis-aligned enclosing boxes, the
  convention of the S3DIS detection ground truth that the axis-aligned TR3D is trained on.

Counting rule, per scan and class: detections with score >= --score-thr are taken in order of
decreasing score; each is matched to the not yet matched true box of its class with which it has
the highest 3D IoU (mmdet3d's DepthInstance3DBoxes.overlaps, the IoU of IndoorMetric). It is
correct if that IoU is >= --iou-thr, otherwise incorrect (a duplicate of a matched object is
incorrect). Cells read ``correct(incorrect)``; '-' marks a class the model does not predict.
"""
import argparse
import json
import pickle
import sys
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))

import torch  # noqa: E402
from mmdet3d.structures import DepthInstance3DBoxes  # noqa: E402

from synthdet.classes import DETECTION_CLASSES  # noqa: E402

PREDICTIONS_FORMAT = 'synthdet.predictions/1'
ROOM_FORMAT = 'synthdet.room/1'
TABLE4_FORMAT = 'synthdet.table4/1'


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description="The paper's Table 4 from predictions.")
    parser.add_argument('predictions', nargs='+', help='.pred.json files or directories')
    parser.add_argument('--infos', nargs='+', help='info pickles holding the ground truth')
    parser.add_argument(
        '--scan-root', default='.', help='directory that relative "scan" paths are relative to')
    parser.add_argument('--score-thr', type=float, default=0.3)
    parser.add_argument('--iou-thr', type=float, default=0.25)
    parser.add_argument('--out', help='write the table as JSON (synthdet.table4/1)')
    return parser.parse_args(argv)


def load_predictions(paths: list[str]) -> list[dict]:
    """Read ``.pred.json`` files (directories are searched for ``*.pred.json``)."""
    files: list[Path] = []
    for path in map(Path, paths):
        found = sorted(path.glob('*.pred.json')) if path.is_dir() else [path]
        if not found:
            raise SystemExit(f'{path}: no *.pred.json files')
        files += found
    documents = []
    for file in files:
        document = json.loads(file.read_text())
        if document.get('format') != PREDICTIONS_FORMAT:
            raise SystemExit(f'{file}: format {document.get("format")!r} is not '
                             f'{PREDICTIONS_FORMAT!r}')
        document['_file'] = str(file)
        documents.append(document)
    return documents


def boxes_from_info(info: dict, categories: dict[str, int]) -> list[tuple[str, list[float]]]:
    """``(class, [cx, cy, cz, dx, dy, dz])`` of one info-pickle sample's instances."""
    names = {label: name for name, label in categories.items()}
    return [(names[inst['bbox_label_3d']], [float(v) for v in inst['bbox_3d'][:6]])
            for inst in info.get('instances', []) if inst['bbox_label_3d'] in names]


def truth_from_infos(paths: list[str]) -> dict[str, list[tuple[str, list[float]]]]:
    """Map points file name (e.g. ``Area_9_lab_3.bin``) to its true boxes."""
    truth = {}
    for path in paths:
        with open(path, 'rb') as f:
            infos = pickle.load(f)
        categories = infos.get('metainfo', {}).get('categories') or {
            name: i
            for i, name in enumerate(DETECTION_CLASSES)
        }
        for info in infos['data_list']:
            truth[Path(info['lidar_points']['lidar_path']).name] = boxes_from_info(
                info, categories)
    return truth


def truth_from_meta(meta_path: Path) -> list[tuple[str, list[float]]]:
    """Axis-aligned enclosing boxes ``(class, [cx, cy, cz, dx, dy, dz])`` of a ``meta.json``."""
    meta = json.loads(meta_path.read_text())
    if meta.get('format') != ROOM_FORMAT:
        raise SystemExit(f'{meta_path}: format {meta.get("format")!r} is not {ROOM_FORMAT!r}')
    boxes = []
    for obj in meta['objects']:
        if obj['class'] not in DETECTION_CLASSES:
            continue
        box = obj['box']
        cos, sin = abs(np.cos(box['yaw'])), abs(np.sin(box['yaw']))
        size_x, size_y, size_z = box['size']
        extent = [cos * size_x + sin * size_y, sin * size_x + cos * size_y, size_z]
        boxes.append((obj['class'], [*map(float, box['center']), *map(float, extent)]))
    return boxes


def _depth_boxes(boxes: list[list[float]], yaws: list[float]) -> DepthInstance3DBoxes:
    """Gravity-centre boxes ``[cx, cy, cz, dx, dy, dz]`` with yaws as mmdet3d depth boxes."""
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
    ious = DepthInstance3DBoxes.overlaps(pred, gt).numpy()
    matched = np.zeros(len(truth), dtype=bool)
    correct = 0
    for row in ious:
        candidates = np.where(matched, -1.0, row)
        best = int(np.argmax(candidates))
        if candidates[best] >= iou_thr:
            matched[best] = True
            correct += 1
    return correct, len(detections) - correct


def count_table(documents: list[dict], truth_of: dict[str, list], score_thr: float,
                iou_thr: float) -> dict:
    """Build the Table 4 document from prediction documents and ``{scan: true boxes}``."""
    models = list(dict.fromkeys(d['model'] for d in documents))
    known = {m: set() for m in models}
    for d in documents:
        known[d['model']].update(d['classes'])
    classes = [c for c in DETECTION_CLASSES if any(c in k for k in known.values())]
    scans: dict[str, dict] = {}
    for d in documents:
        row = scans.setdefault(d['_key'], {'scan': d['scan'], 'truth': {}, 'models': {}})
        boxes = truth_of[d['_key']]
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


def format_count_table(table: dict) -> str:
    """Render the Table 4 document as aligned text."""
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


def main(argv: list[str] | None = None) -> dict:
    """Load predictions and ground truth, print Table 4 and optionally write its JSON."""
    args = parse_args(argv)
    documents = load_predictions(args.predictions)
    truth_of: dict[str, list] = {}
    infos = truth_from_infos(args.infos) if args.infos else None
    for d in documents:
        scan = Path(d['scan'])
        if infos is not None:
            d['_key'] = scan.name
            if scan.name not in infos:
                raise SystemExit(f'{d["_file"]}: scan {scan.name} is in none of the info pickles '
                                 f'{args.infos}')
            truth_of[d['_key']] = infos[scan.name]
        else:
            path = scan if scan.is_absolute() else Path(args.scan_root) / scan
            meta_path = path.parent / 'meta.json'
            if not meta_path.is_file():
                raise SystemExit(f'{d["_file"]}: no ground truth for scan {scan}: {meta_path} '
                                 'does not exist (pass --infos for converted scans)')
            d['_key'] = str(path.resolve())
            truth_of.setdefault(d['_key'], truth_from_meta(meta_path))
    table = count_table(documents, truth_of, args.score_thr, args.iou_thr)
    print(f'Table 4 (score >= {args.score_thr}, IoU >= {args.iou_thr}): true objects per scan, '
          'then correct(incorrect) detections per model')
    print(format_count_table(table))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(table, indent=2) + '\n')
        print(f'written to {args.out}')
    return table


if __name__ == '__main__':
    main()
