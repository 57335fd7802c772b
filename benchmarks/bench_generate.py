"""Wall time of a generation run through the CLI (default: the paper's 3 areas x 50 rooms x 1M
points, 2 workers), written to a temporary folder that is removed afterwards.

    .venv/bin/python benchmarks/bench_generate.py [--rooms-per-area 50] [--points 1000000]
        [--workers 2] [--compare-workers 1]

With ``--compare-workers K`` the same rooms are also generated with K workers, side by side.
A run smaller than 3 x 50 rooms is extrapolated linearly to 150 rooms (and says so). The last
line compares the (extrapolated) wall time of 150 rooms with the 10-minute goal, as a ratio.
"""
import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from synthdet.cli import OneLineParser

GOAL_SECONDS = 600.0
PAPER_ROOMS = 150


def timed_run(out: Path, args: argparse.Namespace, workers: int, cache: Path) -> float:
    command = [
        sys.executable, '-m', 'generator', '--out',
        str(out), '--areas', '7', '8', '9', '--rooms-per-area',
        str(args.rooms_per_area), '--points',
        str(args.points), '--workers',
        str(workers), '--seed', '0', '--asset-cache',
        str(cache), '--quiet'
    ]
    start = time.perf_counter()
    subprocess.run(command, check=True)
    return time.perf_counter() - start


def main() -> None:
    parser = OneLineParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rooms-per-area', type=int, default=50)
    parser.add_argument('--points', type=int, default=1_000_000)
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--compare-workers', type=int, default=None)
    args = parser.parse_args()

    work = Path(tempfile.mkdtemp(prefix='synthdet-bench-generate-'))
    cache = work / 'assets'
    try:
        # build the asset library once, outside the timed runs
        subprocess.run([
            sys.executable, '-c', 'import sys; from generator.assets import '
            'default_library; default_library(sys.argv[1])',
            str(cache)
        ],
                       check=True)
        rooms = 3 * args.rooms_per_area
        results = {args.workers: timed_run(work / 'out', args, args.workers, cache)}
        if args.compare_workers:
            results[args.compare_workers] = timed_run(work / 'out_compare', args,
                                                      args.compare_workers, cache)
        size = sum(f.stat().st_size for f in (work / 'out').rglob('*') if f.is_file())
        print(f'{rooms} rooms x {args.points:,} points, output {size / 1e9:.2f} GB')
        print(f'{"workers":>8}{"wall s":>10}{"s/room":>10}{"150 rooms s":>14}')
        for workers, seconds in results.items():
            print(f'{workers:>8}{seconds:>10.1f}{seconds / rooms:>10.2f}'
                  f'{seconds / rooms * PAPER_ROOMS:>14.1f}')
        if args.compare_workers:
            print(f'{args.workers} vs {args.compare_workers} workers: '
                  f'{results[args.compare_workers] / results[args.workers]:.2f}x faster')
        seconds = results[args.workers] / rooms * PAPER_ROOMS
        how = 'measured' if rooms == PAPER_ROOMS else f'extrapolated from {rooms} rooms'
        print(f'3x50 rooms x {args.points:,} points, {args.workers} workers: {seconds:.0f} s '
              f'({how}) = {seconds / GOAL_SECONDS:.2f}x of the 10-minute goal')
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == '__main__':
    main()
