"""Training speed of ``configs/tr3d/exp2_cpu.py`` on a 2-core CPU: one process with 2 OpenMP
threads (``tools/train.py``, ``make exp2-cpu``) vs 2 processes with 1 thread each
(``tools/dist_train.sh``, gloo, ``make exp2-cpu EXP2_PROCS=2``), the same batch of 4 rooms.

    .venv/bin/python benchmarks/bench_dist_train.py [--rooms-per-area 4] [--points 1000000]
                                                    [--iters 16] [--warmup 4] [--seed 0]
                                                    [--workers 2] [--sample-points N]
                                                    [--fork-tools]

The generator writes ``--rooms-per-area`` rooms of ``--points`` points into areas 7, 8 and 9 of
a temporary folder and ``tools/create_data.py`` converts them (``--workers`` processes each).
Each setup then trains the exp2_cpu config (2 cm voxels, 40,000 sampled points or
``--sample-points``, the mixed-sensor data of ``make exp2-cpu``) from the same seed for
``--iters`` iterations of 4 rooms, without validation, logging every iteration: one process
takes the 4 rooms with ``OMP_NUM_THREADS=2``; two processes take 2 rooms each with
``OMP_NUM_THREADS=1`` and average their gradients. The time per iteration is the Runner's own
(``time`` in ``vis_data/scalars.json``: loading, forward, backward, gradient exchange and
optimiser step), its median over the iterations after the first ``--warmup``.
The last line is the speed-up of the two processes. It needs an idle machine: another job on
the cores slows the two setups differently. ``--fork-tools`` (a quick check of the benchmark)
runs every tool forked from one process that imported the stack once
(``benchmarks/tool_runs.py``), the two training processes started with the environment
torchrun gives them instead of through ``tools/dist_train.sh``: no start-up per process.
"""
import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.tool_runs import add_fork_tools_option, run_tool, start_tool
from synthdet.cli import OneLineParser

REPO = Path(__file__).resolve().parents[1]
CONFIG = 'configs/tr3d/exp2_cpu.py'
BATCH = 4  # rooms per iteration, as in exp2_cpu.py
TRAIN_ROOMS_AREAS = (7, 8)
# (name, processes, OpenMP threads per process); both use the machine's 2 cores
SETUPS = (('tools/train.py', 1, 2), ('tools/dist_train.sh', 2, 1))


def free_port() -> int:
    """A TCP port that is free now, for the processes' rendezvous."""
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def add_training_run_options(parser: argparse.ArgumentParser, per: str) -> None:
    """Add the options of a measured training run on generated rooms: the data (rooms per
    area, points, seed, workers), the iterations (``per``: what they run per) and the warm-up;
    ``check_iterations`` checks them."""
    parser.add_argument('--rooms-per-area', type=int, default=4)
    parser.add_argument('--points', type=int, default=1_000_000)
    parser.add_argument('--iters', type=int, default=16, help=f'training iterations per {per}')
    parser.add_argument('--warmup', type=int, default=4, help='first iterations not counted')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument(
        '--workers', type=int, default=2, help='generator and converter processes for the data')
    add_fork_tools_option(parser)


def check_iterations(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """The parser's one-line error unless the iterations cover the training rooms whole and
    outnumber the warm-up."""
    train_rooms = args.rooms_per_area * len(TRAIN_ROOMS_AREAS)
    if args.rooms_per_area < 1 or (args.iters * BATCH) % train_rooms:
        parser.error(f'--iters x {BATCH} rooms must be a multiple of the {train_rooms} '
                     'training rooms (--rooms-per-area x 2)')
    if args.iters <= args.warmup:
        parser.error('--iters must be larger than --warmup')


def make_data(root: Path,
              rooms_per_area: int,
              points: int,
              seed: int,
              workers: int,
              forked: bool = False) -> None:
    """Generate areas 7-9 into ``root`` and convert them to info pickles, as ``make exp2-cpu``
    (``workers`` processes each; ``forked``: the tools forked, see ``--fork-tools``)."""
    raw = root / 'Stanford3dDataset_v1.2_Aligned_Version'
    for command in (
        [
            '-m', 'generator', '--out', raw, '--areas', 7, 8, 9, '--rooms-per-area',
            rooms_per_area, '--points', points, '--seed', seed, '--workers', workers
        ],
        [
            'tools/create_data.py', 's3dis', '--root-path', root, '--out-dir', root, '--areas', 7,
            8, 9, '--workers', workers
        ],
    ):
        done = run_tool(command, forked=forked)
        if done.returncode != 0:
            sys.exit(f'{command[1]} failed (exit {done.returncode}):\n{done.stderr[-4000:]}')


def sample_options(num_points: int) -> list[str]:
    """``--cfg-options`` that make every ``PointSample`` of the config's training datasets
    sample ``num_points`` points (addressed by their index in each pipeline)."""
    from mmengine.config import Config
    cfg = Config.fromfile(REPO / CONFIG, import_custom_modules=False)
    return [
        f'train_dataloader.dataset.dataset.datasets.{index}.pipeline.{step}.num_points='
        f'{num_points}'
        for index, dataset in enumerate(cfg.train_dataloader.dataset.dataset.datasets)
        for step, transform in enumerate(dataset.pipeline) if transform.type == 'PointSample'
    ]


def train(data: Path,
          work: Path,
          processes: int,
          threads: int,
          repeats: int,
          seed: int,
          extra_options: list[str],
          forked: bool = False) -> list[float]:
    """Train one setup and return the Runner's seconds per iteration, in order (``forked``:
    see ``--fork-tools``)."""
    options = [
        f'{key}.data_root={data}/' for key in ('train_dataloader.dataset.dataset.datasets.0',
                                               'train_dataloader.dataset.dataset.datasets.1',
                                               'val_dataloader.dataset', 'test_dataloader.dataset')
    ]
    options += extra_options
    options += [
        f'train_dataloader.batch_size={BATCH // processes}',
        f'train_dataloader.dataset.times={repeats}', 'train_cfg.max_epochs=1',
        'train_cfg.val_begin=2', 'default_hooks.logger.interval=1', f'randomness.seed={seed}'
    ]
    if forked:
        train_forked(work, processes, threads, options)
    else:
        if processes == 1:
            command = [sys.executable, 'tools/train.py', CONFIG]
        else:
            command = ['bash', 'tools/dist_train.sh', CONFIG, str(processes)]
        command += ['--work-dir', str(work), '--cfg-options', *options]
        env = dict(
            os.environ, OMP_NUM_THREADS=str(threads), PYTHON=sys.executable,
            PORT=str(free_port()))
        run = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True)
        if run.returncode != 0:
            sys.exit(f'{" ".join(command[:3])} failed (exit {run.returncode}):\n'
                     f'{run.stderr[-4000:]}')
    scalars = next(work.glob('*/vis_data/scalars.json')).read_text().splitlines()
    return [json.loads(line)['time'] for line in scalars if '"time"' in line]


