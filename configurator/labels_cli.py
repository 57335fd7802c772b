"""Turn a corrected synthdet FreeCAD document into labels and an S3DIS room.

``python -m configurator labels ROOM.FCStd --scan SCAN --out DIR [--area 1] [--room NAME]``

Writes ``DIR/<scan stem>.labels.json`` (``synthdet.labels/1``, for ``tools/eval_scans.py``) and
``DIR/Area_<N>/<room>/`` (S3DIS format, for ``tools/create_data.py``); see
``configurator/labels.py`` for the rules and docs/teach.md for the workflow.
"""
import argparse
import sys

from configurator.freecad_cli import add_program_options, run_reporting_errors
from synthdet.cli import MAX_AREA, int_in


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register the ``labels`` sub-command's options."""
    parser.add_argument('document', help='the corrected FreeCAD document (.FCStd)')
    parser.add_argument('--scan', required=True, help='the scan the document was made from')
    parser.add_argument('--out', required=True, help='output folder')
    parser.add_argument('--area', type=int_in(1, MAX_AREA), default=10,
                        help=f'S3DIS area number, 1 to {MAX_AREA} (default 10, the area '
                        'teach_finetune.py trains)')
    parser.add_argument('--room', help='S3DIS room name <name>_<number> (default: <scan stem>_1)')
    add_program_options(parser, 'freecadcmd', 'FreeCAD command-line executable', timeout=300.0)


def run(args: argparse.Namespace) -> int:
    """Run the sub-command; 2 for bad input (one line naming the file), 1 when FreeCAD fails,
    128 + the signal number when interrupted."""
    from configurator.labels import make_labels, summary_line
    summary, code = run_reporting_errors(
        lambda: make_labels(args.document, args.scan, args.out, args.area, args.room,
                            args.freecadcmd, args.timeout))
    if code:
        return code
    for warning in summary['warnings']:
        print(f'warning: {warning}', file=sys.stderr)
    print(summary_line(summary))
    return 0
