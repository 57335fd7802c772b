"""Detect objects in scans and write one ``<scan>.pred.json`` per scan.

Usage: python tools/predict.py [CONFIG CHECKPOINT] POINTS... --out DIR [--score-thr 0.3]
                               [--device cpu|cuda:0] [--seed 0] [--voxel M]
                               [--columns x,y,z,r,g,b] [--known EARLIER_SCAN]
                               [--cfg-options k=v ...]

Without CONFIG and CHECKPOINT (the first argument is a config when it ends with .py, .json,
.yaml or .yml) the model is the one that ships with synthdet (``projects/synthdet/weights/``);
a line says which model ran. POINTS are scans in any format of ``synthdet.scan_io``, read
with ``load_scan`` into a local float64 frame (every point, or one per ``--voxel`` as
``python -m configurator corners``; the voxels are those of the scan's coordinates) and
prepared with ``synthdet.prepare.prepare_scan`` (outliers, up axis, floor levelling, walls along the
axes, a denser scan resampled down to the config's training density and one far from it warned
about: ``density_from_config``), each step reported. A scan larger than the config's
``inference_window`` is detected window by window, each window sampled by the config's test
pipeline like a training room, and the windows' boxes are merged with the project's 3D NMS
(``projects/synthdet/inference/windows.py``); a room-sized scan is one window. The boxes are
written in the input scan's own coordinates, with their yaw in that frame
(``"format": "synthdet.predictions/1"``, see docs/training.md).

``--known EARLIER_SCAN``: every scan is a later scan of the room of EARLIER_SCAN, whose
corrected labels ``<stem>.labels.json`` lie beside it. The two are registered, the labelled
objects still in place are written instead of the model's boxes, and the model's detections are
kept only where the room changed (``projects/synthdet/inference/known_objects.py``, docs/teach.md).
A scan that does not register on it (another room) ends with one line and exit code 2.

The arguments are checked first (the config loads, ``--out`` is a folder that can be written,
the checkpoint exists), then every scan is read and checked, all before the model is loaded;
the checkpoint is loaded weights-only (``projects/synthdet/checkpoint.py``). Bad arguments, bad
scans, refused checkpoints and clashing outputs end with one line naming the file and exit code
2; failures at run time with exit code 1. Each JSON is written under a temporary name and
renamed into place. A scan's name is used as the file system gives it (bytes that are not UTF-8
included) for its output file; inside the JSON, and in messages, such bytes show as U+FFFD.
"""
import argparse
from pathlib import Path

from tqdm import tqdm

from projects.synthdet.bootstrap import (add_known_option, check_device, load_config,
                                         parse_model_and_scans, run_tool)
from projects.synthdet.shipped_model import resolve_model
from synthdet.cli import OneLineParser
from synthdet.contracts import write_predictions
from synthdet.outputs import check_output_dir, readable
from synthdet.prepare import prepare_scan
from synthdet.scan_io import load_scan


class BadInput(ValueError):
    """A scan, checkpoint or argument predict cannot use; the message names the file."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = OneLineParser(description='Detect objects in scans with a checkpoint.')
    add_known_option(parser)
    args, args.points = parse_model_and_scans(
        parser, argv,
        'the scans: .e57, .las/.laz, .ply, .pcd, .xyz/.pts/.csv, .txt, .bin',
        'output directory for <scan>.pred.json', 'no scan given')
    return args


def output_path(scan: Path, out_dir: Path) -> Path:
    """``<out_dir>/<scan stem>.pred.json``."""
    return out_dir / f'{scan.stem}.pred.json'


def check_scans(scans: list[Path], out_dir: Path, voxel: float | None,
                columns: str | None) -> dict[Path, Path]:
    """Read every scan once (errors name the file) and map each output path to its scan."""
    targets: dict[Path, Path] = {}
    for scan in scans:
        target = output_path(scan, out_dir)
        if target in targets:
            raise BadInput(f'{scan} and {targets[target]} would both be written to {target}; '
                           'predict them into different --out directories')
        if target.is_dir():
            raise BadInput(f'{target}: is a folder, so the predictions of {scan} cannot be '
                           'written there')
        try:
            load_scan(scan, voxel=voxel, columns=columns)
        except (ValueError, OSError) as error:  # ScanFormatError names the file (and line)
            raise BadInput(readable(str(error))) from None
        targets[target] = scan
    return targets


def main(argv: list[str] | None = None) -> list[Path]:
    """Predict every scan and write its JSON; returns the written paths."""
    args = parse_args(argv)  # before the heavy imports: bad options are refused at once
    out_dir = Path(args.out)
    try:
        check_output_dir(out_dir)
        config, checkpoint, model_line = resolve_model(args.config, args.checkpoint)
        cfg = load_config(config, args.cfg_options)
        from projects.synthdet.inference.detector import ModelDetector, load_model
        from projects.synthdet.inference.known_objects import (KnownScanError, apply_known_scan,
                                                               read_known_scan)
        from projects.synthdet.inference.windows import inference_settings
        spec, density = inference_settings(cfg, config)
        device = check_device(args.device)
    except ValueError as error:  # OutputRefused, ConfigFileError, DeviceError
        raise BadInput(str(error)) from None
    targets = check_scans([Path(p) for p in args.points], out_dir, args.voxel, args.columns)
    try:
        known = read_known_scan(args.known, voxel=args.voxel, columns=args.columns,
                                density=density, seed=args.seed) if args.known else None
    except KnownScanError as error:
        raise BadInput(str(error)) from None
    try:
        model = load_model(cfg, checkpoint, device, args.tta)
    except ValueError as error:  # CheckpointError
        raise BadInput(str(error)) from None
    print(model_line, flush=True)
    detector = ModelDetector(model, args.score_thr, args.seed)
    model_name = Path(config).stem
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for target, scan in tqdm(targets.items(), desc='predict', unit='scan'):
        prepared = prepare_scan(
            load_scan(scan, voxel=args.voxel, columns=args.columns),
            target_density=density,
            seed=args.seed)
        for line in prepared.report:
            tqdm.write(readable(f'{scan.name}: {line}'))
        try:
            predictions = detector.predictions(prepared, spec, model_name)
        except ValueError as error:
            raise RuntimeError(readable(f'{scan}: {error}')) from None
        if known is not None:
            try:
                tqdm.write(apply_known_scan(known, scan, prepared, predictions))
            except KnownScanError as error:
                raise BadInput(str(error)) from None
        write_predictions(target, predictions)  # the contract makes names valid UTF-8
        written.append(target)
    return written


if __name__ == '__main__':
    run_tool(main, 'predict.py', bad_input=(BadInput, ), failure=(RuntimeError, OSError))
