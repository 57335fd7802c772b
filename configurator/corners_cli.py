"""Find a scan's room corners and floor/ceiling levels and write them as synthdet.corners/1 JSON.

Usage: ``python -m configurator corners SCAN --out corners.json [--preview corners.png]``.
"""
from __future__ import annotations
import argparse
import sys

from configurator.corners import (CornerDetectionError, CornerParams, detect_corners,
                                  outline_to_dict)
from synthdet.contracts import write_corners
from synthdet.scan_io import read_scan


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the ``corners`` sub-command's arguments."""
    parser.add_argument('scan', help='room scan: S3DIS .txt, .bin (float32 N x 6) or .ply')
    parser.add_argument('--out', required=True, help='output synthdet.corners/1 JSON file')
    parser.add_argument('--preview', help='optional PNG: the points from above with the outline')
    parser.add_argument(
        '--min-edge',
        type=_positive_metres,
        default=CornerParams.min_edge,
        help='walls shorter than this (m) are merged into their neighbours '
        '(default: %(default)s)')


def _positive_metres(text: str) -> float:
    value = float(text)
    if not 0 < value < 10:
        raise argparse.ArgumentTypeError(f'expected a length in metres in (0, 10), got {text}')
    return value


def run(args: argparse.Namespace) -> int:
    """Detect the corners of ``args.scan``; returns 0, 2 with a message on bad input, or 1 if
    the output cannot be written."""
    try:
        points = read_scan(args.scan)
        outline = detect_corners(points, CornerParams(min_edge=args.min_edge))
    except (OSError, ValueError) as error:  # ScanFormatError and CornerDetectionError too
        kind = 'no room found' if isinstance(error, CornerDetectionError) else 'bad scan'
        print(f'corners: {kind}: {error}', file=sys.stderr)
        return 2
    result = outline_to_dict(outline, args.scan)
    try:
        write_corners(args.out, result)
    except OSError as error:
        print(f'corners: cannot write {args.out}: {error.strerror or error}', file=sys.stderr)
        return 1
    print(f'corners: {len(outline.corners)} corners, floor z={outline.floor_z:.3f} m, '
          f'ceiling z={outline.ceiling_z:.3f} m, '
          f'{outline.quality["wall_points_on_polygon"]:.0%} of wall points on the outline '
          f'-> {args.out}')
    if args.preview:
        from synthdet.room_data import Scan
        from synthdet.topview import draw_top_view
        draw_top_view(
            args.preview,
            Scan(points, None, args.scan),
            corners=outline.corners,
            title=f'{args.scan}: {len(outline.corners)} corners, clockwise from 0')
        print(f'corners: preview -> {args.preview}')
    return 0
