"""Check generated rooms' annotations against the generator's object boxes (meta.json).

Usage: python tools/check_annotations.py RAW_DIR [--areas N ...] [--tolerance 0.05]
                                         [--max-outside 0.01] [--out JSON]

RAW_DIR holds ``Area_N/<room>/`` folders (``data/s3dis/Stanford3dDataset_v1.2_Aligned_Version``).
For each generated room (one with a ``meta.json``; real S3DIS rooms are skipped) and each
detection-class object with an annotation file, the annotated points are compared with the
object's box in its own axes (``synthdet/annotation_check.py``). The table has a row per sensor
model and class: objects, the median and 90th percentile of the largest horizontal extent of the
points as a ratio of the box's (1.00: the true box the converter computes is the object's), the
median and 90th percentile of the share of points outside the box grown by ``--tolerance``
metres, how many objects have any, the median coverage (the share of the box's volume the points'
extents enclose: below 1 where the sensor saw part of an object) and the share of objects covered
less than half. Exit 1 when an object has more than ``--max-outside`` of
its points outside (a labelling rule gives objects points that are not theirs), 2 for unreadable
input, 0 otherwise.
"""
import argparse
import json
import sys
from pathlib import Path

from tqdm import tqdm

from synthdet.annotation_check import (
    MAX_OUTSIDE, TOLERANCE, check_room, describe, format_summary, offenders, summarize)
from synthdet.contracts import SchemaError
from synthdet.outputs import OutputFailed, OutputRefused, check_output, write_text
from synthdet.point_text import PointFileError


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('raw_dir', type=Path, help='folder of Area_N/<room>/ folders')
    parser.add_argument('--areas', type=int, nargs='+', help='areas (default: every Area_N)')
    parser.add_argument(
        '--tolerance', type=float, default=TOLERANCE,
        help=f'metres the box grows per side before a point counts as outside '
        f'(default {TOLERANCE})')
    parser.add_argument(
        '--max-outside', type=float, default=MAX_OUTSIDE,
        help=f'largest share of an object\'s points allowed outside (default {MAX_OUTSIDE})')
    parser.add_argument('--out', type=Path, help='also write the rows and offenders as JSON')
    return parser.parse_args(argv)


def room_dirs(raw_dir: Path, areas: list[int] | None) -> list[Path]:
    """The generated rooms (with meta.json) of the chosen areas, in a stable order."""
    if not raw_dir.is_dir():
        raise FileNotFoundError(f'{raw_dir}: no such folder')
    area_dirs = [raw_dir / f'Area_{n}' for n in areas] if areas else sorted(
        raw_dir.glob('Area_*'))
    for area in area_dirs:
        if not area.is_dir():
            raise FileNotFoundError(f'{area}: no such area folder')
    return sorted(room.parent for area in area_dirs for room in area.glob('*/meta.json'))


def main(argv: list[str] | None = None) -> int:
    """Check, print the table; returns the exit code."""
    args = parse_args(argv)
    try:
        if args.out:
            check_output(args.out, '--out', [args.raw_dir])
        rooms = room_dirs(args.raw_dir, args.areas)
        if not rooms:
            raise FileNotFoundError(f'{args.raw_dir}: no generated room (Area_N/<room>/meta.json)')
        fits = [fit for room in tqdm(rooms, desc='rooms', unit='room', disable=None)
                for fit in check_room(room, args.tolerance)]
    except (FileNotFoundError, SchemaError, PointFileError, OutputRefused) as error:
        print(f'check_annotations: error: {error}', file=sys.stderr)
        return 2
    rows = summarize(fits)
    bad = offenders(fits, args.max_outside)
    print(f'{len(fits)} objects in {len(rooms)} rooms; extent: largest horizontal extent of the '
          f'points / the box\'s; outside: share of points beyond the box + {args.tolerance:g} m; '
          f'coverage: share of the box inside the points\' extents')
    print(format_summary(rows))
    for fit in bad[:10]:
        print(f'  {describe(fit)}')
    if args.out:
        try:
            write_text(args.out, json.dumps({
                'format': 'synthdet.annotation_check/1',
                'tolerance': args.tolerance,
                'rows': rows,
                'offenders': [vars(f) for f in bad]
            }, indent=1) + '\n')
        except OutputFailed as error:
            print(f'check_annotations: error: {error}', file=sys.stderr)
            return 1
    if bad:
        print(f'check_annotations: {len(bad)} objects have more than '
              f'{args.max_outside:.1%} of their points outside their box', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
