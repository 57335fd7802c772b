"""Picture of a FreeCAD document as the FreeCAD GUI shows it on opening (under Xvfb).

``python -m configurator screenshot DOC.FCStd --out DOC.png [--width 1000] [--height 750]``

The real ``freecad`` GUI opens the document on a virtual X display (``Xvfb``), with a
fresh user configuration (no Start page), and saves its 3D view: what a user sees when they
open the file, with the view, colors and visibility the document stores.
"""
import argparse
import contextlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Iterator

from configurator.freecad_cli import (FreecadFailed, add_program_options, check_timeout,
                                      run_freecad_process)
from synthdet.cli import add_int_option
from synthdet.fcstd_guard import check_document
from synthdet.outputs import check_output_file, check_png, write_bytes
from synthdet.processes import ends_with_parent, work_folder

PIXELS = (16, 8000)  # the accepted --width and --height
GUI_SCRIPT = Path(__file__).resolve().parent / 'freecad' / 'screenshot_gui.py'
# A user configuration that opens no Start page (its web view cannot start as root).
USER_CONFIG = '''<?xml version="1.0" encoding="UTF-8" standalone="yes"?>
<FCParameters><FCParamGroup Name="Root"><FCParamGroup Name="BaseApp">
<FCParamGroup Name="Preferences"><FCParamGroup Name="General">
<FCText Name="AutoloadModule">NoneWorkbench</FCText>
</FCParamGroup></FCParamGroup></FCParamGroup></FCParamGroup></FCParameters>
'''


def write_gui_inputs(folder: Path, options: dict, options_name: str) -> tuple[Path, Path]:
    """Write FreeCAD's user config (``user.cfg``) and the ``options`` of the script FreeCAD runs
    (JSON, ``options_name``) into ``folder``; returns both paths."""
    config = folder / 'user.cfg'
    config.write_text(USER_CONFIG, encoding='utf-8')
    options_path = folder / options_name
    options_path.write_text(json.dumps(options), encoding='utf-8')
    return config, options_path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register the ``screenshot`` sub-command's options."""
    parser.add_argument('document', help='FreeCAD document (.FCStd)')
    parser.add_argument('--out', required=True, help='PNG to write')
    add_int_option(parser, '--width', *PIXELS, 1000, 'pixels')
    add_int_option(parser, '--height', *PIXELS, 750, 'pixels')
    add_program_options(parser, 'freecad', 'FreeCAD GUI executable', timeout=300.0)


@contextlib.contextmanager
def virtual_display(width: int, height: int, timeout: float = 30.0) -> Iterator[str]:
    """A private Xvfb server for the block; yields its ``DISPLAY`` (e.g. ``:7``).

    Xvfb picks a free display number itself (``-displayfd``), so several screenshots can run
    at once without the race of ``xvfb-run -a``; the server is stopped when the block ends.
    """
    read_end, write_end = os.pipe()
    try:
        command = ['Xvfb', '-displayfd', str(write_end), '-screen', '0', f'{width}x{height}x24',
                   '-nolisten', 'tcp']
        server = subprocess.Popen(command,
                                  pass_fds=(write_end, ),
                                  stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL,
                                  preexec_fn=ends_with_parent(os.getpid()))
    except FileNotFoundError:
        os.close(read_end)
        os.close(write_end)
        raise FreecadFailed('Xvfb not found: install it (apt-get install xvfb)') from None
    os.close(write_end)
    try:
        with os.fdopen(read_end, 'rb') as stream:
            number = stream.readline().strip()  # Xvfb writes the display once it is ready
        if not number.isdigit():
            raise FreecadFailed(f'Xvfb did not start (exit code {server.poll()})')
        yield f':{number.decode()}'
    finally:
        server.terminate()
        try:
            server.wait(timeout)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()


def screenshot(document: Path,
               out: Path,
               width: int = 1000,
               height: int = 750,
               freecad: str = 'freecad',
               timeout: float = 300.0) -> dict:
    """Open ``document`` in the FreeCAD GUI under Xvfb and save its 3D view to ``out``.

    Returns FreeCAD's report (``visible`` and ``objects`` counts). Raises ``ValueError`` for
    bad arguments (``RefusedDocument`` for a document FreeCAD would run code or open other
    files for; an ``out`` that is the document, a folder, a device or a FIFO),
    ``OutputFailed`` for an ``out`` in a folder that cannot be written (before FreeCAD starts)
    and ``FreecadFailed`` when no picture was made. FreeCAD saves the picture in a work folder; a
    whole PNG is then written to ``out`` through a checked temporary file (``OutputFailed``
    if it cannot be, the previous picture kept).
    """
    check_output_file(out, make_parents=True, inputs=[document])  # writable before FreeCAD
    document, out = Path(document).resolve(), Path(out).resolve()
    check_document(document)  # RefusedDocument (a ValueError) before FreeCAD starts
    if out.suffix.lower() != '.png':
        raise ValueError(f'{out}: the picture must end with .png')
    if not (PIXELS[0] <= width <= PIXELS[1] and PIXELS[0] <= height <= PIXELS[1]):
        raise ValueError(f'--width/--height {width}x{height}: expected {PIXELS[0]} to '
                         f'{PIXELS[1]} pixels')
    check_timeout(timeout)
    with work_folder('synthdet-screenshot') as work_dir:
        result_path, picture = work_dir / 'result.json', work_dir / 'view.png'
        config, options = write_gui_inputs(
            work_dir, {
                'document': str(document),
                'out': str(picture),
                'width': width,
                'height': height,
                'result': str(result_path),
                'paths': [str(GUI_SCRIPT.parent), str(GUI_SCRIPT.parents[2])]
            }, 'options.json')
        command = [freecad, '-u', str(config), str(GUI_SCRIPT)]
        with virtual_display(width + 200, height + 200) as display:
            # Qt settings of this process are not FreeCAD's: importing OpenCV (as mmcv does)
            # points QT_QPA_PLATFORM_PLUGIN_PATH at its own Qt, which makes FreeCAD abort.
            env = {key: value for key, value in os.environ.items() if not key.startswith('QT_')}
            env.update(SYNTHDET_SCREENSHOT=str(options), HOME=str(work_dir), DISPLAY=display)
            result = run_freecad_process(command, env, work_dir, timeout, result_path)
        if result['status'] != 'ok':
            raise FreecadFailed(f'{document}: {result["error"]}')
        if not picture.is_file():
            raise FreecadFailed(f'FreeCAD reported success but {out} was not written')
        data = picture.read_bytes()
        check_png(data, out)
        write_bytes(out, data)
    return result


def run(args: argparse.Namespace) -> int:
    """Run the sub-command; returns the exit code."""
    try:
        result = screenshot(args.document, args.out, args.width, args.height, args.freecad,
                            args.timeout)
    except ValueError as error:  # bad arguments: exit 2 (README, "Safety")
        print(f'error: {error}', file=sys.stderr)
        return 2
    except (FreecadFailed, OSError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    print(f'wrote {args.out}: {result["visible"]} of {result["objects"]} objects visible')
    return 0
