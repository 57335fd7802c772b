"""Every tool's outputs go one checked way (``synthdet.outputs``), tried with real processes.

- an output that is one of the inputs, a device, a FIFO or a folder is refused before any
  work (exit 2, one line naming the option and the path) and left as it was;
- on a full disk (files limited in size, as tests/test_repository/test_faults.py simulates it)
  a tool exits 1 naming the file, keeps the previous output and leaves no empty or truncated
  file;
- an output folder on a read-only file system is exit 1 with one line naming the output;
- what a run killed with ``kill -9`` left is removed by the next run writing there;
- names that are not UTF-8 are written and reported as given.
"""
import os
import resource
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from configurator.freecad_cli import build_document
from synthdet.outputs import PARTIAL
from synthdet.scan_io import write_scan
from tests.checkpoints import initial_checkpoint
from tests.room_scans import NoiseModel, make_room
from tests.test_configurator.test_freecad_outputs import dead_pid, write_inputs
from tests.test_repository.test_faults import assert_clean_error
from tests.tool_process import special_files

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
FULL_DISK_BYTES = 16 << 10  # files may not grow beyond 16 KiB: a picture does not fit


def run(*args: object, env: dict | None = None, **kwargs) -> subprocess.CompletedProcess:
    """Run ``python ARGS...`` from the repository root (one OpenMP thread, ``env`` added)."""
    return subprocess.run([sys.executable, *map(str, args)],
                          cwd=REPO,
                          capture_output=True,
                          text=kwargs.pop('text', True),
                          timeout=kwargs.pop('timeout', 900),
                          env={**os.environ, 'OMP_NUM_THREADS': '1', **(env or {})},
                          **kwargs)


def full_disk() -> None:  # in the child: every file it writes stops at FULL_DISK_BYTES
    resource.setrlimit(resource.RLIMIT_FSIZE, (FULL_DISK_BYTES, FULL_DISK_BYTES))


def temporaries(folder: Path) -> list[str]:
    """Names in ``folder`` that look like a run's temporary or a truncated leftover."""
    return sorted(p.name for p in folder.iterdir() if 'partial' in p.name or '.tmp' in p.name)


@pytest.fixture(scope='module')
def room(tmp_path_factory) -> Path:
    """A small L-shaped room scan (text)."""
    scan = tmp_path_factory.mktemp('room') / 'room.txt'
    write_scan(scan, make_room('L', 100_000, seed=3, noise=NoiseModel()).points)
    return scan


# ------------------------------------------------------------------ outputs that are no file


def test_an_output_that_is_the_scan_is_refused_before_any_work(room, tmp_path):
    scan = tmp_path / 'scan.txt'
    scan.write_bytes(room.read_bytes())
    link = tmp_path / 'link.txt'
    link.symlink_to(scan)
    for option, output in (('--out', scan), ('--out', link), ('--preview', scan)):
        extra = ['--out', tmp_path / 'room.json'] if option == '--preview' else []
        proc = run('-m', 'configurator', 'corners', scan, option, output, *extra)
        assert_clean_error(proc, 2, option, str(output), 'is the input')
        assert scan.read_bytes() == room.read_bytes()
        assert link.is_symlink()
    assert not (tmp_path / 'room.json').exists()  # refused before any work


def test_an_output_that_is_a_device_a_fifo_or_a_folder_is_refused(room, tmp_path):
    fifo, device, folder = special_files(tmp_path, '.json', '/dev/full')
    for output, kind in ((fifo, 'a FIFO'), (device, 'a device'), (folder, 'a folder')):
        proc = run('-m', 'configurator', 'corners', room, '--out', output, timeout=120)
        assert_clean_error(proc, 2, '--out', str(output), kind)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert device.is_symlink() and stat.S_ISCHR(os.stat(device).st_mode)
    assert folder.is_dir() and not list(folder.iterdir())
    proc = run('tools/visualize.py', room, '--out', fifo, timeout=120)
    assert_clean_error(proc, 2, '--out', str(fifo), 'a FIFO')
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    for output, kind in ((device, 'is a device'), (room, 'is a file, expected a folder')):
        proc = run('-m', 'generator', '--out', output, '--rooms-per-area', '1', timeout=120)
        assert_clean_error(proc, 2, '--out', str(output), kind)


# ------------------------------------------------------------------ a full disk


