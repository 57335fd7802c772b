"""Generation time of the same rooms under each sensor model (generator/sensors.py), side by side.

    .venv/bin/python benchmarks/bench_sensors.py [--rooms 3] [--points 1000000] [--repeats 3]

One process, one thread (``OMP_NUM_THREADS`` is the caller's), the asset library built once.
Each sensor's profile (``generator/profiles/{paper,tls,tablet}.json``; ``paper`` with aimed
object rays, the training default of that model, and ``paper-uniform`` with the paper's uniform
directions) generates the same rooms ``(seed 0, area 7, rooms 1..N)``: layout, bpy scene,
scan and text files, into a temporary folder removed afterwards. The passes go round the
models in turn; the median per room of ``--repeats`` passes is printed with its ratio to the
aimed paper sensor. The last line gives the slowest model's seconds per 1M-point room.
"""
import statistics
import tempfile
import time
from pathlib import Path

import bpy  # noqa: F401  (before open3d: both ship libtbb)

from generator.config import load_config
from generator.pipeline import RoomGenerator, RunOptions, plan_tasks
from synthdet.cli import OneLineParser

REPO = Path(__file__).resolve().parents[1]

PROFILES = {
    'paper': ('paper.json', {
        'aim_at_objects': True
    }),
    'paper-uniform': ('paper.json', {}),
    'tls': ('tls.json', {}),
    'tablet': ('tablet.json', {}),
}


def main() -> None:
    parser = OneLineParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rooms', type=int, default=3)
    parser.add_argument('--points', type=int, default=1_000_000)
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix='synthdet-bench-sensors-') as work:
        options = {}
        for label, (profile, override) in PROFILES.items():
            config = load_config(REPO / 'generator' / 'profiles' / profile)
            config['scanner'].update(override)
            options[label] = RunOptions(
                out='',
                points=args.points,
                object_ratio=0.5,
                seed=0,
                config=config,
                asset_cache=str(Path(work) / 'assets'),
                threads=1)
        generator = RoomGenerator(options['paper'])  # one bpy scene; the options change per model
        tasks = plan_tasks([7], args.rooms, 0)
        seconds: dict[str, list[float]] = {label: [] for label in options}
        for repeat in range(args.repeats):
            for label, option in options.items():
                option.out = str(Path(work) / f'{label}_{repeat}')
                generator.options = option
                start = time.perf_counter()
                for task in tasks:
                    generator.generate(task)
                seconds[label].append((time.perf_counter() - start) / len(tasks))
    per_room = {label: statistics.median(times) for label, times in seconds.items()}
    print(f'{args.rooms} rooms x {args.points:,} points, median of {args.repeats} passes, '
          f'1 Embree thread')
    print(f'{"sensor":<15}{"s/room":>8}{"vs paper":>10}')
    for label, value in per_room.items():
        print(f'{label:<15}{value:>8.2f}{value / per_room["paper"]:>9.2f}x')
    slowest = max(per_room, key=per_room.get)
    print(f'sensors: slowest {slowest} {per_room[slowest] * 1e6 / args.points:.2f} s per 1M-point '
          f'room ({per_room[slowest] / per_room["paper"]:.2f}x the aimed paper sensor)')


if __name__ == '__main__':
    main()
