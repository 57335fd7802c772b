"""A model on a folder of labelled real scans: found, false and phantom objects per threshold.

    .venv/bin/python benchmarks/bench_real_scans.py SCANS_DIR --checkpoint CKPT
        [--config configs/tr3d/exp2_cpu.py] [--score-thr 0.3] [--compare-thr 0.5]
        [--device cpu] [--keep DIR] [--fork-tools]
    .venv/bin/python benchmarks/bench_real_scans.py --generate 2 --checkpoint CKPT ...

``--generate N`` evaluates N small generated rooms (``tests/s3dis_fixtures.py``) written as
labelled PLY scans in a temporary folder instead: a check of the benchmark itself, not a
measure of a model on real rooms. ``--fork-tools`` runs ``tools/eval_scans.py`` forked from a
process that imported the stack once (``benchmarks/tool_runs.py``): no start-up of its own.

1. ``tools/eval_scans.py`` evaluates every labelled scan of SCANS_DIR (``X.ply`` with
   ``X.labels.json`` beside it, docs/evaluation.md) in its own process, as a user runs it, at
   the lowest of the thresholds: wall time, its Table-4 layout and AP at IoU 0.25 and 0.5.
2. From the detections it wrote, the same counting at each threshold side by side (``--score-thr``
   and ``--compare-thr``): found of true objects per class, false positives per room, phantom
   YuMis and 3D printers.

Last line, at ``--score-thr``: ``real scans: recall R at IoU 0.25, F false positives per room,
P phantom yumi/3d printer (N rooms)``. The goal for the model of ``make exp2-cpu`` on real rooms
of tables, chairs and sofas: recall >= 0.7 of each, at most 1 false positive per room, no
phantom.
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.tool_runs import add_fork_tools_option, run_tool
from projects.synthdet.evaluation.real_scans import (
    evaluate_detections, labels_path, summary_line)
from synthdet.contracts import LABELS_FORMAT, read_labels, read_predictions
from synthdet.contracts import write_labels
from synthdet.scan_io import read_scan, write_scan
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from synthdet.cli import OneLineParser

REPO_ROOT = Path(__file__).resolve().parents[1]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('scans', type=Path, nargs='?', help='folder of labelled scans')
    parser.add_argument('--generate', type=int, help='evaluate N generated rooms instead')
    parser.add_argument('--checkpoint', type=Path, required=True, help='trained model')
    parser.add_argument('--config', type=Path, default=REPO_ROOT / 'configs/tr3d/exp2_cpu.py')
    parser.add_argument('--score-thr', type=float, default=0.3, help='the threshold reported')
    parser.add_argument('--compare-thr', type=float, default=0.5, help='shown beside it')
    parser.add_argument('--device', default='cpu')
    parser.add_argument('--keep', type=Path, help='write the evaluation here and keep it')
    add_fork_tools_option(parser)
    args = parser.parse_args(argv)
    if (args.scans is None) == (args.generate is None):
        parser.error('give a folder of labelled scans or --generate N, not both')
    return args


def write_generated_scans(folder: Path, rooms: int, seed: int = 0) -> None:
    """``rooms`` small generated rooms as ``<room>.ply`` with ``<room>.labels.json``."""
    truth = write_synthetic_area(folder / 'raw', area=1, n_rooms=rooms, seed=seed,
                                 points_per_object=300)
    for room, boxes in truth.items():
        points = read_scan(folder / 'raw' / S3DIS_DIR / 'Area_1' / room / f'{room}.txt')
        write_scan(folder / f'{room}.ply', points)
        write_labels(folder / f'{room}.labels.json', {
            'format': LABELS_FORMAT, 'scan': f'{room}.ply',
            'classes': ['table', 'chair', 'sofa', 'yumi', '3dprinter'],
            'boxes': [{'class': box['class'],
                       'center': [(lo + hi) / 2 for lo, hi in zip(box['min'], box['max'])],
                       'size': [hi - lo for lo, hi in zip(box['min'], box['max'])],
                       'yaw': 0.0} for box in boxes]})


def evaluate(args: argparse.Namespace, out: Path, lowest: float) -> tuple[dict, float]:
    """Run tools/eval_scans.py at the lowest threshold; its figures and wall time."""
    start = time.perf_counter()
    done = run_tool([
        'tools/eval_scans.py', args.config, args.checkpoint, args.scans, '--out', out,
        '--score-thr',
        str(lowest), '--device', args.device
    ],
                    forked=args.fork_tools)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f'tools/eval_scans.py failed ({done.returncode}): {done.stderr.strip()}')
    print(done.stdout.rstrip())
    return json.loads((out / 'real_scans.json').read_text()), seconds


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    thresholds = sorted({args.score_thr, args.compare_thr})
    with tempfile.TemporaryDirectory() as scratch:
        out = args.keep or Path(scratch) / 'out'
        if args.generate is not None:
            args.scans = Path(scratch) / 'scans'
            write_generated_scans(args.scans, args.generate)
        first, seconds = evaluate(args, out, thresholds[0])
        print(f'\n{first["rooms"]} labelled rooms evaluated in {seconds:.0f} s '
              f'({seconds / max(first["rooms"], 1):.1f} s per room, model loading included)')
        entries = []
        for row in first['scans']:
            scan = args.scans / row['scan']
            predictions = read_predictions(out / f'{scan.stem}.pred.json')
            entries.append((row['scan'], read_labels(labels_path(scan)),
                            predictions['detections']))
    classes = first['classes']  # the model's, with the phantom classes
    results = {thr: evaluate_detections(entries, classes, thr) for thr in thresholds}
    print('\nfound of true objects per class (false positives), in total over the folder')
    print('score >='.ljust(10) + ''.join(c.rjust(12) for c in classes) +
          'recall'.rjust(9) + 'FP/room'.rjust(9) + 'phantoms'.rjust(10))
    for thr, result in results.items():
        cells = [
            '-' if cell is None else f'{cell["found"]}/{cell["truth"]} ({cell["false"]})'
            for cell in (result['total'][c] for c in classes)
        ]
        recall = result['overall_recall']
        print(f'{thr:<10g}' + ''.join(c.rjust(12) for c in cells) +
              ('n/a' if recall is None else f'{recall:.3f}').rjust(9) +
              f'{result["false_positives_per_room"]:.2f}'.rjust(9) +
              str(result['phantoms']).rjust(10))
    print(summary_line(results[args.score_thr]))


if __name__ == '__main__':
    main()
