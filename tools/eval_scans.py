"""Evaluate a model on labelled scans: what it finds and what it invents, per scan and in total.

Usage: python tools/eval_scans.py [CONFIG CHECKPOINT] SCANS_OR_DIR... --out DIR
                                  [--score-thr 0.3] [--device cpu|cuda:0] [--seed 0]
                                  [--voxel M] [--tta] [--columns x,y,z,r,g,b]
                                  [--cfg-options k=v ...]

Without CONFIG and CHECKPOINT the model is the one that ships with synthdet
(``projects/synthdet/weights/``, as ``tools/predict.py``); a line says which model ran.

A labelled scan is ``X.<suffix>`` (any format ``tools/predict.py`` reads) with its truth
``X.labels.json`` beside it (``synthdet.labels/1``, docs/evaluation.md); a folder stands for
every scan in it with a labels file (the others are named and skipped). Each scan is read,
prepared and detected exactly as ``tools/predict.py`` does, and counted with the paper's
Table 4 rule on rotated boxes (``projects/synthdet/evaluation/real_scans.py``). Prints the
Table-4 layout (``truth found(false)`` per scan and class, YuMi and 3D printer always shown),
recall per class at IoU 0.25, AP at IoU 0.25 and 0.5, and ends with the line
``real scans: recall R at IoU 0.25, F false positives per room, P phantom yumi/3d printer
(N rooms)``. Writes into ``--out``: ``real_scans.json`` (all figures), ``real_scans.txt`` (the
printed table), and per scan ``<stem>.pred.json`` and ``<stem>.png`` (a top view with truth and
detections).

Every scan and labels file is read and checked before the model is loaded. A missing labels
file, invalid JSON, a bad scan or checkpoint end with one line naming the file and exit code 2;
failures at run time with exit code 1 (an ``--out`` folder that cannot be written: at once).
"""
import argparse
from pathlib import Path

from projects.synthdet.bootstrap import (
    check_device, load_config, parse_model_and_scans, run_tool)
from projects.synthdet.shipped_model import resolve_model
from synthdet.cli import OneLineParser
from synthdet.outputs import OutputRefused, check_output_dir
from synthdet.scan_io import load_scan


class BadInput(ValueError):
    """A scan, labels file, checkpoint or argument the evaluation cannot use."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    args, args.scans = parse_model_and_scans(
        OneLineParser(
            description='Evaluate a checkpoint on labelled scans (X.ply + X.labels.json).'), argv,
        'labelled scans or folders of them', 'output directory',
        'no labelled scan or folder given')
    return args


def main(argv: list[str] | None = None) -> dict:
    """Evaluate and print; returns the figures (``synthdet.real_scans/1``)."""
    args = parse_args(argv)  # bad options end here, before torch and mmdet3d are loaded
    from projects.synthdet.evaluation.real_scans import (LabelsError, evaluate_scans,
                                                         find_labelled_scans, format_result)
    from projects.synthdet.inference.detector import load_model
    from projects.synthdet.inference.windows import inference_settings
    try:  # a folder that cannot be written is OutputFailed (exit 1) before any work
        check_output_dir(args.out, '--out', inputs=args.scans)
    except OutputRefused as error:
        raise BadInput(str(error)) from None
    try:
        scans, skipped = find_labelled_scans(args.scans)
        for item in scans:  # every scan readable before the model is loaded
            load_scan(item.scan, voxel=args.voxel, columns=args.columns)
    except LabelsError as error:
        raise BadInput(str(error)) from None
    except (ValueError, OSError) as error:  # ScanFormatError names the file (and line)
        raise BadInput(str(error)) from None
    for line in skipped:
        print(line)
    try:
        config, checkpoint, model_line = resolve_model(args.config, args.checkpoint)
        cfg = load_config(config, args.cfg_options)
        inference_settings(cfg, config)
        model = load_model(cfg, checkpoint, check_device(args.device), args.tta)
    except ValueError as error:  # a bad config, checkpoint or device, no inference settings
        raise BadInput(str(error)) from None
    print(model_line, flush=True)
    result = evaluate_scans(
        cfg,
        model,
        scans,
        args.out,
        score_thr=args.score_thr,
        seed=args.seed,
        voxel=args.voxel,
        columns=args.columns,
        model_name=Path(config).stem)
    print(format_result(result))
    return result


if __name__ == '__main__':
    run_tool(main, 'eval_scans.py', bad_input=(BadInput, ), failure=(RuntimeError, OSError))
