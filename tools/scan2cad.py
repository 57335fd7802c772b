"""One command from a scan to a FreeCAD document: read, prepare, detect, trace corners, build.

Usage: python tools/scan2cad.py SCAN --out hall.FCStd [--config CFG --checkpoint CKPT]
                                [--score-thr 0.3] [--device cpu] [--seed 0] [--voxel 0.02]
                                [--columns x,y,z,r,g,b] [--library DIR] [--wall-thickness 0.1]
                                [--known EARLIER_SCAN]

Without ``--config`` and ``--checkpoint`` the detector is the model that ships with synthdet
(``projects/synthdet/weights/``, its model card beside it); the first line says which model
ran. The stages are the ones a user runs one by one, on the same prepared scan:
1. ``synthdet.scan_io.load_scan`` (one point per ``--voxel``, 2 cm by default as the corners:
   a hall's memory stays bounded) and ``synthdet.prepare.prepare_scan`` (each step reported;
   for detection a scan denser than the config's training density is resampled down to it,
   ``density_from_config``, while the corners use every point);
2. detection by windows sized from the training rooms (``ModelDetector.predictions``, as
   ``tools/predict.py --voxel`` with the same voxel) -> ``<out stem>.pred.json`` beside it;
   with ``--known EARLIER_SCAN``, an earlier scan of the room with its corrected labels beside
   it, the objects found again there and the detections where the room changed, as
   ``tools/predict.py --known``;
3. the room corners on the prepared points, written in the scan's coordinates
   (``configurator.corners.outline_in_scan``, as ``python -m configurator corners
   --approximate``) -> ``<out stem>.corners.json``; when no outline can be traced, an
   approximate floor (the points' footprint or its bounding rectangle, on the floor level
   found) marked ``approximate_floor`` with a warning: a real scan always ends in a document;
4. the FreeCAD document (``configurator.freecad_cli.build_document``, as
   ``python -m configurator freecad``).
Every output is in the scan's own coordinates (a georeferenced scan gives georeferenced boxes).
The outputs of one run are made in a work folder of the run, then copied to temporary names of
the run beside their targets and renamed together at the end (``synthdet.outputs``): a failed
run leaves the previous set as it was, and the next run removes what a killed one left.
"""
import argparse
import sys
import time
from pathlib import Path

from configurator.corners import SCAN_VOXEL, CornerDetectionError, room_outline
from configurator.corners import outline_in_scan, outline_to_dict
from configurator.freecad_cli import (FreecadFailed, build_document, check_input_scan,
                                      wall_thickness_option)
from projects.synthdet.bootstrap import (add_detection_arguments, add_known_option, check_device,
                                         load_config)
from projects.synthdet.shipped_model import resolve_model
from synthdet.cli import OneLineParser
from synthdet.contracts import write_corners, write_predictions
from synthdet.outputs import check_output_file, copy_into_place, names_as_given, readable
from synthdet.prepare import align_scan, resample_to_density
from synthdet.processes import work_folder
from synthdet.scan_io import load_scan


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = OneLineParser(description='Scan -> detections, corners -> FreeCAD .FCStd')
    parser.add_argument('scan', help='.e57, .las/.laz, .ply, .pcd, .xyz/.pts/.csv, .txt or .bin')
    parser.add_argument(
        '--config', help='model config, e.g. configs/tr3d/exp2.py (default: the shipped model)')
    parser.add_argument('--checkpoint', help='checkpoint file (default: the shipped model)')
    parser.add_argument('--out', required=True, help='FreeCAD document to write (.FCStd)')
    parser.add_argument('--library', help='folder of <class>.step files replacing built-ins')
    parser.add_argument(
        '--wall-thickness',
        type=wall_thickness_option,
        default=0.1,
        help='metres, up to 2 (default 0.1)')
    parser.add_argument('--freecadcmd', default='freecadcmd', help='FreeCAD command line')
    add_detection_arguments(parser, voxel=SCAN_VOXEL)
    add_known_option(parser)
    return parser.parse_args(argv)


