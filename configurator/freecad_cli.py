"""Build a parametric FreeCAD document (.FCStd) from a scan's detections and room corners.

``python -m configurator freecad --scan SCAN --predictions PRED.json --out room.FCStd
[--corners CORNERS.json] [--library DIR] [--min-score 0.3] [--wall-thickness 0.1]``

The inputs are validated here, then real ``freecadcmd`` runs ``ImportSynthdet.FCMacro`` (the
same macro a FreeCAD user runs from the GUI) with a job JSON, and the macro's result JSON is
checked.
"""
import argparse
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Callable, TypeVar

from configurator.freecad.synthdet_freecad.schema import JOB_FORMAT, RESULT_FORMAT
from synthdet.cli import MAX_TIMEOUT, add_score_option, check_input_file, float_in, seconds
from synthdet.contracts import load_json, read_corners, read_predictions, validate_corners
from synthdet.outputs import check_output, copy_into_place, readable
from synthdet.processes import ends_with_parent, work_folder

T = TypeVar('T')

MACRO = Path(__file__).resolve().parent / 'freecad' / 'ImportSynthdet.FCMacro'
MAX_WALL_THICKNESS = 2.0  # metres
wall_thickness_option = float_in(0.0, MAX_WALL_THICKNESS, include_low=False)


class FreecadFailed(RuntimeError):
    """FreeCAD did not produce the document."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register the ``freecad`` sub-command's options."""
    parser.add_argument('--scan', required=True, help='the scan (.txt, .bin or .ply)')
    parser.add_argument('--predictions', required=True, help='synthdet.predictions/1 JSON')
    parser.add_argument('--out', required=True, help='FreeCAD document to write (.FCStd)')
    parser.add_argument('--corners', help='synthdet.corners/1 JSON (default: from the scan)')
    parser.add_argument('--library', help='folder of <class>.step files replacing built-ins')
    add_score_option(parser, '--min-score', 0.3, 'skip detections scoring below this')
    parser.add_argument(
        '--wall-thickness',
        type=wall_thickness_option,
        default=0.1,
        help=f'wall thickness in metres, up to {MAX_WALL_THICKNESS:g} (default 0.1)')
    add_program_options(parser, 'freecadcmd', 'FreeCAD command-line executable', timeout=900.0)


def add_program_options(parser: argparse.ArgumentParser, program: str, what: str,
                        timeout: float) -> None:
    """``--<program>`` (default: ``$SYNTHDET_<PROGRAM>``, else ``program``) and ``--timeout``."""
    parser.add_argument(
        f'--{program}',
        default=os.environ.get(f'SYNTHDET_{program.upper()}', program),
        help=f'{what} (default: {program})')
    parser.add_argument(
        '--timeout',
        type=seconds,
        default=timeout,
        help=f'seconds to wait for FreeCAD, up to {MAX_TIMEOUT:.0f} (default {timeout:.0f})')


def check_input_scan(scan: Path) -> None:
    """``InputFileError`` (a ``ValueError``) unless ``scan`` is a regular file that is not
    empty: a folder, a FIFO or a link to a device is named as such."""
    check_input_file(scan, 'scan file')
    if scan.stat().st_size == 0:
        raise ValueError(f'{scan}: the scan is empty')


def check_timeout(timeout: float) -> None:
    """Raise ``ValueError`` unless ``timeout`` is a positive number of seconds, at most
    ``MAX_TIMEOUT`` (a week)."""
    if not 0.0 < timeout <= MAX_TIMEOUT:  # NaN fails too
        raise ValueError(f'--timeout {timeout:g}: expected a number of seconds in '
                         f'(0, {MAX_TIMEOUT:.0f}]')


def _corners_from_scan(scan: Path) -> dict:
    from configurator.corners import CornerDetectionError, corners_for_scan
    try:
        corners = corners_for_scan(scan)
    except CornerDetectionError as error:
        raise CornerDetectionError(f'{scan}: no room found: {error}') from None
    return validate_corners(corners, f'corners computed from {scan}')


def run_freecad_process(command: list[str], env: dict, work_dir: Path, timeout: float,
                        result_path: Path) -> dict:
    """Run a FreeCAD process that reports through a JSON file; returns that report.

    Raises ``FreecadFailed`` when the program is missing, times out or writes no report.
    """
    try:
        process = _run_process_group(command, env, work_dir, timeout)
    except FileNotFoundError:
        raise FreecadFailed(f'{command[0]!r} not found: install FreeCAD (apt-get install '
                            'freecad) or pass its path') from None
    except subprocess.TimeoutExpired:
        raise FreecadFailed(f'FreeCAD did not finish within {timeout:.0f} s') from None
    if not result_path.is_file():
        output = (process.stderr.strip() or process.stdout.strip())[-2000:]
        raise FreecadFailed(f'FreeCAD exited with code {process.returncode} without a result '
                            f'from {Path(command[-1]).name}:\n{output}')
    try:
        return load_json(str(result_path))
    except ValueError as error:  # cut short: FreeCAD could not write it whole (a full disk)
        raise FreecadFailed(f'FreeCAD wrote no whole result: {error}') from None


def _run_freecad(job: dict, work_dir: Path, freecadcmd: str, timeout: float) -> dict:
    job_path = work_dir / 'job.json'
    result_path = work_dir / 'result.json'
    job_path.write_text(json.dumps(job, indent=1), encoding='utf-8')
    env = dict(os.environ, SYNTHDET_JOB=str(job_path), SYNTHDET_RESULT=str(result_path))
    result = run_freecad_process([freecadcmd, str(MACRO)], env, work_dir, timeout, result_path)
    if not isinstance(result, dict) or result.get('format') != RESULT_FORMAT:
        raise FreecadFailed(f'{result_path}: not a {RESULT_FORMAT} result')
    if result.get('status') != 'ok':
        raise FreecadFailed(f'FreeCAD import failed: {result.get("error")}')
    for key in ('warnings', 'objects'):
        if not isinstance(result.get(key), list):
            raise FreecadFailed(f'{result_path}: the {RESULT_FORMAT} result has no "{key}" list')
    return result


