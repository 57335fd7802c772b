"""A generated factory hall as LAZ -> FreeCAD document, and windowed vs room-sized recall.

    .venv/bin/python benchmarks/bench_hall.py --checkpoint work_dirs/demo/train/epoch_N.pth
        [--config work_dirs/demo/exp2_cpu_demo.py] [--points 30000000] [--hall-size 40 25]
        [--rooms 15] [--room-points 1000000] [--score-thr 0.3] [--seed 0] [--keep DIR]
        [--fork-tools]

1. ``python -m generator`` makes one hall (``hall`` section of the generator config, fixed
   size ``--hall-size``) of ``--points`` points and ``--rooms`` rooms of the default
   configuration (area 9, the test area of exp2) of ``--room-points`` points, each with a PLY
   that labels every point with its instance.
2. The hall is written as a LAZ file (``synthdet.scan_io.write_las_chunks``, millimetres).
3. ``tools/scan2cad.py`` turns the LAZ into an FCStd (with the predictions and corners JSON
   beside it), in its own process: wall time and peak resident memory (the largest
   ``ru_maxrss`` of it and its children, FreeCAD included).
4. ``tools/predict.py`` detects the rooms (one window each, the same reading and preparation).
5. Recall at IoU 0.25: a true object (the axis-aligned box of its points, as the converter
   makes the training boxes, for the model's classes) is found when a detection of its class
   above ``--score-thr`` overlaps it by 3D IoU >= 0.25 (each detection matches one object, in
   descending score order; boxes compared axis-aligned, as TR3D predicts them).

Last line: ``hall <N>M points -> FCStd: <s> s, peak <G> GB; windowed recall <r> vs room recall
<r>``. The goals: windowed recall at least 0.95 of room recall, peak under 8 GB.
``--fork-tools`` (a quick check of the benchmark) runs the tools forked from one process that
imported the stack once (``benchmarks/tool_runs.py``): no start-up per tool; the peak is then
the forked scan2cad's (the imported stack included) or its FreeCAD's, the larger.
"""
import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.tool_runs import add_fork_tools_option, run_tool
from synthdet.contracts import read_predictions
from synthdet.ply import read_ply_vertices
from synthdet.scan_io import write_las_chunks
from synthdet.cli import OneLineParser


IOU = 0.25
CHUNK = 2_000_000
# Runs a command and prints the largest resident memory (kB) of it and its descendants.
PEAK_WRAPPER = ('import resource, subprocess, sys\n'
                'code = subprocess.run(sys.argv[1:]).returncode\n'
                'print("peak_kb", resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n'
                'sys.exit(code)\n')


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('--checkpoint', type=Path, required=True, help='trained model (make demo)')
    parser.add_argument(
        '--config', type=Path, help='its config (default: the .py beside the work dir)')
    parser.add_argument('--points', type=int, default=30_000_000, help='points of the hall')
    parser.add_argument('--hall-size', type=float, nargs=2, default=[40.0, 25.0])
    parser.add_argument('--rooms', type=int, default=15, help='room-sized scans for the baseline')
    parser.add_argument('--room-points', type=int, default=1_000_000)
    parser.add_argument('--score-thr', type=float, default=0.3)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--keep', type=Path, help='work here and keep the files')
    add_fork_tools_option(parser)
    return parser.parse_args(argv)


def default_config(checkpoint: Path) -> Path:
    """``make demo`` writes ``WORK/exp2_cpu_<size>.py`` and ``WORK/train/epoch_N.pth``."""
    found = sorted(checkpoint.resolve().parent.parent.glob('exp2_cpu_*.py'))
    if not found:
        raise SystemExit(f'{checkpoint}: no exp2_cpu_*.py beside its work dir; pass --config')
    return found[0]


def run(*args: str | Path, forked: bool = False) -> subprocess.CompletedProcess:
    """Run ``python ARGS`` from the repository root (``forked``: see ``--fork-tools``); stop
    with its output when it fails."""
    done = run_tool(args, forked=forked)
    if done.returncode:
        raise SystemExit(f'{" ".join(map(str, args))} failed:\n{done.stderr[-3000:]}')
    return done


def generate(out: Path,
             area: int,
             count: int,
             points: int,
             seed: int,
             config: Path | None,
             forked: bool = False) -> list[Path]:
    """Generate rooms (or a hall) with PLY labels; returns the room folders."""
    extra = ['--config', str(config)] if config else []
    run('-m', 'generator', '--out', out, '--areas', str(area), '--rooms-per-area', str(count),
        '--points', str(points), '--seed', str(seed), '--ply', '--quiet', *extra, forked=forked)
    return sorted(p for p in (out / f'Area_{area}').iterdir() if p.is_dir())


def truth_boxes(room: Path, classes: list[str]) -> list[tuple[str, np.ndarray]]:
    """``(class, (6,) min/max corners)`` of every instance of ``classes``, from its points."""
    vertex = read_ply_vertices(room / f'{room.name}.ply')
    names = json.loads((room / f'{room.name}.ply.json').read_text())['instances']
    xyz = np.column_stack([vertex['x'], vertex['y'], vertex['z']])
    instance = np.asarray(vertex['instance'])
    order = np.argsort(instance, kind='stable')
    starts = np.flatnonzero(np.r_[True, np.diff(instance[order]) != 0])
    low = np.minimum.reduceat(xyz[order], starts)
    high = np.maximum.reduceat(xyz[order], starts)
    boxes = []
    for k, index in enumerate(instance[order][starts]):
        cls = names[index].rsplit('_', 1)[0]
        if cls in classes:
            boxes.append((cls, np.concatenate([low[k], high[k]])))
    return boxes


