"""TR3D on CPU at 1 cm vs 2 cm voxels on one generated room: train step, inference, peak memory.

Usage: python benchmarks/bench_model.py [--points 100000] [--iters 3] [--threads 1]
                                        [--in-process]

One room (6 x 6 x 3 m, floor, ceiling, walls and ~10 objects, written by
``tests/s3dis_fixtures.write_synthetic_area``) is sampled to ``--points`` points. Every voxel
size runs in its own subprocess so that peak RSS (``ru_maxrss``, including the ~0.5 GB of
imported libraries) is per configuration. A training iteration is forward + backward + AdamW
step on a batch of one scene; inference is ``predict`` with NMS. Times are medians over
``--iters`` runs after one warm-up run, as CPU seconds of the process (``time.process_time``,
the cost on any machine) and as wall seconds (inflated on a shared machine). Workers get
``OMP_NUM_THREADS=--threads``: the OpenMP runtime reads it at start-up only, and
``torch.set_num_threads`` alone leaves MinkowskiEngine's CPU kernels spin-waiting on a busy
machine. ``--in-process`` times the three models one after another in this process instead (a
quick check of the benchmark itself: one start-up instead of three, but the peak memory is then
the largest so far, not each model's).

A third model is 2 cm voxels with ``TR3DNeck(backbone_fine_level=True)``: a finest head level on
the first backbone stage's voxels (16 cm apart at 2 cm voxels, as TR3D's finest level at 1 cm),
the CPU-scale way to a finer level against the straightforward one, 1 cm voxels. The last two
lines are the ratios: 2 cm vs 1 cm, and 2 cm with the fine level vs 2 cm and vs 1 cm.
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from synthdet.cli import OneLineParser

CLASSES = ('table', 'chair', 'sofa', 'bookcase', 'board')
LABEL2LEVEL = (1, 0, 1, 1, 0)  # published TR3D S3DIS
# model name: voxel size, backbone fine level, label2level (the fine level is level 0)
MODELS_TIMED = {
    '1cm': (0.01, False, LABEL2LEVEL),
    '2cm': (0.02, False, LABEL2LEVEL),
    '2cm+fine': (0.02, True, tuple(level + 1 for level in LABEL2LEVEL)),
}


def make_room(num_points: int, seed: int, out_file: Path) -> None:
    """Write one generated room as an .npz of (N, 6) float32 points (RGB 0-1), boxes, labels."""
    from tests.s3dis_fixtures import read_room_scene, write_synthetic_area
    with tempfile.TemporaryDirectory() as root:
        truth = write_synthetic_area(
            Path(root),
            area=7,
            n_rooms=1,
            seed=seed,
            classes=CLASSES,
            points_per_object=6000,
            room_size=(6.0, 6.0, 3.0))
        room, boxes = next(iter(truth.items()))
        points, box_array, labels = read_room_scene(Path(root), 7, room, boxes, CLASSES)
    rng = np.random.default_rng(seed)
    points = points[rng.choice(len(points), num_points, replace=len(points) < num_points)]
    np.savez(out_file, points=points, boxes=box_array, labels=labels)


def run_worker(room_file: Path, name: str, iters: int, threads: int) -> dict:
    """Time training and inference of the TR3D S3DIS model ``name`` of :data:`MODELS_TIMED`."""
    import torch
    from mmdet3d.registry import MODELS
    from mmdet3d.structures import Det3DDataSample, DepthInstance3DBoxes
    from mmdet3d.utils import register_all_modules
    from mmengine.structures import InstanceData

    import projects.synthdet.models  # noqa: F401  (registers TR3D)
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    register_all_modules(init_default_scope=True)
    room = np.load(room_file)
    voxel_size, fine_level, label2level = MODELS_TIMED[name]
    model = MODELS.build(
        dict(
            type='TR3DDetector',
            voxel_size=voxel_size,
            backbone=dict(
                type='TR3DMinkResNet', in_channels=3, depth=34, num_planes=(64, 128, 128, 128)),
            neck=dict(
                type='TR3DNeck',
                in_channels=(64, 128, 128, 128),
                out_channels=128,
                backbone_fine_level=fine_level),
            bbox_head=dict(type='TR3DHead', num_classes=len(CLASSES), label2level=label2level),
            test_cfg=dict(nms_pre=1000, iou_thr=0.5, score_thr=0.01)))
    model.init_weights()
    sample = Det3DDataSample(metainfo=dict(box_type_3d=DepthInstance3DBoxes))
    sample.gt_instances_3d = InstanceData(
        bboxes_3d=DepthInstance3DBoxes(
            torch.from_numpy(room['boxes']).float(),
            box_dim=6,
            with_yaw=False,
            origin=(0.5, 0.5, 0.5)),
        labels_3d=torch.from_numpy(room['labels']).long())
    data = dict(inputs=dict(points=[torch.from_numpy(room['points'])]), data_samples=[sample])
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-3, weight_decay=1e-4)

    def train_step() -> None:
        losses = model(**model.data_preprocessor(data, training=True), mode='loss')
        optimizer.zero_grad()
        sum(losses.values()).backward()
        optimizer.step()

    def infer() -> None:
        with torch.no_grad():
            model(**model.data_preprocessor(data, training=False), mode='predict')

    def median_seconds(step) -> tuple[float, float]:
        """Median CPU seconds (this process) and wall seconds of ``step``."""
        step()  # warm-up
        cpu, wall = [], []
        for _ in range(iters):
            cpu_start, wall_start = time.process_time(), time.perf_counter()
            step()
            cpu.append(time.process_time() - cpu_start)
            wall.append(time.perf_counter() - wall_start)
        return statistics.median(cpu), statistics.median(wall)

    model.train()
    train_cpu, train_wall = median_seconds(train_step)
    model.eval()
    infer_cpu, infer_wall = median_seconds(infer)
    voxels = len(np.unique(np.floor(room['points'][:, :3] / voxel_size), axis=0))
    return dict(
        voxels=voxels,
        train_cpu=train_cpu,
        train_wall=train_wall,
        infer_cpu=infer_cpu,
        infer_wall=infer_wall,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('--points', type=int, default=100_000)
    parser.add_argument('--iters', type=int, default=3, help='timed runs after one warm-up')
    parser.add_argument('--threads', type=int, default=1, help='torch CPU threads')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument(
        '--in-process',
        action='store_true',
        help='time the models in this process (peak memory then not per model)')
    parser.add_argument('--worker', choices=MODELS_TIMED, help=argparse.SUPPRESS)
    parser.add_argument('--room', type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        print(json.dumps(run_worker(args.room, args.worker, args.iters, args.threads)))
        return

    with tempfile.TemporaryDirectory() as tmp:
        room_file = Path(tmp) / 'room.npz'
        make_room(args.points, args.seed, room_file)
        results = {}
        env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
        for name in MODELS_TIMED:
            if args.in_process:
                results[name] = run_worker(room_file, name, args.iters, args.threads)
                continue
            command = [sys.executable, __file__, '--worker', name]
            command += ['--room', str(room_file), '--iters', str(args.iters)]
            command += ['--threads', str(args.threads)]
            run = subprocess.run(command, check=True, capture_output=True, text=True, env=env)
            results[name] = json.loads(run.stdout.strip().splitlines()[-1])
    print(f'TR3D (published S3DIS model), {args.points} points, one 6x6x3 m room, '
          f'{args.threads} thread(s), median of {args.iters}; CPU = process CPU seconds' +
          ('; all in one process: peak RSS is the largest so far' if args.in_process else ''))
    print(f"{'model':>8} {'voxels':>8} {'train CPU s':>12} {'train wall s':>13} "
          f"{'infer CPU s':>12} {'infer wall s':>13} {'peak RSS MB':>12}")
    for name, r in results.items():
        print(f"{name:>8} {r['voxels']:>8} {r['train_cpu']:>12.2f} "
              f"{r['train_wall']:>13.2f} {r['infer_cpu']:>12.2f} {r['infer_wall']:>13.2f} "
              f"{r['peak_rss_mb']:>12.0f}")
    fine, coarse, fine_level = results['1cm'], results['2cm'], results['2cm+fine']
    print(f"2 cm vs 1 cm (CPU seconds): train x{fine['train_cpu'] / coarse['train_cpu']:.2f} "
          f"faster, inference x{fine['infer_cpu'] / coarse['infer_cpu']:.2f} faster, "
          f"peak memory x{coarse['peak_rss_mb'] / fine['peak_rss_mb']:.2f}")
    train, infer = fine_level['train_cpu'], fine_level['infer_cpu']
    print(f"2 cm + fine level (CPU seconds): train x{train / coarse['train_cpu']:.2f} of 2 cm, "
          f"x{train / fine['train_cpu']:.2f} of 1 cm; inference "
          f"x{infer / coarse['infer_cpu']:.2f} of 2 cm, x{infer / fine['infer_cpu']:.2f} of 1 cm")


if __name__ == '__main__':
    main()