def output_paths(out: Path) -> tuple[Path, Path]:
    """The predictions and corners JSON written beside ``out``."""
    return out.with_suffix('.pred.json'), out.with_suffix('.corners.json')


def scan_to_cad(args: argparse.Namespace, report=print) -> dict:
    """Run the four stages on ``args.scan``; returns FreeCAD's result (objects, warnings, the
    corner finder's notes first: an approximate floor, an open-top scan)."""
    scan, out = Path(args.scan), Path(args.out)
    if out.suffix.lower() != '.fcstd':
        raise ValueError(f'{out}: the output must end with .FCStd')
    predictions_path, corners_path = output_paths(out)
    check_input_scan(scan)
    inputs = [scan, args.config, args.checkpoint, args.library, args.known]
    for path in (out, predictions_path, corners_path):  # the arguments before any work
        check_output_file(path, inputs=inputs)
    config, checkpoint, model_line = resolve_model(args.config, args.checkpoint)
    report(model_line)
    cfg = load_config(config, args.cfg_options)
    from projects.synthdet.inference.detector import ModelDetector, load_model
    from projects.synthdet.inference.known_objects import apply_known_scan, read_known_scan
    from projects.synthdet.inference.windows import inference_settings
    spec, density = inference_settings(cfg, config)
    device = check_device(args.device)
    start = time.perf_counter()
    loaded = load_scan(scan, voxel=args.voxel, columns=args.columns)
    known = read_known_scan(args.known, voxel=args.voxel, columns=args.columns, density=density,
                            seed=args.seed) if args.known else None
    # the corners, as `configurator corners`, use every point; detection the resampled ones
    outlined = align_scan(loaded)
    prepared = resample_to_density(outlined, density, args.seed)
    for line in prepared.report:
        report(f'prepare: {line}')
    detector = ModelDetector(
        load_model(cfg, checkpoint, device, args.tta), args.score_thr, args.seed)
    with work_folder('synthdet-scan2cad') as work:
        # the document's label is its file's stem, as when FreeCAD saves it where it belongs
        staged = [work / 'room.pred.json', work / 'room.corners.json', work / readable(out.name)]
        predictions = detector.predictions(prepared, spec, Path(config).stem)
        if known is not None:
            report(f'known objects: {apply_known_scan(known, scan, prepared, predictions)}')
        write_predictions(staged[0], predictions)
        report(f'detect: {len(predictions["detections"])} objects -> {predictions_path}')
        outline = outline_in_scan(room_outline(outlined.points), outlined)
        corners = outline_to_dict(outline, str(scan))
        write_corners(staged[1], corners)
        kind = 'approximate corners' if outline.approximate else 'corners'
        report(f'corners: {len(corners["corners"])} {kind} -> {corners_path}')
        result = build_document(
            scan,
            staged[0],
            staged[2],
            corners=staged[1],
            library=args.library,
            min_score=args.score_thr,
            wall_thickness=args.wall_thickness,
            freecadcmd=args.freecadcmd)
        copy_into_place(list(zip(staged, (predictions_path, corners_path, out))))
    result = dict(result, document=str(out.resolve()), warnings=[
        *(f'{scan}: {note}' for note in outline.notes), *result['warnings']])
    report(f'freecad: {len(result["objects"])} objects -> {result["document"]} '
           f'({time.perf_counter() - start:.1f} s from reading the scan)')
    return result


def main(argv: list[str] | None = None) -> int:
    """Run scan2cad; returns 0, 2 for bad input (scan, checkpoint, no room found), 1 for a
    failure at run time (FreeCAD, an unwritable output), each with a one-line message."""
    args = parse_args(argv)
    names_as_given()
    try:
        result = scan_to_cad(args)
    except ValueError as error:  # ScanFormatError, CheckpointError, SchemaError too
        kind = 'no room found' if isinstance(error, CornerDetectionError) else 'bad input'
        print(f'scan2cad: {kind}: {error}', file=sys.stderr)
        return 2
    except (OSError, FreecadFailed) as error:
        print(f'scan2cad: failed: {error}', file=sys.stderr)
        return 1
    for warning in result['warnings']:
        print(f'warning: {warning}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
