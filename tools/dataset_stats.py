"""Print the paper's Table 1: detection instances per class and area, S3DIS vs synthetic.

Counts come from the info pickles ``<data_root>/s3dis_infos_Area_N.pkl`` written by
``tools/create_data.py``; ``--out table1.json`` also writes the table as JSON
(``synthdet.table1/1``) and as text (``table1.txt``). Example::

    python tools/dataset_stats.py data/s3dis --areas 1 2 3 4 5 6 7 8 9 --out work_dirs/table1.json

``--sensors`` prints instead the generator sensor models that scanned the areas' rooms (their
``meta.json``), one per line in the order of ``synthdet.contracts.SENSOR_MODELS``: the sensors
``tools/test.py --sensor`` has rooms for (``make exp2-cpu`` tests each of them).
"""
import argparse
import sys
from pathlib import Path

from projects.synthdet.evaluation.table1 import (
    count_instances, find_info_areas, format_table1, info_path, table1)
from synthdet.contracts import SENSOR_MODELS
from synthdet.info_files import InfoFileError, room_sensors
from synthdet.outputs import OutputFailed, OutputRefused, check_output
from projects.synthdet.evaluation.table_files import write_table


def sensors_of_areas(data_root: str, areas: list[int] | None, extra_tag: str) -> list[str]:
    """The sensor models that scanned the rooms of the areas' info pickles (default: every
    pickle found), in the order of ``SENSOR_MODELS``."""
    areas = find_info_areas(data_root, extra_tag) if areas is None else areas
    found = set()
    for area in areas:
        info_file = info_path(data_root, area, extra_tag)
        if not info_file.is_file():
            raise FileNotFoundError(
                f'{info_file}: info pickle not found (run tools/create_data.py)')
        found.update(room_sensors(info_file))
    return [model for model in SENSOR_MODELS if model in found]


def main(argv: list[str] | None = None) -> int:
    """Count, print Table 1 and optionally write it; returns the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('data_root', help='folder holding s3dis_infos_Area_N.pkl')
    parser.add_argument('--areas', type=int, nargs='+', help='areas (default: every pickle found)')
    parser.add_argument('--out', help='write the table to this JSON file and a .txt next to it')
    parser.add_argument(
        '--extra-tag', default='s3dis', help='the pickles are <extra-tag>_infos_Area_N.pkl')
    parser.add_argument(
        '--sensors',
        action='store_true',
        help='print the sensor models that scanned the rooms instead (one per line)')
    args = parser.parse_args(argv)
    try:
        if args.out:
            check_output(args.out, '--out', [args.data_root])
            check_output(Path(args.out).with_suffix('.txt'), '--out', [args.data_root])
        if args.sensors:
            print('\n'.join(sensors_of_areas(args.data_root, args.areas, args.extra_tag)))
            return 0
        counts = count_instances(args.data_root, args.areas, args.extra_tag)
    except (FileNotFoundError, InfoFileError, OutputRefused) as error:
        print(f'dataset_stats: error: {error}', file=sys.stderr)
        return 2
    document = table1(counts)
    text = (f'Table 1: detection instances per class, counted from the info pickles in '
            f'{args.data_root}\n{format_table1(document)}')
    print(text)
    if args.out:
        try:
            print(f'written to {args.out} and {write_table(args.out, document, text)}')
        except OutputFailed as error:
            print(f'dataset_stats: error: {error}', file=sys.stderr)
            return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
