"""Create mmdet3d info pickles and point/mask .bin files from S3DIS-format data.

Example::

    python tools/create_data.py s3dis --root-path data/s3dis --out-dir data/s3dis --workers 2
"""
import argparse
import sys

from projects.synthdet.datasets.s3dis_converter import (
    OutputOverflowError, S3DISLayoutError, convert_s3dis)
from synthdet.cli import MAX_AREA, OneLineParser, add_int_option, int_in
from synthdet.point_text import PointFileError
from synthdet.processes import Interrupted, stop_on_signals

MAX_WORKERS = 256


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='dataset', required=True)
    s3dis = sub.add_parser('s3dis', help='S3DIS-format areas (real areas 1-6, synthetic 7-9)')
    s3dis.add_argument(
        '--root-path',
        required=True,
        help='folder holding Stanford3dDataset_v1.2_Aligned_Version/')
    s3dis.add_argument('--out-dir', required=True, help='output folder (e.g. the same data/s3dis)')
    s3dis.add_argument(
        '--areas',
        type=int_in(1, MAX_AREA),
        nargs='+',
        help=f'area numbers, 1 to {MAX_AREA} (default: all found)')
    add_int_option(s3dis, '--workers', 1, MAX_WORKERS, 1, 'parallel processes over rooms')
    s3dis.add_argument(
        '--on-error',
        choices=('raise', 'skip'),
        default='raise',
        help='stop at the first bad input, or skip bad lines/files and report them')
    s3dis.add_argument(
        '--extra-tag',
        default='s3dis',
        help='name the info pickles <extra-tag>_infos_Area_N.pkl (the configs read s3dis)')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Convert; exit 0, 2 for bad input (or nothing converted), 1 for a failure while writing."""
    args = parse_args(argv)
    try:
        with stop_on_signals():
            summary = convert_s3dis(
                args.root_path,
                args.out_dir,
                areas=args.areas,
                workers=args.workers,
                on_error=args.on_error,
                info_prefix=args.extra_tag)
    except (PointFileError, S3DISLayoutError, OutputOverflowError) as error:
        print(f'create_data: error: {error}', file=sys.stderr)
        return 2
    except OSError as error:
        print(f'create_data: error: {error.filename or args.out_dir}: '
              f'{error.strerror or error}', file=sys.stderr)
        return 1
    except Interrupted as stop:
        print(f'create_data: stopped by {stop}; no partial output is left', file=sys.stderr)
        return stop.exit_code
    print(summary.report())
    if not sum(summary.rooms_per_area.values()):
        print(f'create_data: error: {args.root_path}: no room could be converted',
              file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
