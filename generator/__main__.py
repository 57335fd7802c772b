"""CLI: ``python -m generator --out DIR --areas 7 8 9 --rooms-per-area 50 --points 1000000``."""
import argparse
import math
import os
import re
import sys
import time
from pathlib import Path

from synthdet.cli import MAX_AREA, OneLineParser, shown
from synthdet.outputs import OutputFailed, OutputRefused, check_output_dir

PROFILES = Path(__file__).resolve().parent / 'profiles'
# the accepted ranges of the integer options (docs/generator.md); a hall of 10-50 million
# points is the largest scan the generator is made for
MAX_POINTS = 100_000_000
MAX_ROOMS_PER_AREA = 100_000
MAX_WORKERS = 256
MAX_SEED = 2**63 - 1


def whole_number(text: str) -> int:
    """An argparse ``type``: an integer, also written as a whole float (``1e6``)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        number = float(text)
    except ValueError:
        number = math.nan
    if not number.is_integer():  # NaN and infinities are not
        raise argparse.ArgumentTypeError(f'expected an integer, got {shown(text)}')
    return int(number)


def check_range(parser: argparse.ArgumentParser, option: str, values: list[int], low: int,
                high: int) -> None:
    """``parser.error`` unless every value of ``option`` is in ``[low, high]``."""
    for value in values:
        if not low <= value <= high:
            parser.error(f'{option} must be >= {low:,} and <= {high:,}, got {shown(str(value))}')


def profile_names() -> list[str]:
    """Names of the packaged configuration profiles (generator/profiles/<name>.json)."""
    return sorted(path.stem for path in PROFILES.glob('*.json'))


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog='python -m generator',
        description='Generate synthetic factory rooms (Blender scenes + simulated LiDAR) as S3DIS '
        'areas: OUT/Area_N/factory_<k>/{factory_<k>.txt, Annotations/, meta.json}.')
    parser.add_argument(
        '--out',
        required=True,
        type=Path,
        help='output root, e.g. data/s3dis/Stanford3dDataset_v1.2_Aligned_Version')
    parser.add_argument(
        '--areas',
        type=whole_number,
        nargs='+',
        default=[7, 8, 9],
        help=f'area numbers to write, 1 to {MAX_AREA} (default: 7 8 9)')
    parser.add_argument(
        '--rooms-per-area',
        type=whole_number,
        default=50,
        help=f'rooms per area, 1 to {MAX_ROOMS_PER_AREA:,} (default 50)')
    parser.add_argument(
        '--points',
        type=whole_number,
        default=1_000_000,
        help=f'points per room, 1 to {MAX_POINTS:,} (default 1,000,000)')
    parser.add_argument(
        '--object-ratio',
        type=float,
        default=0.5,
        help='share of the points on movable objects (default 0.5)')
    parser.add_argument(
        '--seed',
        type=whole_number,
        default=0,
        help='run seed, 0 to 2^63-1; room seeds derive from (seed, area, room)')
    parser.add_argument(
        '--workers',
        type=whole_number,
        default=1,
        help=f"worker processes ('spawn'), 1 to {MAX_WORKERS}")
    parser.add_argument(
        '--shard',
        default='1/1',
        help='K/N: generate only every N-th room starting at the K-th (1-based)')
    settings = parser.add_mutually_exclusive_group()
    settings.add_argument(
        '--config',
        type=Path,
        help='JSON or YAML file overriding the defaults '
        '(probabilities, sizes, sensors, appearance, clutter)')
    settings.add_argument(
        '--profile',
        choices=profile_names(),
        help='a profile of generator/profiles/ instead of the default mix of sensors, '
        'appearance and clutter (paper = the paper-faithful scans)')
    parser.add_argument(
        '--library',
        type=Path,
        help='folder of <class>.blend asset files instead of the procedural library')
    parser.add_argument(
        '--asset-cache',
        type=Path,
        help='cache folder of the procedural library (default ~/.cache/synthdet/assets)')
    parser.add_argument(
        '--asset-seed',
        type=whole_number,
        default=0,
        help='seed of the procedural library, 0 to 2^63-1')
    parser.add_argument('--ply', action='store_true', help='also write <room>.ply (CloudCompare)')
    parser.add_argument(
        '--preview',
        action='store_true',
        help='also write a top-down <room>.png colored by class')
    parser.add_argument(
        '--save-blend', action='store_true', help='also save the Blender scene as <room>.blend')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    return parser


def check_arguments(args: argparse.Namespace, parser: argparse.ArgumentParser) -> tuple[int, int]:
    """Reject bad arguments before any work; return the shard (K, N)."""
    check_range(parser, '--areas', args.areas, 1, MAX_AREA)
    check_range(parser, '--rooms-per-area', [args.rooms_per_area], 1, MAX_ROOMS_PER_AREA)
    check_range(parser, '--points', [args.points], 1, MAX_POINTS)
    check_range(parser, '--workers', [args.workers], 1, MAX_WORKERS)
    check_range(parser, '--seed', [args.seed], 0, MAX_SEED)
    check_range(parser, '--asset-seed', [args.asset_seed], 0, MAX_SEED)
    duplicates = sorted({a for a in args.areas if args.areas.count(a) > 1})
    if duplicates:
        parser.error(f'--areas has duplicates: {" ".join(map(str, duplicates))}')
    if not 0.0 <= args.object_ratio <= 1.0:  # NaN fails too
        parser.error(f'--object-ratio must be in [0, 1], got {shown(str(args.object_ratio))}')
    match = re.fullmatch(r'(\d{1,9})/(\d{1,9})', args.shard)
    if not match or not 1 <= int(match.group(1)) <= int(match.group(2)):
        parser.error(f'--shard must be K/N with 1 <= K <= N < 10^9, got {shown(args.shard)}')
    for area in args.areas:  # never mix generated rooms into a real S3DIS area
        area_dir = args.out / f'Area_{area}'
        foreign = sorted(p.name for p in area_dir.iterdir()
                         if p.is_dir() and not p.name.startswith(('factory_', '.'))) \
            if area_dir.is_dir() else []
        if foreign:
            parser.error(f'{area_dir} holds rooms the generator did not make (e.g. {foreign[0]}); '
                         f'choose other --areas (the real S3DIS uses 1-6)')
    if args.library is not None and not args.library.is_dir():
        parser.error(f'--library {args.library}: folder not found')
    return int(match.group(1)), int(match.group(2))


def main(argv: list[str] | None = None) -> int:
    """Generate the rooms; returns 0, 2 for bad usage, a bad config or an ``--out`` that is no
    folder, 1 for an ``--out`` that cannot be written or a failing write, 130/143 when
    stopped by SIGINT/SIGTERM."""
    parser = build_parser()
    args = parser.parse_args(argv)
    shard = check_arguments(args, parser)
    try:  # before the asset library is built: an --out that is no folder or cannot be written
        check_output_dir(args.out, '--out')
    except OutputRefused as error:
        parser.error(str(error))
    except OutputFailed as error:
        print(f'generator: error: {error}', file=sys.stderr)
        return 1
    from generator.config import ConfigError, load_config
    try:
        config = load_config(PROFILES / f'{args.profile}.json' if args.profile else args.config)
    except ConfigError as err:
        parser.error(str(err))
    from generator.pipeline import RunOptions, plan_tasks, run
    threads = max(1, (os.cpu_count() or 1) // args.workers)
    options = RunOptions(
        out=str(args.out),
        points=args.points,
        object_ratio=args.object_ratio,
        seed=args.seed,
        config=config,
        library=str(args.library) if args.library else None,
        asset_cache=str(args.asset_cache) if args.asset_cache else None,
        asset_seed=args.asset_seed,
        ply=args.ply,
        preview=args.preview,
        save_blend=args.save_blend,
        threads=threads)
    tasks = plan_tasks(args.areas, args.rooms_per_area, args.seed, shard)
    start = time.perf_counter()
    written = 0
    from synthdet.processes import Interrupted, stop_on_signals
    try:
        with stop_on_signals():
            for _, status, _ in run(tasks, options, workers=args.workers,
                                    progress=not args.quiet):
                written += status == 'written'
    except Interrupted as stop:
        print(f'generator: stopped by {stop} after {written} room(s); finished rooms are kept, '
              'the same command completes the run', file=sys.stderr)
        return stop.exit_code
    except OSError as error:
        print(f'generator: error: {error.filename or args.out}: {error.strerror or error}',
              file=sys.stderr)
        return 1
    print(
        f'generator: {written} room(s) written, {len(tasks) - written} already present, '
        f'{time.perf_counter() - start:.1f} s, output in {args.out}',
        file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
