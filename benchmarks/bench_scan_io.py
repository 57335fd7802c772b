"""Scan reading in bounded memory: streamed ``load_scan`` vs reading the whole file, side by side.

    .venv/bin/python benchmarks/bench_scan_io.py [--points 30000000] [--voxel 0.05]
        [--chunk 1000000] [--room-points 1000000] [--scan FILE]

Writes a georeferenced LAZ of about ``--points`` points (``tests/room_scans.py`` rooms of
``--room-points`` points, tiled side by side over a hall-sized area and shifted to 500000 /
5400000, written a chunk at a time by ``synthdet.scan_io.write_las_chunks``) unless ``--scan``
names one. Then, each in its own process so that the peak resident memory (``ru_maxrss``) is
its own, it runs

- streamed: ``load_scan(scan, voxel)``, chunks of ``--chunk`` points voxel-filtered on the fly;
- read-all: ``read_scan(scan)``, the whole file as one float64 array, as before;
- imports only: the interpreter and libraries both sides load, for reference.

It prints both peaks and times, the kept voxels and the bound ``docs/scans.md`` states
(64 bytes per kept voxel plus the chunk buffers), and ends with one line comparing the two.
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from synthdet.scan_io import load_scan, read_scan, write_las_chunks
from tests.room_scans import make_room
from synthdet.cli import OneLineParser

GEO = np.array([500000.0, 5400000.0, 300.0])
ROOM_POINTS = 1_000_000


def hall_chunks(total: int, room_points: int = ROOM_POINTS):
    """Rooms of ``room_points`` points (8 different ones, repeated) on a grid of 12 m cells:
    about ``total`` points over a hall-sized area, one room at a time."""
    rooms = [
        make_room('rect', n_points=room_points, seed=seed, rotate=False).points
        for seed in range(8)
    ]
    count = max(1, round(total * len(rooms) / sum(len(room) for room in rooms)))
    columns = int(np.ceil(np.sqrt(count)))
    for index in range(count):
        points = rooms[index % len(rooms)].copy()
        points[:, :3] += GEO + [12.0 * (index % columns), 12.0 * (index // columns), 0.0]
        yield points


def measure(mode: str, scan: str, voxel: float, chunk: int, points: int,
            room_points: int) -> None:
    """Child process: write the scan, or run one side and print its figures (seconds, points,
    kept)."""
    start = time.perf_counter()
    if mode == 'write':
        points = kept = write_las_chunks(scan, hall_chunks(points, room_points))
    elif mode == 'streamed':
        loaded = load_scan(scan, voxel=voxel, chunk_points=chunk)
        points, kept = loaded.points_read, len(loaded.points)
    elif mode == 'read-all':
        points = kept = len(read_scan(scan))
    else:  # imports only: the floor both sides share
        points = kept = 0
    print(f'{time.perf_counter() - start:.3f} {points} {kept}')


def run_child(mode: str, args: argparse.Namespace, scan: str) -> tuple[float, int, int, float]:
    """Run ``measure`` in a fresh process; returns seconds, points, kept and peak GB. The
    parent stays small (no scan in memory), so the child's peak, which counts the moment
    between fork and exec, is its own."""
    process = subprocess.Popen([
        sys.executable, __file__, '--measure', mode, '--scan', scan, '--voxel',
        str(args.voxel), '--chunk',
        str(args.chunk), '--points',
        str(args.points), '--room-points',
        str(args.room_points)
    ],
                               stdout=subprocess.PIPE,
                               text=True)
    output = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode:
        raise SystemExit(f'{mode} failed with exit code {process.returncode}')
    seconds, points, kept = output.split()
    return float(seconds), int(points), int(kept), usage.ru_maxrss / 1024**2  # KiB -> GiB


def main() -> None:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('--points', type=int, default=30_000_000)
    parser.add_argument('--voxel', type=float, default=0.05)
    parser.add_argument('--chunk', type=int, default=1_000_000)
    parser.add_argument(
        '--room-points', type=int, default=ROOM_POINTS, help='points of each tiled room')
    parser.add_argument('--scan', help='an existing scan instead of the generated LAZ')
    parser.add_argument(
        '--measure', choices=('write', 'streamed', 'read-all', 'imports'), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        measure(args.measure, args.scan, args.voxel, args.chunk, args.points, args.room_points)
        return
    with tempfile.TemporaryDirectory() as folder:
        scan = args.scan
        if scan is None:
            scan = str(Path(folder) / 'hall.laz')
            seconds, written, _, _ = run_child('write', args, scan)
            print(f'wrote {written:,} points to a LAZ of {os.path.getsize(scan) / 1e6:.0f} MB '
                  f'in {seconds:.0f} s')
        streamed = run_child('streamed', args, scan)
        whole = run_child('read-all', args, scan)
        imports = run_child('imports', args, scan)
    points = streamed[1]
    bound = 64 * streamed[2] / 1024**3
    print(f'{"method":<44}{"seconds":>9}{"peak GB":>9}')
    print(f'{"streamed load_scan, " + f"{args.voxel * 100:g} cm voxels":<44}'
          f'{streamed[0]:>9.1f}{streamed[3]:>9.2f}')
    print(f'{"read-all read_scan (float64 N x 6)":<44}{whole[0]:>9.1f}{whole[3]:>9.2f}')
    print(f'{"imports only (Python, numpy, numba, laspy)":<44}{imports[0]:>9.1f}'
          f'{imports[3]:>9.2f}')
    print(f'{points:,} points, {streamed[2]:,} kept voxels: 64 B each = {bound:.2f} GB, '
          f'chunks of {args.chunk:,} points')
    print(f'scan_io {points / 1e6:.0f}M-point LAZ: streamed load_scan peak {streamed[3]:.2f} GB '
          f'in {streamed[0]:.0f} s vs read-all {whole[3]:.2f} GB in {whole[0]:.0f} s: '
          f'{whole[3] / streamed[3]:.1f}x less memory')


if __name__ == '__main__':
    main()
