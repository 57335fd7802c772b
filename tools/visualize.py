"""Draw a scan from above, colored by class, with ground-truth and predicted boxes (PNG), and
export it as PLY.

    python tools/visualize.py Area_9/factory_1/factory_1.txt --gt Area_9/factory_1/meta.json \\
        --pred factory_1.pred.json --corners factory_1.corners.json --out factory_1.png \\
        [--ply factory_1.ply] [--color-by class|rgb|height] [--min-score 0.3]

SCAN is an S3DIS room ``.txt`` (classes from its ``Annotations/``), a converted
``points/<room>.bin`` (classes from ``semantic_mask/``), or any scan ``synthdet.scan_io`` reads
(``.e57``, ``.las``/``.laz``, ``.ply``, ``.pcd``, ``.xyz``/``.pts``/``.csv``, ``.txt``, ``.bin``;
then colored by RGB or height). ``--gt`` takes a generator ``meta.json`` or an info pickle
(``s3dis_infos_Area_N.pkl``, matched by the scan's file name).
"""
from __future__ import annotations

import argparse
import sys

from synthdet.cli import OneLineParser, add_score_option
from synthdet.outputs import check_output, names_as_given
from synthdet.room_data import (boxes_from_predictions, corner_polygon,
                                 load_ground_truth, load_scan, write_labelled_ply)
from synthdet.topview import draw_top_view


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=' '.join(__doc__.split('\n\n')[0].split()))
    parser.add_argument('scan', help='S3DIS room .txt, a points/*.bin or any scan (docs/scans.md)')
    parser.add_argument('--gt', help='ground truth: generator meta.json or info .pkl')
    parser.add_argument('--pred', help='predictions JSON (synthdet.predictions/1)')
    parser.add_argument('--corners', help='corners JSON (synthdet.corners/1)')
    parser.add_argument('--out', required=True, help='output PNG')
    parser.add_argument('--ply', help='also write the scan as PLY (with class indices)')
    parser.add_argument(
        '--color-by',
        choices=('class', 'rgb', 'height'),
        help='point colors (default: class if annotated, else rgb/height)')
    add_score_option(parser, '--min-score', 0.3, 'draw predictions scoring at least this')
    parser.add_argument('--title', default='', help='figure title (default: the scan name)')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Draw (and export) one scan; returns the exit code: 2 with a message for bad inputs (an
    output that is an input, a folder, a device or a FIFO too, before any work), 1 when an
    output cannot be written."""
    args = parse_args(argv)
    names_as_given()
    try:
        inputs = (args.scan, args.gt, args.pred, args.corners)
        for option, output in (('--out', args.out), ('--ply', args.ply)):
            if output is not None:
                check_output(output, option, inputs)
        scan = load_scan(args.scan)
        gt = load_ground_truth(args.gt, args.scan) if args.gt else []
        pred = boxes_from_predictions(args.pred, args.min_score) if args.pred else []
        corners = corner_polygon(args.corners) if args.corners else None
        draw_top_view(args.out, scan, gt, pred, corners, args.color_by, args.title)
        if args.ply:
            write_labelled_ply(args.ply, scan)
    except (ValueError, KeyError) as error:  # a bad input file: exit 2 (docs/safety.md)
        print(f'visualize: error: {error}', file=sys.stderr)
        return 2
    except OSError as error:  # e.g. an unwritable output: exit 1
        print(f'visualize: error: {error}', file=sys.stderr)
        return 1
    print(f'wrote {args.out} ({len(scan.points)} points, {len(gt)} ground-truth and '
          f'{len(pred)} predicted boxes)' + (f' and {args.ply}' if args.ply else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