def iou_3d(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Axis-aligned 3D IoU of one ``(6,)`` min/max box with ``(M, 6)`` boxes."""
    low = np.maximum(box[:3], boxes[:, :3])
    high = np.minimum(box[3:], boxes[:, 3:])
    inter = np.prod(np.clip(high - low, 0, None), axis=1)
    volume = np.prod(box[3:] - box[:3]) + np.prod(boxes[:, 3:] - boxes[:, :3], axis=1)
    return inter / np.maximum(volume - inter, 1e-12)


def recall(truth: list[tuple[str, np.ndarray]], detections: list[dict],
           score_thr: float) -> tuple[int, int]:
    """(objects found at IoU >= 0.25, objects): greedy one-to-one matching by score."""
    found = 0
    for cls in {c for c, _ in truth}:
        boxes = np.array([b for c, b in truth if c == cls])
        free = np.ones(len(boxes), dtype=bool)
        ranked = sorted((d for d in detections if d['class'] == cls and d['score'] >= score_thr),
                        key=lambda d: -d['score'])
        for detection in ranked:
            centre, size = np.array(detection['center']), np.array(detection['size'])
            overlap = np.where(free, iou_3d(np.r_[centre - size / 2, centre + size / 2], boxes),
                               0.0)
            best = int(np.argmax(overlap))
            if overlap[best] >= IOU:
                free[best] = False
                found += 1
    return found, len(truth)


def write_hall_laz(room: Path, laz: Path) -> int:
    """The hall's points (from its PLY) as LAZ, written a chunk at a time."""
    vertex = read_ply_vertices(room / f'{room.name}.ply')
    columns = ('x', 'y', 'z', 'red', 'green', 'blue')

    def chunks():
        for start in range(0, len(vertex), CHUNK):
            part = vertex[start:start + CHUNK]
            yield np.column_stack([np.asarray(part[c], dtype=np.float64) for c in columns])

    return write_las_chunks(laz, chunks())


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    checkpoint = args.checkpoint.resolve()
    if not checkpoint.is_file():
        raise SystemExit(f'{checkpoint}: checkpoint not found (make demo writes one under '
                         f'work_dirs/demo/train)')
    config = args.config.resolve() if args.config else default_config(checkpoint)
    from mmengine.config import Config
    classes = list(Config.fromfile(str(config)).test_dataloader.dataset.metainfo['classes'])
    work = args.keep or Path(tempfile.mkdtemp(prefix='synthdet-bench-hall-'))
    work.mkdir(parents=True, exist_ok=True)
    try:
        width, depth = args.hall_size
        hall_config = work / 'hall.json'
        hall_config.write_text(
            json.dumps({'hall': {
                'width': [width, width],
                'depth': [depth, depth]
            }}))
        start = time.perf_counter()
        [hall] = generate(work / 'hall', 1, 1, args.points, args.seed, hall_config,
                          args.fork_tools)
        rooms = generate(work / 'rooms', 9, args.rooms, args.room_points, args.seed, None,
                         args.fork_tools)
        print(f'generated the hall ({width:g} x {depth:g} m, {args.points:,} points) and '
              f'{len(rooms)} rooms in {time.perf_counter() - start:.0f} s')
        laz = work / 'hall.laz'
        written = write_hall_laz(hall, laz)
        print(f'{laz}: {written:,} points, {laz.stat().st_size / 1e6:.0f} MB')

        out = work / 'cad' / 'hall.FCStd'
        out.parent.mkdir(exist_ok=True)
        start = time.perf_counter()
        scan2cad = [
            'tools/scan2cad.py', laz, '--config', config, '--checkpoint', checkpoint, '--out',
            out, '--score-thr',
            str(args.score_thr), '--seed',
            str(args.seed)
        ]
        if args.fork_tools:
            done = run(*scan2cad, forked=True)
            output, peak_kb = done.stdout, done.peak_kb
        else:
            done = run('-c', PEAK_WRAPPER, sys.executable, *scan2cad)
            parts = done.stdout.split('peak_kb')
            output, peak_kb = parts[0], parts[-1]
        seconds = time.perf_counter() - start
        peak_gb = int(peak_kb) / 1e6
        print(output.rstrip())
        hall_found, hall_total = recall(
            truth_boxes(hall, classes),
            read_predictions(str(out.with_suffix('.pred.json')))['detections'], args.score_thr)

        predictions = work / 'room_predictions'
        run('tools/predict.py',
            config,
            checkpoint,
            *[room / f'{room.name}.ply' for room in rooms],
            '--out',
            predictions,
            '--score-thr',
            str(args.score_thr),
            '--seed',
            str(args.seed),
            forked=args.fork_tools)
        room_found = room_total = 0
        for room in rooms:
            detections = read_predictions(str(predictions /
                                              f'{room.name}.pred.json'))['detections']
            found, total = recall(truth_boxes(room, classes), detections, args.score_thr)
            room_found, room_total = room_found + found, room_total + total
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    hall_recall, room_recall = hall_found / hall_total, room_found / room_total
    print(f'hall: {hall_found} of {hall_total} objects found; rooms: {room_found} of '
          f'{room_total} ({len(rooms)} rooms of {args.room_points:,} points)')
    print(f'hall {written / 1e6:.1f}M points -> FCStd: {seconds:.0f} s, peak {peak_gb:.1f} GB; '
          f'windowed recall {hall_recall:.3f} vs room recall {room_recall:.3f}')


if __name__ == '__main__':
    main()