def test_visualize_on_a_full_disk_keeps_the_previous_picture(room, tmp_path):
    picture = tmp_path / 'room.png'
    proc = run('tools/visualize.py', room, '--out', picture)
    assert proc.returncode == 0, proc.stderr
    previous = picture.read_bytes()
    assert len(previous) > FULL_DISK_BYTES
    proc = run('tools/visualize.py', room, '--out', picture, '--title', 'again',
               preexec_fn=full_disk)
    assert_clean_error(proc, 1, str(picture), 'cannot write')
    assert picture.read_bytes() == previous
    new = tmp_path / 'new.png'
    proc = run('tools/visualize.py', room, '--out', new, preexec_fn=full_disk)
    assert_clean_error(proc, 1, str(new), 'cannot write')
    assert not new.exists()  # no empty or truncated picture
    assert temporaries(tmp_path) == []


def test_corners_preview_on_a_full_disk_is_a_failure_without_an_empty_picture(room, tmp_path):
    out = tmp_path / 'room.json'
    proc = run('-m', 'configurator', 'corners', room, '--out', out, '--preview',
               tmp_path / 'first.png')  # also compiles (and caches) the reader's kernels
    assert proc.returncode == 0, proc.stderr
    preview = tmp_path / 'room.png'
    proc = run('-m', 'configurator', 'corners', room, '--out', out, '--preview', preview,
               preexec_fn=full_disk)
    assert_clean_error(proc, 1, str(preview), 'cannot write')
    assert not preview.exists()
    assert temporaries(tmp_path) == []


@pytest.fixture(scope='module')
def document(tmp_path_factory) -> Path:
    """A FreeCAD document of a room with six parts, made by real freecadcmd."""
    folder = tmp_path_factory.mktemp('document')
    inputs = write_inputs(folder, 6)
    out = folder / 'room.FCStd'
    build_document(inputs['scan'], inputs['predictions'], out, inputs['corners'])
    return out


def test_screenshot_on_a_full_disk_is_a_failure_and_keeps_the_picture(document, tmp_path):
    picture = tmp_path / 'room.png'
    proc = run('-m', 'configurator', 'screenshot', document, '--out', picture)
    assert proc.returncode == 0, proc.stderr
    previous = picture.read_bytes()
    assert len(previous) > 1024
    # FreeCAD on a full disk: its files stop at 1 KiB, and it is told so (EFBIG), not killed
    full = tmp_path / 'freecad-on-a-full-disk'
    full.write_text("#!/bin/bash\ntrap '' XFSZ\nulimit -f 1\nexec freecad \"$@\"\n")
    full.chmod(0o755)
    proc = run('-m', 'configurator', 'screenshot', document, '--out', picture, '--freecad', full)
    assert_clean_error(proc, 1, str(picture), 'incomplete')
    assert picture.read_bytes() == previous
    assert temporaries(tmp_path) == []


def test_screenshot_whose_freecad_cannot_write_at_all_ends_before_its_timeout(document,
                                                                              tmp_path):
    """FreeCAD that can write no byte (not even its report) is a failure at once, exit 1, not
    a wait for ``--timeout``."""
    full = tmp_path / 'freecad-on-a-full-disk'
    full.write_text("#!/bin/bash\ntrap '' XFSZ\nulimit -f 0\nexec freecad \"$@\"\n")
    full.chmod(0o755)
    picture = tmp_path / 'room.png'
    start = time.perf_counter()
    proc = run('-m', 'configurator', 'screenshot', document, '--out', picture, '--freecad', full,
               '--timeout', '120')
    assert_clean_error(proc, 1, 'FreeCAD wrote no whole result')
    assert time.perf_counter() - start < 100 and not picture.exists()


def test_labels_eval_scans_and_dataset_stats_on_a_full_disk_name_the_output(
        document, checkpoint, room, tmp_path):
    """Exit 1, one line naming the file or room that did not fit, nothing half-written."""
    from tests.test_evaluation.test_dataset_stats import write_infos
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0.0, 6.0, (50_000, 2)),
                              rng.uniform(0.0, 2.8, 50_000), np.full((50_000, 3), 128.0)])
    scan = tmp_path / 'scan.xyz'
    write_scan(scan, points)
    labelled = tmp_path / 'labelled' / 'room.txt'
    labelled.parent.mkdir()
    labelled.write_bytes(room.read_bytes())
    labelled.with_name('room.labels.json').write_text(
        '{"format": "synthdet.labels/1", "scan": "room.txt", "boxes": [], '
        '"classes": ["table", "chair", "sofa", "yumi", "3dprinter"]}')
    write_infos(tmp_path, 1, [[0, 1], [2]])
    labels, evaluation = tmp_path / 'labels', tmp_path / 'evaluation'
    cases = [
        (['-m', 'configurator', 'labels', document, '--scan', scan, '--out', labels],
         labels / 'Area_10' / 'scan_1'),
        (['tools/eval_scans.py', TINY, checkpoint, labelled, '--out', evaluation, '--voxel',
          '0.05'], evaluation / 'room.pred.json'),
    ]
    for command, output in cases:
        proc = run(*command, env={'PYTHONWARNINGS': 'ignore'}, preexec_fn=full_disk)
        assert_clean_error(proc, 1, f'{output}: cannot write')
        assert not output.exists() and temporaries(output.parent) == []
    table = tmp_path / 'table1.md'
    proc = run('tools/dataset_stats.py', tmp_path, '--out', table,
               preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0)))
    assert_clean_error(proc, 1, f'{table}: cannot write')
    assert not table.exists() and temporaries(tmp_path) == []


