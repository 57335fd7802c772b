"""CLI: build the procedural asset library as one `<class>.blend` per class.

    python -m generator.assets --out DIR [--instances 24] [--seed 0] [--classes chair table]
                               [--preview PNG_DIR]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from generator.assets.library import ASSET_CLASSES, build_library, load_library
from synthdet.cli import OneLineParser, add_int_option, int_in
from synthdet.outputs import OutputFailed, OutputRefused, check_output_dir

MAX_INSTANCES = 10_000


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(
        prog='python -m generator.assets',
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        '--out', type=Path, required=True, help='folder for the <class>.blend files')
    add_int_option(parser, '--instances', 1, MAX_INSTANCES, 24, 'instances per class')
    parser.add_argument(
        '--seed', type=int_in(0, 2**63 - 1), default=0, help='0 to 2^63-1 (default 0)')
    parser.add_argument(
        '--classes',
        nargs='+',
        default=list(ASSET_CLASSES),
        choices=ASSET_CLASSES,
        metavar='CLASS',
        help=f'classes to build (default: all of {" ".join(ASSET_CLASSES)})')
    parser.add_argument(
        '--preview',
        type=Path,
        default=None,
        help='also draw one PNG per class of the built library into this folder')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build (and draw) the library; returns 0, 2 with one line for an output that is not a
    folder (checked first), 1 with one line when a folder or a file cannot be written."""
    args = parse_args(argv)
    try:
        check_output_dir(args.out, '--out')
        if args.preview is not None:
            check_output_dir(args.preview, '--preview')
        _build(args)
    except OutputRefused as error:
        print(f'generator.assets: error: {error}', file=sys.stderr)
        return 2
    except OutputFailed as error:
        print(f'generator.assets: error: {error}', file=sys.stderr)
        return 1
    return 0


def _build(args: argparse.Namespace) -> None:
    start = time.perf_counter()
    paths = build_library(args.out, args.instances, args.seed, args.classes)
    print(f'built {len(paths)} library files in {time.perf_counter() - start:.1f} s:')
    library = load_library(args.out)
    for cls in library.classes():
        print(f'  {args.out / (cls + ".blend")}: {len(library.instances(cls))} instances')
    if args.preview is not None:
        from generator.assets.preview import render_previews
        for path in render_previews(library, args.preview):
            print(f'  preview {path}')


if __name__ == '__main__':
    sys.exit(main())