def _run_process_group(command: list[str], env: dict, cwd: Path,
                       timeout: float) -> subprocess.CompletedProcess:
    """Run ``command`` in its own process group; a timeout or an interruption kills the group,
    and the program gets SIGKILL when this process ends in any way (``kill -9`` included).

    FreeCAD may start helper processes: killing only ``freecadcmd`` would leave them running.
    """
    process = subprocess.Popen(
        command,
        env=env,
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        errors='replace',
        start_new_session=True,
        preexec_fn=ends_with_parent(os.getpid()))
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except BaseException:  # TimeoutExpired, Ctrl-C, SIGTERM turned into an exception
        os.killpg(process.pid, signal.SIGKILL)
        process.communicate()
        raise
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)


def build_document(scan: Path,
                   predictions: Path,
                   out: Path,
                   corners: Path | None = None,
                   library: Path | None = None,
                   min_score: float = 0.3,
                   wall_thickness: float = 0.1,
                   freecadcmd: str = 'freecadcmd',
                   timeout: float = 900.0) -> dict:
    """Validate the inputs, run FreeCAD and return the macro's result (objects, warnings).

    Raises ``SchemaError``/``ValueError`` for bad inputs (``OutputRefused`` for an ``out`` that
    is an input, a folder, a device or a FIFO) and ``FreecadFailed`` when FreeCAD does not
    produce the document. FreeCAD saves in a work folder under a name it can open (bytes that
    are not UTF-8 replaced); the finished document is then copied to a checked temporary file
    beside ``out`` and renamed into place (``synthdet.outputs``): ``out`` keeps the name given.
    """
    check_output(out, '--out', inputs=[scan, predictions, corners])
    scan, predictions, out = Path(scan), Path(predictions), Path(out).resolve()
    check_input_scan(scan)
    read_predictions(str(predictions))
    if out.suffix.lower() != '.fcstd':
        raise ValueError(f'{out}: the output must end with .FCStd')
    if library is not None and not Path(library).is_dir():
        raise ValueError(f'{library}: library folder not found')
    if not 0.0 <= min_score <= 1.0:  # NaN fails too
        raise ValueError(f'--min-score {min_score}: expected a score in [0, 1]')
    if not 0.0 < wall_thickness <= MAX_WALL_THICKNESS:
        raise ValueError(f'--wall-thickness {wall_thickness:g}: expected a thickness in metres '
                         f'in (0, {MAX_WALL_THICKNESS:g}]')
    check_timeout(timeout)
    with work_folder('synthdet-freecad') as work_dir:
        if corners is not None:
            read_corners(str(corners))
            corners_path = Path(corners).resolve()
        else:
            corners_path = work_dir / 'corners.json'
            corners_path.write_text(json.dumps(_corners_from_scan(scan)), encoding='utf-8')
        job = {
            'format': JOB_FORMAT,
            'predictions': str(predictions.resolve()),
            'corners': str(corners_path),
            'out': str(work_dir / readable(out.name)),
            'library': str(Path(library).resolve()) if library is not None else None,
            'min_score': min_score,
            'wall_thickness': wall_thickness
        }
        result = _run_freecad(job, work_dir, freecadcmd, timeout)
        if not os.path.isfile(job['out']):
            raise FreecadFailed(f'FreeCAD reported success but {out} was not written')
        copy_into_place([(job['out'], out)])
    return dict(result, document=str(out))


def run_reporting_errors(step: Callable[[], T]) -> tuple[T | None, int]:
    """Run ``step`` so that SIGINT/SIGTERM end FreeCAD; a failure prints one ``error:`` line.

    Returns ``(result, 0)``, or ``(None, exit code)``: 2 for bad input (a ``ValueError``:
    SchemaError, ScanFormatError, CornerDetectionError, LabelsInputError), 1 when FreeCAD fails
    or a file cannot be used, 128 + the signal number when interrupted.
    """
    from synthdet.processes import Interrupted, stop_on_signals
    try:
        with stop_on_signals():
            return step(), 0
    except ValueError as error:
        print(f'error: {error}', file=sys.stderr)
        return None, 2
    except (FreecadFailed, OSError) as error:
        print(f'error: {error}', file=sys.stderr)
        return None, 1
    except Interrupted as stop:
        print(f'error: stopped by {stop}; FreeCAD was ended', file=sys.stderr)
        return None, stop.exit_code


def run(args: argparse.Namespace) -> int:
    """Run the sub-command; prints warnings and a summary, returns the exit code.

    2 for bad inputs (the message names the file), 1 when FreeCAD fails, 128 + the signal
    number when interrupted; the previous document at ``--out`` is kept in every case.
    """
    result, code = run_reporting_errors(
        lambda: build_document(args.scan, args.predictions, args.out, args.corners, args.library,
                               args.min_score, args.wall_thickness, args.freecadcmd,
                               args.timeout))
    if code:
        return code
    for warning in result['warnings']:
        print(f'warning: {warning}', file=sys.stderr)
    groups = {}
    for obj in result['objects']:
        groups[obj['group']] = groups.get(obj['group'], 0) + 1
    summary = ', '.join(f'{count} in {group}' for group, count in sorted(groups.items()))
    print(f'wrote {result["document"]}: {len(result["objects"])} objects'
          f'{" (" + summary + ")" if summary else ""}, '
          f'{result["skipped_low_score"]} below --min-score')
    return 0