# ------------------------------------------------------------------ a read-only folder


def run_read_only(folder: Path, *args: object) -> tuple[subprocess.CompletedProcess, float]:
    """Run ``python ARGS...`` with ``folder`` a read-only file system: a tmpfs mounted read-only
    in a private mount namespace of that process (a user namespace: no root needed, and the
    mount ends with the process). Returns the process and its wall time in seconds."""
    folder.mkdir()
    mount = 'mount -t tmpfs -o ro,size=64k tmpfs "$0" && exec "$@"'
    start = time.perf_counter()
    proc = subprocess.run(['unshare', '--map-root-user', '--mount', 'sh', '-c', mount,
                           str(folder), sys.executable, *map(str, args)],
                          cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, 'OMP_NUM_THREADS': '1', 'PYTHONWARNINGS': 'ignore'})
    return proc, time.perf_counter() - start


def test_a_read_only_output_folder_is_one_line_naming_the_output(room, document, tmp_path):
    """Exit 1 and one line naming the output (not a temporary of the run); the tools that
    check their output folder first do so before FreeCAD, Blender, training or detection
    start."""
    read_only = tmp_path / 'read-only'
    cases = [
        (['tools/visualize.py', room, '--out', read_only / 'room.png'], 'room.png: cannot write'),
        (['-m', 'configurator', 'screenshot', document, '--out', read_only / 'room.png'],
         'cannot write in'),
        (['-m', 'generator.assets', '--out', read_only / 'assets', '--classes', 'chair'],
         'cannot write in'),
        (['tools/train.py', TINY, '--work-dir', read_only / 'train'], 'cannot write in'),
        (['tools/test.py', TINY, 'missing.pth', '--work-dir', read_only / 'test'],
         'cannot write in'),
        (['tools/demo.py', '--size', 'tiny', '--work-dir', read_only / 'demo'],
         'cannot write in'),
        (['tools/eval_scans.py', TINY, 'missing.pth', room, '--out', read_only / 'eval'],
         'cannot write in'),
        (['-m', 'generator', '--out', read_only / 'rooms', '--rooms-per-area', '1'],
         'cannot write in'),
    ]
    for command, message in cases:
        proc, seconds = run_read_only(read_only, *command)
        assert_clean_error(proc, 1, str(read_only), message)
        assert 'partial' not in proc.stderr and seconds < 120, (command, proc.stderr[-2000:])
        read_only.rmdir()


# ------------------------------------------------------------------ leftovers of killed runs


def _start(*args: object, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *map(str, args)],
                            cwd=REPO,
                            env={**os.environ, 'OMP_NUM_THREADS': '1', **(env or {})},
                            stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE,
                            start_new_session=True)


def _kill_9_when(process: subprocess.Popen, ready, timeout: float = 600) -> None:
    """``kill -9`` the process (only it: its children end by themselves) once ``ready()``."""
    deadline = time.monotonic() + timeout
    while not ready():
        assert process.poll() is None, process.stderr.read().decode()[-2000:]
        assert time.monotonic() < deadline, 'never ready'
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait(60)
    process.stderr.close()


def _runs_freecad(process: subprocess.Popen) -> bool:
    try:
        children = psutil.Process(process.pid).children(recursive=True)
        return any('freecad' in child.name().lower() for child in children)
    except psutil.NoSuchProcess:
        return False


@pytest.fixture(scope='module')
def checkpoint(tmp_path_factory) -> Path:
    return initial_checkpoint(TINY, tmp_path_factory.mktemp('model') / 'tiny.pth')


