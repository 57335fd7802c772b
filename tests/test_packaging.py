"""``pip install .`` into a fresh venv that already has the native stack gives a working install.

The fresh venv sees the project's stack (torch, mmcv, MinkowskiEngine, bpy, ...) through a ``.pth``
line, as a machine that built the stack once would, and installs synthdet from a copy of the
working tree with ``--no-index``: the install may not need the network, and every
``install_requires`` entry must be met by the stack. The checks then run from outside the
source tree, so only the installed files can be imported.
"""
import json
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from tests.room_scans import make_room

REPO = Path(__file__).resolve().parents[1]
SOURCE_IGNORE = shutil.ignore_patterns('.git', '.venv', 'work_dirs', 'data', '__pycache__',
                                       '*.egg-info', 'build', '.pytest_cache')
# Console scripts and the module each must run (see setup.cfg [options.entry_points]).
CONSOLE_SCRIPTS = ('synthdet-generate', 'synthdet-configurator')


def run(command: list, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``command``; fail the test with its output when it exits non-zero."""
    result = subprocess.run([str(part) for part in command],
                            cwd=cwd,
                            capture_output=True,
                            text=True,
                            timeout=timeout)
    assert result.returncode == 0, f'{command} exited {result.returncode}:\n' \
                                   f'{result.stdout[-3000:]}\n{result.stderr[-3000:]}'
    return result


@pytest.fixture(scope='module')
def installed(tmp_path_factory) -> dict:
    """A fresh venv with synthdet installed from a copy of the working tree."""
    root = tmp_path_factory.mktemp('packaging')
    source = root / 'source'
    shutil.copytree(REPO, source, ignore=SOURCE_IGNORE, symlinks=True)
    venv = root / 'venv'
    run([sys.executable, '-m', 'venv', '--without-pip', venv], cwd=root)
    python = venv / 'bin' / 'python'
    purelib = Path(
        run([python, '-c', 'import sysconfig; print(sysconfig.get_paths()["purelib"])'],
            cwd=root).stdout.strip())
    stack = sysconfig.get_paths()['purelib']  # this interpreter's site-packages: the stack
    (purelib / 'native_stack.pth').write_text(stack + '\n')
    run([python, '-m', 'pip', 'install', '--no-index', '--no-build-isolation', '--quiet', source],
        cwd=root)
    outside = root / 'elsewhere'
    outside.mkdir()
    return {'python': python, 'bin': venv / 'bin', 'purelib': purelib, 'cwd': outside}


def test_packages_import_from_the_install_not_the_source_tree(installed):
    code = ('import json, configurator, generator, projects.synthdet, synthdet; '
            'print(json.dumps([m.__file__ for m in '
            '(configurator, generator, projects.synthdet, synthdet)]))')
    files = json.loads(run([installed['python'], '-c', code], cwd=installed['cwd']).stdout)
    for file in files:
        assert Path(file).is_relative_to(installed['purelib']), file


def test_macro_profiles_and_license_are_installed(installed):
    purelib = installed['purelib']
    macro = purelib / 'configurator' / 'freecad' / 'ImportSynthdet.FCMacro'
    assert macro.read_text() == (REPO / 'configurator/freecad/ImportSynthdet.FCMacro').read_text()
    profiles = sorted(p.name for p in (purelib / 'generator' / 'profiles').glob('*.json'))
    assert profiles == sorted(p.name for p in (REPO / 'generator' / 'profiles').glob('*.json'))
    assert 'paper.json' in profiles
    licences = list(purelib.glob('synthdet-*.dist-info/**/LICENSE'))
    assert licences and 'Apache License' in licences[0].read_text()


@pytest.mark.parametrize('script', CONSOLE_SCRIPTS)
def test_console_scripts_answer_help(installed, script):
    result = run([installed['bin'] / script, '--help'], cwd=installed['cwd'])
    assert result.stdout.startswith('usage:')


def test_installed_configurator_builds_a_freecad_document(installed):
    """The installed package data (the FreeCAD macro) works: corners, then a document."""
    work = installed['cwd']
    room = make_room('L', n_points=60_000, seed=3, furniture=0)
    scan = work / 'room.txt'
    np.savetxt(scan, room.points, fmt='%.4f')
    corners = work / 'room.corners.json'
    run([installed['bin'] / 'synthdet-configurator', 'corners', scan, '--out', corners], cwd=work)
    found = json.loads(corners.read_text())['corners']
    assert len(found) == 6
    predictions = work / 'room.pred.json'
    centre = np.asarray(room.polygon).mean(axis=0)
    predictions.write_text(
        json.dumps({
            'format': 'synthdet.predictions/1',
            'scan': 'room.txt',
            'model': 'test',
            'classes': ['table'],
            'detections': [{
                'class': 'table',
                'score': 0.9,
                'center': [float(centre[0]), float(centre[1]), room.floor_z + 0.375],
                'size': [1.2, 0.8, 0.75],
                'yaw': 0.0
            }]
        }))
    document = work / 'room.FCStd'
    run([
        installed['bin'] / 'synthdet-configurator', 'freecad', '--scan', scan, '--predictions',
        predictions, '--corners', corners, '--out', document
    ],
        cwd=work)
    assert document.stat().st_size > 0
