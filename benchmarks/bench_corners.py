"""Room corners: the traced-outline method vs a convex-hull baseline, side by side.

    .venv/bin/python benchmarks/bench_corners.py [--rooms 10] [--points 300000]
        [--generate 30] [--generated DIR ...]

For every room shape (rect, L, U, T) and noise setting (clean; LiDAR noise: 1 cm range noise,
0.03 degree angular jitter, 10 % dropout, dropout patches, 0.05 % outliers) it generates
``--rooms`` rooms (``tests/room_scans.py``, random rotation, furniture, a door and a window)
and prints, for both methods, the mean corner error (each true corner to the nearest found
corner, cm) and the share of rooms with the right corner count. ``--generate N`` runs
``python -m generator`` for N rooms without and N rooms with its noise models (box, L and U
shapes in equal shares, ``--points`` each) in a temporary folder; ``--generated DIR`` adds
existing generator rooms. For generator rooms the ``meta.json`` polygon is the truth; they are
the issue's accuracy goal (<= 3 cm, >= 95 % right count; <= 5 cm with noise).
Then it times both methods on 1M-point rooms. The convex-hull baseline uses the same floor and
ceiling levels, wall band and polygon simplification; only the outline differs.

Ends with one line: the traced method on the generator rooms (clean, noisy), then both methods
on all rooms (error ratio, count accuracy, time per 1M points).
"""
import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests/room_scans.py

from configurator.corners import (
    CornerDetectionError,
    CornerParams,
    detect_corners,  # noqa
    find_levels,
    simplify_outline)
from synthdet.contracts import read_room  # noqa: E402
from synthdet.scan_io import read_scan  # noqa: E402
from tests.room_scans import SHAPES, NoiseModel, make_room  # noqa: E402


def convex_hull_corners(points: np.ndarray, params: CornerParams = CornerParams()) -> np.ndarray:
    """Baseline: convex hull of the wall-band points, simplified like the traced outline."""
    floor_z, ceiling_z = find_levels(points[:, 2], params)
    band = (points[:, 2] > floor_z + params.wall_margin) & \
        (points[:, 2] < ceiling_z - params.wall_margin)
    xy = points[band, :2]
    hull = xy[ConvexHull(xy).vertices][::-1]  # scipy lists 2D hulls counter-clockwise
    return simplify_outline(
        hull, tolerance=0.05, min_edge=params.min_edge, min_turn=params.min_turn)


def corner_error(found: np.ndarray, truth: np.ndarray) -> float:
    """Mean distance from each true corner to the nearest found corner (metres)."""
    return float(np.linalg.norm(truth[:, None] - found[None], axis=2).min(axis=1).mean())


def evaluate(method, points: np.ndarray, truth: np.ndarray) -> tuple[float, bool]:
    try:
        found = method(points)
    except CornerDetectionError:
        return float('nan'), False
    return corner_error(found, truth), len(found) == len(truth)


METHODS = {
    'traced': lambda points: detect_corners(points).corners,
    'hull': convex_hull_corners,
}


def generated_rooms(folder: Path):
    """(label, points, true polygon) of every generator room under ``folder``."""
    for meta_path in sorted(folder.rglob('meta.json')):
        meta = read_room(meta_path)
        scan = meta_path.parent / f'{meta_path.parent.name}.txt'
        noise = meta['generator'].get('config', {}).get('scanner', {}).get('range_noise', 0)
        label = f'generator {meta["room"].get("shape", "?")}' + (' noisy' if noise else '')
        yield label, read_scan(scan), np.array(meta['room']['polygon'], dtype=np.float64)


GENERATOR_CONFIGS = {
    'clean': {
        'room': {
            'shapes': {
                'box': 0.34,
                'L': 0.33,
                'U': 0.33
            }
        }
    },
    'noisy': {
        'room': {
            'shapes': {
                'box': 0.34,
                'L': 0.33,
                'U': 0.33
            }
        },
        'scanner': {
            'range_noise': 0.01,
            'angular_jitter': 0.001,
            'dropout': 0.1
        }
    },
}


def generate_rooms(out: Path, rooms: int, points: int) -> list[Path]:
    """Run the generator for ``rooms`` clean and ``rooms`` noisy rooms under ``out``."""
    folders = []
    for seed, (name, config) in enumerate(GENERATOR_CONFIGS.items(), start=5):
        config_path = out / f'{name}.json'
        config_path.write_text(json.dumps(config))
        command = [
            sys.executable, '-m', 'generator', '--out',
            str(out / name), '--areas', '7', '--rooms-per-area',
            str(rooms), '--points',
            str(points), '--seed',
            str(seed), '--config',
            str(config_path), '--workers', '1', '--quiet'
        ]
        subprocess.run(command, check=True, cwd=Path(__file__).resolve().parents[1])
        folders.append(out / name)
    return folders


