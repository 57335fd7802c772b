"""What ``pip install .`` and the editable install (``pip install -e .``) put on ``sys.path``.

The wheel holds one top-level package, the shared library ``synthdet``: the generic names of the
clone's other folders (``generator``, ``configurator``, ``projects``) are not installed. The
editable install, the one ``scripts/setup.sh`` makes, is a ``.pth`` line naming the clone, so
``generator``, ``configurator``, ``projects.synthdet``, ``tools`` and ``tests`` import under their
one name from any folder. Both are built from a copy of the working tree without network access,
into fresh venvs that see the project's stack (numpy, torch, ...) through a ``.pth`` line, as a
machine that built the stack once would; the checks run outside the source tree.
"""
import json
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from synthdet.scan_io import write_scan
from tests.room_scans import make_room

REPO = Path(__file__).resolve().parents[2]
SOURCE_IGNORE = shutil.ignore_patterns('.git', '.venv', 'work_dirs', 'data', '__pycache__',
                                       '*.egg-info', 'build', '.pytest_cache')
CLONE_ONLY = ('generator', 'configurator', 'projects')


def run(command: list, cwd: Path, check: bool = True) -> subprocess.CompletedProcess:
    """Run ``command``; with ``check``, fail the test with its output when it exits non-zero."""
    result = subprocess.run([str(part) for part in command],
                            cwd=cwd,
                            capture_output=True,
                            text=True,
                            timeout=600)
    if check:
        assert result.returncode == 0, f'{command} exited {result.returncode}:\n' \
                                       f'{result.stdout[-3000:]}\n{result.stderr[-3000:]}'
    return result


def fresh_venv(root: Path) -> dict:
    """A venv under ``root`` that sees this interpreter's site-packages (the stack) via a .pth."""
    venv = root / 'venv'
    run([sys.executable, '-m', 'venv', '--without-pip', venv], cwd=root)
    python = venv / 'bin' / 'python'
    purelib = Path(
        run([python, '-c', 'import sysconfig; print(sysconfig.get_paths()["purelib"])'],
            cwd=root).stdout.strip())
    (purelib / 'native_stack.pth').write_text(sysconfig.get_paths()['purelib'] + '\n')
    outside = root / 'elsewhere'
    outside.mkdir()
    return {'python': python, 'purelib': purelib, 'cwd': outside}


def copy_source(root: Path) -> Path:
    """A copy of the working tree without its build outputs, data and venv."""
    source = root / 'source'
    shutil.copytree(REPO, source, ignore=SOURCE_IGNORE, symlinks=True)
    return source


@pytest.fixture(scope='module')
def wheel(tmp_path_factory) -> Path:
    """The wheel ``pip wheel`` builds from a copy of the working tree."""
    root = tmp_path_factory.mktemp('wheel')
    source = copy_source(root)
    run([
        sys.executable, '-m', 'pip', 'wheel', '--no-deps', '--no-build-isolation', '--no-index',
        '--quiet', '--wheel-dir', root / 'dist', source
    ],
        cwd=root)
    (built, ) = (root / 'dist').glob('synthdet-*.whl')
    return built


@pytest.fixture(scope='module')
def installed(wheel, tmp_path_factory) -> dict:
    """A fresh venv with the wheel installed (its ``install_requires`` met by the stack)."""
    env = fresh_venv(tmp_path_factory.mktemp('installed'))
    run([env['python'], '-m', 'pip', 'install', '--no-index', '--quiet', wheel], cwd=env['cwd'])
    return env


@pytest.fixture(scope='module')
def editable(tmp_path_factory) -> dict:
    """A fresh venv with a copy of the clone installed the way scripts/setup.sh installs it."""
    root = tmp_path_factory.mktemp('editable')
    env = fresh_venv(root)
    env['source'] = copy_source(root)
    run([
        env['python'], '-m', 'pip', 'install', '--no-deps', '--no-build-isolation', '--no-index',
        '--quiet', '-e', env['source']
    ],
        cwd=env['cwd'])
    return env


def test_wheel_has_one_top_level_package_synthdet(wheel):
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        (top_level, ) = [name for name in names if name.endswith('.dist-info/top_level.txt')]
        assert archive.read(top_level).decode().split() == ['synthdet']
        licence = [name for name in names if name.endswith('/LICENSE')]
        assert licence and 'Apache License' in archive.read(licence[0]).decode()
    roots = {name.split('/')[0] for name in names}
    assert roots == {'synthdet', 'synthdet-0.1.0.dist-info'}
    # every module of the library, subpackages included, and nothing else
    library = {path.relative_to(REPO).as_posix() for path in (REPO / 'synthdet').rglob('*.py')}
    assert {name for name in names if name.endswith('.py')} == library


def test_installed_library_reads_a_scan_outside_the_clone(installed):
    points = make_room('L', n_points=2_000, seed=1).points
    write_scan(installed['cwd'] / 'room.ply', points)
    code = ('import json, synthdet, synthdet.scan_io as scan_io; '
            'points = scan_io.read_scan("room.ply"); '
            'print(json.dumps([synthdet.__file__, scan_io.__file__, len(points)]))')
    package, scan_io, count = json.loads(run([installed['python'], '-c', code],
                                             cwd=installed['cwd']).stdout)
    assert Path(package).is_relative_to(installed['purelib'])
    assert Path(scan_io).is_relative_to(installed['purelib'])
    assert count == len(points)


@pytest.mark.parametrize('name', CLONE_ONLY)
def test_install_has_no_generic_top_level_package(installed, name):
    result = run([installed['python'], '-c', f'import {name}'], cwd=installed['cwd'], check=False)
    assert result.returncode == 1
    assert f"No module named '{name}'" in result.stderr
    assert not (installed['purelib'] / name).exists()


def test_editable_install_imports_the_clone_under_its_folder_names(editable):
    modules = ('synthdet.scan_io', 'generator.config', 'configurator.corners',
               'projects.synthdet', 'tests.room_scans')
    code = ('import importlib, json, sys; '
            f'files = [importlib.import_module(m).__file__ for m in {modules!r}]; '
            'print(json.dumps(files))')
    files = json.loads(run([editable['python'], '-c', code], cwd=editable['cwd']).stdout)
    for module, file in zip(modules, files):
        expected = editable['source'].joinpath(*module.split('.'))
        assert Path(file) in (expected / '__init__.py', expected.with_suffix('.py')), module


def test_a_tool_runs_from_another_folder_with_the_editable_install(editable):
    """A tool imports the clone's packages through the install; it inserts no path itself."""
    tool = editable['source'] / 'tools' / 'check_annotations.py'
    assert 'sys.path' not in tool.read_text()
    result = run([editable['python'], tool, '--help'], cwd=editable['cwd'])
    assert result.stdout.startswith('usage:')