def train_forked(work: Path, processes: int, threads: int, options: list[str]) -> None:
    """``tools/train.py`` forked (``benchmarks/tool_runs.py``): one process, or one per rank
    with the environment torchrun gives each and mmengine's pytorch launcher."""
    command = ['tools/train.py', CONFIG, '--work-dir', str(work), '--cfg-options', *options]
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    if processes > 1:
        command += ['--launcher', 'pytorch']
        env.update(MASTER_ADDR='127.0.0.1', MASTER_PORT=str(free_port()),
                   WORLD_SIZE=str(processes), LOCAL_WORLD_SIZE=str(processes))
    work.mkdir(parents=True, exist_ok=True)
    logs = [work / f'rank_{rank}.log' for rank in range(processes)]
    ranks = [
        start_tool(command,
                   log,
                   env=dict(env, RANK=str(rank), LOCAL_RANK=str(rank)) if processes > 1 else env,
                   forked=True) for rank, log in enumerate(logs)
    ]
    while any(rank.poll() is None for rank in ranks):  # a failed rank stops its peers
        if any(rank.returncode for rank in ranks):
            for rank in ranks:
                rank.terminate()
        time.sleep(0.2)
    for log, code in zip(logs, (rank.returncode for rank in ranks)):
        if code != 0:
            sys.exit(f'tools/train.py ({log.stem}) failed (exit {code}):\n'
                     f'{log.read_text(errors="replace")[-4000:]}')


def main(argv: list[str] | None = None) -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    add_training_run_options(parser, 'setup')
    parser.add_argument(
        '--sample-points',
        type=int,
        help='points each training room is sampled to (default: the config\'s 40,000)')
    args = parser.parse_args(argv)
    check_iterations(parser, args)
    train_rooms = args.rooms_per_area * len(TRAIN_ROOMS_AREAS)
    if args.sample_points is not None and args.sample_points < 1:
        parser.error('--sample-points must be >= 1')
    repeats = args.iters * BATCH // train_rooms
    options = [] if args.sample_points is None else sample_options(args.sample_points)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / 'data'
        make_data(data, args.rooms_per_area, args.points, args.seed, args.workers,
                  args.fork_tools)
        for name, processes, threads in SETUPS:
            times = train(data,
                          Path(tmp) / f'work_{processes}', processes, threads, repeats, args.seed,
                          options, args.fork_tools)
            if len(times) != args.iters:
                sys.exit(f'{name}: logged {len(times)} iterations, expected {args.iters}')
            results[name] = (processes, threads, statistics.median(times[args.warmup:]))
    sampled = '' if args.sample_points is None else f' sampled to {args.sample_points}'
    print(f'{CONFIG}, batch of {BATCH} rooms of {args.points} generated points{sampled}, '
          f'{args.iters} iterations, median of the last {args.iters - args.warmup}; '
          f'{os.cpu_count()} cores')
    print(f"{'setup':<22} {'processes':>9} {'threads':>8} {'rooms/proc':>10} "
          f"{'s/iter':>7} {'rooms/s':>8}")
    for name, (processes, threads, seconds) in results.items():
        print(f'{name:<22} {processes:>9} {threads:>8} {BATCH // processes:>10} '
              f'{seconds:>7.2f} {BATCH / seconds:>8.2f}')
    (_, _, one), (_, _, two) = results.values()
    print(f'2 processes x 1 thread vs 1 process x 2 threads: x{one / two:.2f} faster per '
          f'iteration of {BATCH} rooms ({two:.2f} s vs {one:.2f} s)')


if __name__ == '__main__':
    main()
