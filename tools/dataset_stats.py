"""Print the paper's Table 1: detection instances per class and area, S3DIS vs synthetic.

Counts come from the info pickles ``<data_root>/s3dis_infos_Area_N.pkl`` written by
``tools/create_data.py``. Example::

    python tools/dataset_stats.py data/s3dis --areas 1 2 3 4 5 6 7 8 9
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages

from projects.synthdet.datasets.instance_counts import (  # noqa: E402
    InfoFileError, count_instances, format_table1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('data_root', help='folder holding s3dis_infos_Area_N.pkl')
    parser.add_argument('--areas', type=int, nargs='+', help='areas (default: every pickle found)')
    args = parser.parse_args(argv)
    try:
        counts = count_instances(args.data_root, args.areas)
    except (FileNotFoundError, InfoFileError) as error:
        print(f'dataset_stats: error: {error}', file=sys.stderr)
        return 2
    print(f'Table 1: detection instances per class, counted from the info pickles in '
          f'{args.data_root}')
    print(format_table1(counts))
    return 0


if __name__ == '__main__':
    sys.exit(main())
