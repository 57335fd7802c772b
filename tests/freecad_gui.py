"""Run a test driver script inside the FreeCAD GUI (offscreen), as the GUI macro tests do."""
import json
import os
import subprocess
from pathlib import Path

from configurator.freecad_cli import MACRO
from configurator.freecad_screenshot import write_gui_inputs

# Lines of a driver: run the macro while its ``answer()`` answers the dialogs every 100 ms.
RUN_MACRO_ANSWERING = """\
timer = QtCore.QTimer()
timer.timeout.connect(answer)
timer.start(100)
with open(params['macro'], encoding='utf-8') as stream:
    code = compile(stream.read(), params['macro'], 'exec')
exec(code, {'__file__': params['macro'], '__name__': '__main__'})
timer.stop()
"""
# The last lines of a driver: write ``seen`` to the report and leave at once (the offscreen
# platform has no OpenGL context to tear the 3D view down).
WRITE_REPORT = """\
with open(params['report'], 'w', encoding='utf-8') as stream:
    json.dump(seen, stream)
os._exit(0)
"""


def run_gui_driver(folder: Path, driver_source: str, params: dict, **env: str) -> dict:
    """Run ``driver_source`` in ``freecad`` with the project's user config and return the JSON
    report it writes.

    The driver reads its parameters from the JSON file named by ``SYNTHDET_TEST_PARAMS``:
    ``params`` plus ``macro`` (the synthdet macro) and ``report`` (where to write the report).
    ``env`` adds environment variables. Fails with FreeCAD's output when no report is written.
    """
    driver = folder / 'drive_gui.py'
    driver.write_text(driver_source, encoding='utf-8')
    report = folder / 'gui.json'
    config, params_path = write_gui_inputs(folder, {
        'macro': str(MACRO),
        'report': str(report),
        **params
    }, 'gui_params.json')
    process = subprocess.run(
        ['freecad', '-u', str(config), str(driver)],
        env=dict(
            os.environ, QT_QPA_PLATFORM='offscreen', SYNTHDET_TEST_PARAMS=str(params_path), **env),
        cwd=folder,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        errors='replace',
        timeout=300)
    assert report.is_file(), process.stdout[-3000:]
    return json.loads(report.read_text(encoding='utf-8'))