def summary(results: dict[str, dict[str, list]], noisy: bool) -> tuple[float, float]:
    """Traced mean error (cm) and right-count share over the clean or noisy generator rooms."""
    runs = [
        run for label, by_method in results.items()
        if label.startswith('generator') and label.endswith('noisy') == noisy
        for run in by_method['traced']
    ]
    if not runs:
        return float('nan'), float('nan')
    return np.nanmean([e for e, _ in runs]) * 100, float(np.mean([ok for _, ok in runs]))


def time_methods(rooms: int) -> dict[str, float]:
    """Median wall seconds per noisy 1M-point room for each method; prints wall and CPU time."""
    wall = {name: [] for name in METHODS}
    cpu = {name: [] for name in METHODS}
    for seed in range(rooms):
        room = make_room(
            SHAPES[seed % len(SHAPES)], 1_000_000, seed=2000 + seed, noise=NoiseModel())
        for name, method in METHODS.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            method(room.points)
            wall[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
    seconds = {name: float(np.median(values)) for name, values in wall.items()}
    cpu_seconds = {name: float(np.median(values)) for name, values in cpu.items()}
    print(f'time per 1M-point room (median of {rooms}), wall / CPU: traced '
          f'{seconds["traced"]:.3f} / {cpu_seconds["traced"]:.3f} s, hull '
          f'{seconds["hull"]:.3f} / {cpu_seconds["hull"]:.3f} s')
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rooms', type=int, default=10, help='rooms per shape and noise')
    parser.add_argument('--points', type=int, default=300_000, help='points per room')
    parser.add_argument(
        '--timing-rooms', type=int, default=3, help='1M-point rooms timed (0: no timing)')
    parser.add_argument(
        '--generated',
        type=Path,
        nargs='*',
        default=[],
        help='folders of python -m generator rooms (meta.json truth)')
    parser.add_argument(
        '--generate',
        type=int,
        default=30,
        help='generator rooms to make, clean and again noisy (0: none)')
    args = parser.parse_args()
    workspace = tempfile.TemporaryDirectory(prefix='synthdet-bench-corners-')
    if args.generate:
        args.generated += generate_rooms(Path(workspace.name), args.generate, args.points)

    results: dict[str, dict[str, list]] = {}
    cases = []
    for noisy in (False, True):
        for shape in SHAPES:
            label = f'{shape} {"noisy" if noisy else "clean"}'
            for seed in range(args.rooms):
                cases.append((label, lambda s=shape, n=noisy, seed=seed: make_room(
                    s, args.points, seed=1000 + seed, noise=NoiseModel() if n else None)))
    for label, make in cases:
        room = make()
        for name, method in METHODS.items():
            results.setdefault(label, {}).setdefault(name, []).append(
                evaluate(method, room.points, room.polygon))
    for folder in args.generated:
        for label, points, truth in generated_rooms(folder):
            for name, method in METHODS.items():
                results.setdefault(label,
                                   {}).setdefault(name,
                                                  []).append(evaluate(method, points, truth))

    print(f'{"rooms":<22}{"n":>4} | {"traced err cm":>13} {"count ok":>9} | '
          f'{"hull err cm":>11} {"count ok":>9}')
    totals = {name: [] for name in METHODS}
    for label, by_method in results.items():
        row = f'{label:<22}{len(by_method["traced"]):>4} |'
        for name in METHODS:
            errors = np.array([e for e, _ in by_method[name]])
            correct = np.mean([ok for _, ok in by_method[name]])
            totals[name] += by_method[name]
            width = 13 if name == 'traced' else 11
            row += f' {np.nanmean(errors) * 100:>{width}.2f} {correct:>9.0%} |'
        print(row.rstrip(' |'))

    timing = ''
    if args.timing_rooms > 0:
        seconds = time_methods(args.timing_rooms)
        timing = (f'; time per 1M points traced {seconds["traced"]:.2f} s vs hull '
                  f'{seconds["hull"]:.2f} s ({seconds["traced"] / seconds["hull"]:.1f}x)')

    error = {name: np.nanmean([e for e, _ in totals[name]]) * 100 for name in METHODS}
    correct = {name: np.mean([ok for _, ok in totals[name]]) for name in METHODS}
    generated = [
        f'{name} {err:.2f} cm / {ok:.0%} right count'
        for name, (err, ok) in (('clean', summary(results, False)),
                                ('noisy', summary(results, True))) if not np.isnan(err)
    ]
    print(f'corners, generator rooms: traced {", ".join(generated) or "none"}; all rooms: '
          f'traced {error["traced"]:.2f} cm '
          f'/ {correct["traced"]:.0%} vs convex hull {error["hull"]:.2f} cm / '
          f'{correct["hull"]:.0%}: hull error {error["hull"] / error["traced"]:.1f}x traced'
          f'{timing}')
    workspace.cleanup()


if __name__ == '__main__':
    main()
