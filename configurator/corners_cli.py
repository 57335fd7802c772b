"""Find a scan's room corners and floor/ceiling levels and write them as synthdet.corners/1 JSON.

Usage: ``python -m configurator corners SCAN --out corners.json [--preview corners.png]
[--approximate]``. The scan (any format of ``synthdet.scan_io``) is streamed, voxel-filtered and
prepared (``synthdet.prepare``); the corners are written in the scan's own coordinates.
"""
from __future__ import annotations
import argparse
import os
import sys

from configurator.corners import (SCAN_VOXEL, CornerDetectionError, CornerParams, detect_corners,
                                  outline_in_scan, outline_to_dict, room_outline)
from synthdet.contracts import write_corners
from synthdet.outputs import OutputFailed, OutputRefused, check_output
from synthdet.prepare import prepare_scan
from synthdet.scan_io import SCAN_SUFFIXES, load_scan


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the ``corners`` sub-command's arguments."""
    parser.add_argument('scan', help=f'room scan: {", ".join(SCAN_SUFFIXES)} (docs/scans.md)')
    parser.add_argument(
        '--columns',
        help='what the values of a text scan\'s lines are, e.g. x,y,z,r,g,b or x,y,z,i '
        '(_ skips one; default: from their count)')
    parser.add_argument(
        '--voxel',
        type=_positive_metres,
        default=SCAN_VOXEL,
        help='keep one point per voxel of this size (m) while reading (default: %(default)s)')
    parser.add_argument('--out', required=True, help='output synthdet.corners/1 JSON file')
    parser.add_argument('--preview', help='optional PNG: the points from above with the outline')
    parser.add_argument(
        '--min-edge',
        type=_positive_metres,
        default=CornerParams.min_edge,
        help='walls shorter than this (m) are merged into their neighbours '
        '(default: %(default)s)')
    parser.add_argument(
        '--approximate',
        action='store_true',
        help='when no room outline can be traced, write an approximate floor (the footprint '
        'of the points or its bounding rectangle, quality.approximate_floor = 1) with a '
        'warning instead of failing')


def _positive_metres(text: str) -> float:
    value = float(text)
    if not 0 < value < 10:
        raise argparse.ArgumentTypeError(f'expected a length in metres in (0, 10), got {text}')
    return value


def _cannot_write(path: str | None) -> str | None:
    """Why the output file ``path`` cannot be written, checked before any work; else None."""
    if path is None:
        return None
    folder = os.path.dirname(os.path.abspath(path))
    return None if os.path.isdir(folder) else f'no folder {folder}'


def run(args: argparse.Namespace) -> int:
    """Detect the corners of ``args.scan``; returns 0, 2 with a message on bad input (an output
    that is the scan, a folder, a device or a FIFO too), or 1 if an output cannot be written
    (its folder checked before the scan is read)."""
    try:
        for option, output in (('--out', args.out), ('--preview', args.preview)):
            if output is not None:
                check_output(output, option, inputs=[args.scan])
    except OutputRefused as error:
        print(f'corners: {error}', file=sys.stderr)
        return 2
    for output in (args.out, args.preview):
        problem = _cannot_write(output)
        if problem:
            print(f'corners: cannot write {output}: {problem}', file=sys.stderr)
            return 1
    try:
        prepared = prepare_scan(load_scan(args.scan, voxel=args.voxel, columns=args.columns))
    except (OSError, ValueError) as error:  # ScanFormatError too
        print(f'corners: bad scan: {error}', file=sys.stderr)
        return 2
    # the reading and preparation notes (a float32 warning...) come first, also before a failure
    for line in prepared.report:
        print(f'corners: {line}', file=sys.stderr if line.startswith('warning') else sys.stdout)
    find = room_outline if args.approximate else detect_corners
    try:
        outline = outline_in_scan(find(prepared.points, CornerParams(min_edge=args.min_edge)),
                                  prepared)
    except CornerDetectionError as error:
        print(f'corners: no room found: {args.scan}: {error}', file=sys.stderr)
        return 2
    for note in outline.notes:
        print(f'corners: warning: {args.scan}: {note}', file=sys.stderr)
    result = outline_to_dict(outline, args.scan)
    try:
        write_corners(args.out, result)
    except OutputFailed as error:
        print(f'corners: {error}', file=sys.stderr)
        return 1
    ceiling = 'ceiling' if outline.quality.get('ceiling_found', 1.0) else 'no ceiling, walls to'
    print(f'corners: {len(outline.corners)} {"approximate " if outline.approximate else ""}'
          f'corners, floor z={outline.floor_z:.3f} m, {ceiling} z={outline.ceiling_z:.3f} m, '
          f'{outline.quality["wall_points_on_polygon"]:.0%} of wall points on the outline '
          f'-> {args.out}')
    if args.preview:
        from synthdet.room_data import Scan
        from synthdet.topview import draw_top_view
        points = prepared.points.copy()
        points[:, :3] = prepared.points_to_scan(points[:, :3])
        try:
            draw_top_view(
                args.preview,
                Scan(points, None, args.scan),
                corners=outline.corners,
                title=f'{args.scan}: {len(outline.corners)} corners, clockwise from 0')
        except OutputFailed as error:
            print(f'corners: {error}', file=sys.stderr)
            return 1
        print(f'corners: preview -> {args.preview}')
    return 0