def _scan2cad(scan: Path, out: Path, checkpoint: Path) -> list:
    return ['tools/scan2cad.py', scan, '--config', TINY, '--checkpoint', checkpoint, '--out',
            out, '--device', 'cpu']


def test_a_run_after_kill_9_of_scan2cad_removes_its_leftovers(room, checkpoint, tmp_path):
    work = tmp_path / 'tmp'
    work.mkdir()
    out_dir = tmp_path / 'out'
    out_dir.mkdir()
    out = out_dir / 'room.FCStd'
    killed = _start(*_scan2cad(room, out, checkpoint), env={'TMPDIR': str(work)})
    _kill_9_when(killed, lambda: _runs_freecad(killed))
    proc = run(*_scan2cad(room, out, checkpoint), env={'TMPDIR': str(work)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert sorted(p.name for p in out_dir.iterdir()) == [
        'room.FCStd', 'room.corners.json', 'room.pred.json']
    assert list(work.iterdir()) == []


def test_scan2cad_writes_a_name_that_is_not_utf8_as_given(room, checkpoint, tmp_path):
    scan = Path(os.fsdecode(bytes(tmp_path) + b'/caf\xe9.xyz'))
    write_scan(scan, np.loadtxt(room))
    proc = run(*_scan2cad(scan, scan.with_suffix('.FCStd'), checkpoint), text=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    names = sorted(os.listdir(os.fsencode(tmp_path)))
    assert names == [b'caf\xe9.FCStd', b'caf\xe9.corners.json', b'caf\xe9.pred.json',
                     b'caf\xe9.xyz']
    assert bytes(tmp_path) + b'/caf\xe9.FCStd' in proc.stdout  # reported as given


def test_a_run_after_kill_9_of_labels_removes_its_partial_room(tmp_path):
    inputs = write_inputs(tmp_path, 6)
    document = tmp_path / 'room.FCStd'
    build_document(inputs['scan'], inputs['predictions'], document, inputs['corners'])
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0.0, 6.0, (3_000_000, 2)),
                              rng.uniform(0.0, 2.8, 3_000_000), np.full((3_000_000, 3), 128.0)])
    scan = tmp_path / 'scan.bin'
    write_scan(scan, points)
    out = tmp_path / 'labels'
    area = out / 'Area_10'
    command = ('-m', 'configurator', 'labels', document, '--scan', scan, '--out', out)
    killed = _start(*command)
    _kill_9_when(killed, lambda: area.is_dir() and any('partial' in p.name
                                                       for p in area.iterdir()))
    proc = run(*command)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert sorted(p.name for p in area.iterdir()) == ['scan_1']


def test_only_temporaries_of_ended_runs_are_removed(room, tmp_path):
    """Stale names of a dead process go; those of a live one and any other name stay."""
    dead, alive = dead_pid(), os.getpid()
    stale = [f'.room.corners.{dead}.0a1b2c3d.partial.json', f'.room.{dead}.0a1b2c3d.partial.json',
             f'.room_1.{dead}.0a1b2c3d.partial', f'.room.partial-{dead}-0a1b2c3d.FCStd1']
    kept = [f'.room.{alive}.0a1b2c3d.partial.json', f'.room.{dead}.partial.json',
            'room.partial.json', f'room.{dead}.0a1b2c3d.partial.json']
    for name in stale + kept:
        (tmp_path / name).write_text('left by a run')
    (tmp_path / stale[2]).unlink()
    (tmp_path / stale[2]).mkdir()  # a partial folder (of `configurator labels`)
    assert all(PARTIAL.fullmatch(name) for name in stale)
    proc = run('-m', 'configurator', 'corners', room, '--out', tmp_path / 'room.json')
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept + ['room.json'])


# ------------------------------------------------------------------ names that are not UTF-8


def test_freecad_writes_a_name_that_is_not_utf8_as_given(tmp_path):
    inputs = write_inputs(tmp_path, 3)
    out = bytes(tmp_path) + b'/r\xe9sultat.FCStd'
    proc = run('-m', 'configurator', 'freecad', '--scan', inputs['scan'], '--predictions',
               inputs['predictions'], '--corners', inputs['corners'], '--out', os.fsdecode(out),
               text=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert os.path.isfile(out)
    assert b'wrote ' + out + b': 3 objects' in proc.stdout
    assert sorted(n for n in os.listdir(os.fsencode(tmp_path)) if n.endswith(b'.FCStd')) == [
        b'r\xe9sultat.FCStd']
