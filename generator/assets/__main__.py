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
from synthdet.outputs import OutputFailed, OutputRefused, check_output


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='python -m generator.assets',
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        '--out', type=Path, required=True, help='folder for the <class>.blend files')
    parser.add_argument('--instances', type=int, default=24, help='instances per class')
    parser.add_argument('--seed', type=int, default=0)
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
    args = parser.parse_args(argv)
    if args.instances < 1:
        parser.error(f'--instances must be >= 1, got {args.instances}')
    if args.seed < 0:
        parser.error(f'--seed must be >= 0, got {args.seed}')
    return args


def main(argv: list[str] | None = None) -> int:
    """Build (and draw) the library; returns 0, 2 with one line for an output that is not a
    folder (checked first), 1 with one line when a file cannot be written."""
    args = parse_args(argv)
    try:
        check_output(args.out, '--out', folder=True)
        if args.preview is not None:
            check_output(args.preview, '--preview', folder=True)
    except OutputRefused as error:
        print(f'generator.assets: error: {error}', file=sys.stderr)
        return 2
    try:
        _build(args)
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
