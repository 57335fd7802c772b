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

The counting rule is in ``projects/synthdet/evaluation/table4.py``. Cells read
``correct(incorrect)``; '-' marks a class the model does not predict. ``--out`` writes the
table as JSON (``synthdet.table4/1``) and as text next to it (``table4.txt``).

Bad input (an option out of range, a missing or invalid predictions file, info pickle or
``meta.json``) ends with one line naming it and exit code 2, before any counting; an output that
cannot be written with exit code 1.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from projects.synthdet.bootstrap import run_tool
from projects.synthdet.evaluation.table4 import (TrueBox, format_table4, table4,
                                                 truth_from_infos)
from projects.synthdet.evaluation.table_files import write_table
from synthdet.classes import DETECTION_CLASSES
from synthdet.cli import (InputFileError, OneLineParser, add_score_option, check_input_file,
                          float_in)
from synthdet.contracts import SchemaError, read_predictions, read_room
from synthdet.info_files import InfoFileError


class BadInput(ValueError):
    """A predictions file, info pickle or meta.json the table cannot use; names the file."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = OneLineParser(description="The paper's Table 4 from predictions.")
    parser.add_argument('predictions', nargs='+', help='.pred.json files or directories')
    parser.add_argument('--infos', nargs='+', help='info pickles holding the ground truth')
    parser.add_argument(
        '--scan-root', default='.', help='directory that relative "scan" paths are relative to')
    add_score_option(parser, '--score-thr', 0.3, 'lowest score counted')
    parser.add_argument(
        '--iou-thr',
        type=float_in(0.0, 1.0, include_low=False),
        default=0.25,
        help='in (0, 1] (default 0.25)')
    parser.add_argument('--out', help='write the table to this JSON file and a .txt next to it')
    return parser.parse_args(argv)


def load_predictions(paths: list[str]) -> list[tuple[Path, dict]]:
    """``(file, document)`` of ``.pred.json`` files (directories are searched for them)."""
    files: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir():
            found = sorted(path.glob('*.pred.json'))
            if not found:
                raise BadInput(f'{path}: no *.pred.json files in the folder')
        else:
            check_input_file(path, 'predictions file')
            found = [path]
        files += found
    return [(file, read_predictions(file)) for file in files]


def truth_from_meta(meta_path: Path) -> list[TrueBox]:
    """Axis-aligned enclosing boxes ``(class, [cx, cy, cz, dx, dy, dz])`` of a ``meta.json``."""
    meta = read_room(meta_path)
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


def main(argv: list[str] | None = None) -> dict:
    """Load predictions and ground truth, print Table 4 and optionally write it."""
    args = parse_args(argv)
    for path in args.infos or []:
        check_input_file(path, 'info pickle')
    infos = truth_from_infos(args.infos) if args.infos else None
    predictions, truth_of = [], {}
    for file, document in load_predictions(args.predictions):
        scan = Path(document['scan'])
        if infos is not None:
            if scan.name not in infos:
                raise BadInput(f'{file}: scan {scan.name} is in none of the info pickles '
                               f'{" ".join(args.infos)}')
            key = scan.name
            truth_of[key] = infos[key]
        else:
            path = scan if scan.is_absolute() else Path(args.scan_root) / scan
            meta_path = path.parent / 'meta.json'
            if not meta_path.is_file():
                raise BadInput(f'{file}: no ground truth for scan {scan}: {meta_path} '
                               'does not exist (pass --infos for converted scans)')
            key = str(path.resolve())
            truth_of.setdefault(key, truth_from_meta(meta_path))
        predictions.append((key, document))
    table = table4(predictions, truth_of, args.score_thr, args.iou_thr)
    text = (f'Table 4 (score >= {args.score_thr}, IoU >= {args.iou_thr}): true objects per '
            f'scan, then correct(incorrect) detections per model\n{format_table4(table)}')
    print(text)
    if args.out:
        print(f'written to {args.out} and {write_table(args.out, table, text)}')
    return table


if __name__ == '__main__':
    run_tool(main, 'count_table.py',
             bad_input=(BadInput, InputFileError, SchemaError, InfoFileError))
