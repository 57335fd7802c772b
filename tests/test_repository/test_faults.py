"""Safe and fault-tolerant, tried with real processes as an attacker and an unlucky user.

- checkpoints: a checkpoint that runs code when unpickled is refused by predict, test, train
  --resume and publish_model, and creates no file; training writes an inference checkpoint that
  plain ``torch.load(weights_only=True)`` reads; full unpickling needs --trust-checkpoint and a
  checkpoint inside the work directory;
- process hygiene: ``kill -9`` of the generator's and of create_data's parent leaves no worker
  and publishes nothing more, and the same command then gives the bytes of a clean run;
  SIGINT/SIGTERM stop with a message, no traceback and no partial output;
- configurator: far outliers cost no memory, a scan without floor is an error, a georeferenced
  float64 scan is exact and a georeferenced float32 one gets a warning; a failing FreeCAD save
  keeps the old document; placements that overflow in millimetres or degrees are rejected; --timeout ends
  FreeCAD's whole process group;
- converter: class names from ``<class>_<index>.txt`` (any case of the suffix), float32
  overflow named, exit codes (2 bad input, 1 run-time failure).
"""
import hashlib
import json
import os
import pickle
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
import torch

from configurator.freecad_cli import FreecadFailed, build_document
from projects.synthdet.datasets.s3dis_converter import UnknownClassWarning, convert_s3dis
from synthdet.classes import SEMANTIC_CLASSES
from synthdet.scan_io import write_scan
from tests.room_scans import NoiseModel, make_room
from tests.s3dis_fixtures import S3DIS_DIR, write_synthetic_area
from tests.test_generator.test_generator_pipeline import same_tree
from tests.test_tools.test_tr3d_tools import data_options

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / 'configs' / 'tr3d' / 'tiny.py'
TINY_CLASSES = ['table', 'chair', 'sofa', 'yumi', '3dprinter']
GEO_OFFSET = np.array([500_000.0, 5_000_000.0])  # UTM-like coordinates


def run(*args: object, timeout: float = 600, **kwargs) -> subprocess.CompletedProcess:
    """Run ``python ARGS...`` from the repository root with one OpenMP thread."""
    env = {**os.environ, 'OMP_NUM_THREADS': '1'}
    return subprocess.run([sys.executable, *map(str, args)],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=timeout,
                          env=env,
                          **kwargs)


def assert_clean_error(proc: subprocess.CompletedProcess, code: int, *fragments: str) -> None:
    """Exit ``code``, no traceback, and one stderr line holding every fragment."""
    assert proc.returncode == code, proc.stderr[-3000:]
    assert 'Traceback' not in proc.stderr, proc.stderr[-3000:]
    lines = [line for line in proc.stderr.splitlines() if all(f in line for f in fragments)]
    assert len(lines) == 1, proc.stderr[-3000:]


def wait_until(condition, timeout: float, interval: float = 0.01) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(interval)
    return condition()


def alive(processes: list[psutil.Process]) -> list[psutil.Process]:
    """The processes that still run (zombies waiting for a reaper count as ended)."""
    running = []
    for process in processes:
        try:
            if process.status() != psutil.STATUS_ZOMBIE:
                running.append(process)
        except psutil.NoSuchProcess:
            pass
    return running


def signal_when(process: subprocess.Popen, ready, signum: int) -> tuple:
    """Once ``ready()`` holds, send ``signum`` to the process (started with piped, text
    stderr); returns its CompletedProcess and the child processes it had then."""
    try:
        assert wait_until(lambda: ready() or process.poll() is not None, 300)
        workers = psutil.Process(process.pid).children(recursive=True)
        assert process.poll() is None, 'the run ended before the signal'
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=120)
    finally:
        kill_group(process)
    return subprocess.CompletedProcess(process.args, process.returncode, '', stderr), workers


def kill_group(process: subprocess.Popen) -> None:
    """End whatever is left of a test's process group (started with ``start_new_session``)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


# ------------------------------------------------------------------------------ checkpoints


class OpensMarker:
    """Unpickling this object calls ``open(marker, 'w')``: a stand-in for any hidden code."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, 'w')


@pytest.fixture(scope='module')
def trained(tmp_path_factory) -> dict:
    """Two converted rooms, one epoch of tools/train.py, and a malicious checkpoint."""
    root = tmp_path_factory.mktemp('faults_checkpoints')
    write_synthetic_area(root / 'raw', area=1, n_rooms=2, seed=11, points_per_object=300)
    convert_s3dis(root / 'raw', root / 'data', areas=[1])
    work = root / 'work'
    proc = run('tools/train.py', TINY, '--work-dir', work, '--cfg-options',
               *data_options(root / 'data'), 'train_cfg.max_epochs=1', 'val_cfg=None',
               'val_dataloader=None', 'val_evaluator=None')
    assert proc.returncode == 0, proc.stderr[-3000:]
    weights = torch.load(work / 'inference.pth', weights_only=True)['state_dict']
    marker = root / 'MARKER'
    evil = root / 'evil.pth'
    torch.save({'meta': {}, 'state_dict': weights, 'payload': OpensMarker(marker)}, evil)
    return {
        'root': root,
        'data': root / 'data',
        'work': work,
        'evil': evil,
        'marker': marker,
        'scan': root / 'raw' / S3DIS_DIR / 'Area_1' / 'office_1' / 'office_1.txt',
        'stdout': proc.stdout
    }


def test_the_malicious_checkpoint_really_runs_code_when_fully_unpickled(trained, tmp_path):
    probe = tmp_path / 'probe.pth'
    torch.save({'payload': OpensMarker(tmp_path / 'PROBE')}, probe)
    torch.load(probe, weights_only=False)
    assert (tmp_path / 'PROBE').exists()  # so a missing MARKER below means: refused


@pytest.mark.slow
def test_malicious_checkpoint_is_refused_by_every_tool(trained):
    evil, root = trained['evil'], trained['root']
    commands = {
        'predict': ['tools/predict.py', TINY, evil, trained['scan'], '--out', root / 'pred'],
        'test': [
            'tools/test.py', TINY, evil, '--work-dir', root / 'test', '--cfg-options',
            *data_options(trained['data'])
        ],
        'publish': ['tools/publish_model.py', evil, root / 'published.pth'],
        'resume': [
            'tools/train.py', TINY, '--work-dir', root / 'resumed', '--resume', evil,
            '--cfg-options', *data_options(trained['data']), 'train_cfg.max_epochs=2',
            'val_cfg=None', 'val_dataloader=None', 'val_evaluator=None'
        ],
        'trust outside the work dir': [
            'tools/train.py', TINY, '--work-dir', root / 'trusted', '--resume', evil,
            '--trust-checkpoint', '--cfg-options', *data_options(trained['data'])
        ],
    }
    for name, command in commands.items():
        proc = run(*command)
        fragment = 'inside the work directory' if name.startswith('trust') else 'refused'
        assert_clean_error(proc, 2, str(evil), fragment)
        assert not trained['marker'].exists(), f'{name} ran the code in the checkpoint'
    assert not list(root.glob('published*.pth'))


@pytest.mark.slow
def test_trust_checkpoint_unpickles_only_the_resumed_file_of_the_work_dir(trained, tmp_path):
    work = tmp_path / 'work'
    work.mkdir()
    inside = work / 'epoch_1.pth'
    inside.write_bytes(trained['evil'].read_bytes())
    marker = trained['marker']
    proc = run('tools/train.py', TINY, '--work-dir', work, '--resume', inside, '--cfg-options',
               *data_options(trained['data']), 'train_cfg.max_epochs=2')
    assert_clean_error(proc, 2, 'refused', '--trust-checkpoint')  # the hint names the flag
    assert not marker.exists()
    proc = run('tools/train.py', TINY, '--work-dir', work,
               '--resume', inside, '--trust-checkpoint', '--cfg-options',
               *data_options(trained['data']), 'train_cfg.max_epochs=2')
    # the user vouched for this file: it was unpickled fully (the payload ran), then mmengine
    # found no epoch in its meta
    assert marker.exists() and proc.returncode != 0
    marker.unlink()


def test_training_writes_an_inference_checkpoint_and_publish_model_makes_one(trained, tmp_path):
    work = trained['work']
    assert f'{work / "inference.pth"}' in trained['stdout']
    inference = torch.load(work / 'inference.pth', weights_only=True)  # no allowlist needed
    assert set(inference) == {'meta', 'state_dict'}
    assert list(inference['meta']['dataset_meta']['classes']) == TINY_CLASSES
    assert inference['meta']['epoch'] == 1
    with pytest.raises(pickle.UnpicklingError):  # the training checkpoint needs more than that
        torch.load(work / 'epoch_1.pth', weights_only=True)
    from projects.synthdet.checkpoint import load_checkpoint_file
    training = load_checkpoint_file(work / 'epoch_1.pth')  # weights-only with the allowlist
    assert {'optimizer', 'message_hub'} <= set(training)
    assert inference['state_dict'].keys() == training['state_dict'].keys()
    for key, value in training['state_dict'].items():
        assert torch.equal(value, inference['state_dict'][key]), key

    proc = run('tools/publish_model.py', work / 'epoch_1.pth', tmp_path / 'tiny.pth')
    assert proc.returncode == 0, proc.stderr[-2000:]
    (published, ) = tmp_path.glob('tiny-*.pth')
    digest = hashlib.sha256(published.read_bytes()).hexdigest()
    assert published.name == f'tiny-{digest[:8]}.pth' and f'published {published}' in proc.stdout
    loaded = torch.load(published, weights_only=True)
    assert set(loaded) == {'meta', 'state_dict'}
    assert all(torch.equal(v, loaded['state_dict'][k]) for k, v in training['state_dict'].items())


@pytest.mark.slow
def test_predict_with_either_checkpoint_and_scans_checked_before_the_model(trained, tmp_path):
    outputs = {}
    for name in ('inference.pth', 'epoch_1.pth'):
        out = tmp_path / name
        proc = run('tools/predict.py', TINY, trained['work'] / name, trained['scan'], '--out', out,
                   '--score-thr', '0')
        assert proc.returncode == 0, proc.stderr[-2000:]
        outputs[name] = json.loads((out / 'office_1.pred.json').read_text())
    assert outputs['inference.pth'] == outputs['epoch_1.pth']
    assert outputs['inference.pth']['classes'] == TINY_CLASSES
    # a bad second scan is found before the (here missing) checkpoint is even looked at
    bad = tmp_path / 'bad.txt'
    bad.write_text('1 2 3 4 5 6\n1 2 x 4 5 6\n')
    proc = run('tools/predict.py', TINY, tmp_path / 'missing.pth', trained['scan'], bad, '--out',
               tmp_path / 'never')
    assert_clean_error(proc, 2, f'{bad}:2')
    assert not (tmp_path / 'never').exists()


# --------------------------------------------------------------------------- process hygiene


@pytest.fixture(scope='module')
def asset_cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp('faults_assets')


def _generator_args(cache: Path, rooms: int) -> list[str]:
    return [
        '--areas', '7', '--rooms-per-area',
        str(rooms), '--points', '20000', '--seed', '3', '--asset-cache',
        str(cache), '--quiet'
    ]


def _rooms(out: Path) -> set[str]:
    return {p.name for p in (out / 'Area_7').glob('factory_*')}


@pytest.mark.slow
def test_kill_9_of_the_generator_ends_its_workers_and_a_rerun_is_byte_identical(
        asset_cache, tmp_path):
    from generator.__main__ import main
    args = _generator_args(asset_cache, rooms=5)
    clean, killed = tmp_path / 'clean', tmp_path / 'killed'
    assert main([*args, '--out', str(clean), '--workers', '1']) == 0
    process = subprocess.Popen(
        [sys.executable, '-m', 'generator', *args, '--out',
         str(killed), '--workers', '2'],
        cwd=REPO,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    try:
        parent = psutil.Process(process.pid)
        assert wait_until(lambda: len(_rooms(killed)) >= 1, 300), 'no room was published'
        workers = parent.children(recursive=True)
        assert len(workers) >= 2 and process.poll() is None, 'the run ended before the kill'
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        published = _rooms(killed)  # the parent is gone: from now on nothing may appear
        assert wait_until(lambda: not alive(workers), 10), f'orphans: {alive(workers)}'
        time.sleep(3)
        assert _rooms(killed) == published, 'a room was published after the parent died'
        assert len(published) < 5
    finally:
        kill_group(process)
    assert main([*args, '--out', str(killed), '--workers', '2']) == 0
    same_tree(clean, killed)
    assert not list(killed.glob('Area_*/.tmp.*'))


@pytest.mark.slow
def test_sigint_stops_the_generator_without_traceback(asset_cache, tmp_path):
    out = tmp_path / 'out'
    process = subprocess.Popen([
        sys.executable, '-m', 'generator', *_generator_args(asset_cache, rooms=6), '--out',
        str(out), '--workers', '2'
    ],
                               cwd=REPO,
                               start_new_session=True,
                               stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE,
                               text=True)
    proc, workers = signal_when(process, lambda: _rooms(out), signal.SIGINT)
    assert_clean_error(proc, 130, 'stopped by SIGINT')
    assert wait_until(lambda: not alive(workers), 10)


def _area_for_conversion(root: Path, rooms: int, points_per_object: int) -> Path:
    write_synthetic_area(root, area=1, n_rooms=rooms, seed=4, points_per_object=points_per_object)
    return root


def _create_data(raw: Path, out: Path, *extra: str) -> list[str]:
    return [
        REPO / 'tools' / 'create_data.py', 's3dis', '--root-path', raw, '--out-dir', out, *extra
    ]


@pytest.fixture(scope='module')
def big_area(tmp_path_factory) -> Path:
    """24 rooms of ~50k points: a conversion that lasts long enough to be killed."""
    return _area_for_conversion(tmp_path_factory.mktemp('faults_raw'), 24, 3000)


def _start(command: list, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *map(str, command)],
                            cwd=REPO,
                            start_new_session=True,
                            env={
                                **os.environ, 'OMP_NUM_THREADS': '1'
                            },
                            **kwargs)


def _partials(out: Path, pattern: str = '*.partial') -> list[Path]:
    return list(out.rglob(pattern))


@pytest.mark.slow
def test_kill_9_of_create_data_ends_its_workers_and_a_rerun_is_byte_identical(big_area, tmp_path):
    clean, killed = tmp_path / 'clean', tmp_path / 'killed'
    proc = run(*_create_data(big_area, clean, '--workers', '1'))
    assert proc.returncode == 0, proc.stderr[-2000:]
    process = _start(
        _create_data(big_area, killed, '--workers', '2'),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    try:
        # A room half-written (only workers write room .bin partials; the parent renames them
        # as results arrive). The parent is stopped at once, so that on a loaded machine it
        # cannot finish the run before the kill; its workers keep their partials.
        assert wait_until(
            lambda: process.poll() is not None or _partials(killed, '*.bin.partial'), 120)
        assert process.poll() is None, 'the run ended before the kill'
        os.kill(process.pid, signal.SIGSTOP)
        workers = psutil.Process(process.pid).children(recursive=True)
        assert len(workers) == 2
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        assert wait_until(lambda: not alive(workers), 10), f'orphans: {alive(workers)}'
    finally:
        kill_group(process)
    assert _partials(killed) and not (killed / 's3dis_infos_Area_1.pkl').exists()
    proc = run(*_create_data(big_area, killed, '--workers', '2'))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert not _partials(killed)
    same_tree(clean, killed)  # the pickle too: its bytes do not depend on --workers


@pytest.mark.slow
def test_sigterm_stops_create_data_cleanly(big_area, tmp_path):
    out = tmp_path / 'out'
    process = _start(
        _create_data(big_area, out, '--workers', '2'),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True)
    proc, workers = signal_when(process, lambda: _partials(out), signal.SIGTERM)
    assert_clean_error(proc, 143, 'stopped by SIGTERM')
    assert not _partials(out) and not (out / 's3dis_infos_Area_1.pkl').exists()
    assert wait_until(lambda: not alive(workers), 10)


# ------------------------------------------------------------------------------ configurator


def _limit_memory() -> None:  # in the child: 3 GiB of address space (the old grid needed 18.7)
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def _corners(scan: Path, out: Path) -> subprocess.CompletedProcess:
    return run('-m', 'configurator', 'corners', scan, '--out', out, preexec_fn=_limit_memory)


def _corner_error(corners: list, polygon: np.ndarray) -> float:
    from synthdet.geometry import distance_to_polygon
    return float(distance_to_polygon(np.array(corners), polygon).max())


@pytest.fixture(scope='module')
def l_room():
    return make_room('L', 100_000, seed=3, noise=NoiseModel())


def test_far_outliers_cost_no_memory(l_room, tmp_path):
    rng = np.random.default_rng(0)
    far = [  # dense clusters, so the density test of the preparation keeps them
        np.column_stack([centre + rng.normal(0.0, 0.02, (50, 3)), np.zeros((50, 3))])
        for centre in ([1000.0, 1000.0, 1.0], [5000.0, -5000.0, 2.0])
    ]
    scan = tmp_path / 'far.txt'
    write_scan(scan, np.vstack([l_room.points, *far]))
    proc = _corners(scan, tmp_path / 'far.json')
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads((tmp_path / 'far.json').read_text())
    assert len(result['corners']) == 6
    assert _corner_error(result['corners'], l_room.polygon) < 0.01
    assert result['quality']['far_points'] > 0  # left out by the corner search itself


def test_corners_output_under_a_file_is_refused_before_any_work(l_room, tmp_path):
    scan = tmp_path / 'room.txt'
    write_scan(scan, l_room.points)
    blocked = tmp_path / 'file'
    blocked.write_text('')
    proc = _corners(scan, blocked / 'room.json')
    assert_clean_error(proc, 2, 'cannot be used', str(blocked / 'room.json'))


def test_scan_without_floor_is_an_error(l_room, tmp_path):
    points = l_room.points[l_room.points[:, 2] > l_room.floor_z + 0.05]
    scan = tmp_path / 'no_floor.txt'
    write_scan(scan, points)
    proc = _corners(scan, tmp_path / 'no_floor.json')
    assert_clean_error(proc, 2, 'no floor found')
    assert not (tmp_path / 'no_floor.json').exists()


def test_georeferenced_scans(l_room, tmp_path):
    points = l_room.points.copy()
    points[:, :2] += GEO_OFFSET
    ply = tmp_path / 'geo.ply'
    write_scan(ply, points)  # float64 coordinates: float32 would be 0.5 m apart here
    proc = _corners(ply, tmp_path / 'geo.json')
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads((tmp_path / 'geo.json').read_text())
    corners = np.array(result['corners']) - GEO_OFFSET
    assert len(corners) == 6 and _corner_error(corners, l_room.polygon) < 0.01
    assert result['floor_z'] == pytest.approx(l_room.floor_z, abs=0.01)

    binary = tmp_path / 'geo.bin'  # float32 cannot hold these coordinates to centimetres
    write_scan(binary, points)
    proc = _corners(binary, tmp_path / 'geo_bin.json')
    assert 'Traceback' not in proc.stderr
    assert f'{binary}: warning: float32 coordinates as large as' in proc.stdout + proc.stderr


def _pred(path: Path, center, yaw: float = 0.0) -> Path:
    path.write_text(
        json.dumps({
            'format':
            'synthdet.predictions/1',
            'scan':
            'scan.txt',
            'model':
            'tiny',
            'classes': ['table'],
            'detections': [{
                'class': 'table',
                'score': 0.9,
                'center': center,
                'size': [1.0, 1.0, 1.0],
                'yaw': yaw
            }]
        }))
    return path


def _corners_json(path: Path) -> Path:
    path.write_text(
        json.dumps({
            'format': 'synthdet.corners/1',
            'scan': 'scan.txt',
            'corners': [[0.0, 0.0], [0.0, 4.0], [5.0, 4.0], [5.0, 0.0]],
            'floor_z': 0.0,
            'ceiling_z': 3.0,
            'quality': {
                'wall_points_on_polygon': 1.0
            }
        }))
    return path


def test_placements_that_overflow_in_freecad_units_are_rejected(tmp_path):
    scan = tmp_path / 'scan.txt'
    scan.write_text('0 0 0 1 2 3\n')
    corners = _corners_json(tmp_path / 'room.corners.json')
    for name, center, yaw, where in (('centre', [1e306, 1.0, 0.5], 0.0, 'center[0]'),
                                     ('yaw', [1.0, 1.0, 0.5], 1e308, 'yaw')):
        pred = _pred(tmp_path / f'{name}.pred.json', center, yaw)
        proc = run('-m', 'configurator', 'freecad', '--scan', scan, '--predictions', pred,
                   '--corners', corners, '--out', tmp_path / f'{name}.FCStd')
        assert_clean_error(proc, 2, str(pred), where, "FreeCAD's units")
        assert not (tmp_path / f'{name}.FCStd').exists()


def test_failing_freecad_save_keeps_the_old_document(tmp_path):
    scan = tmp_path / 'scan.txt'
    scan.write_text('0 0 0 1 2 3\n')
    corners = _corners_json(tmp_path / 'room.corners.json')
    first = _pred(tmp_path / 'first.pred.json', [1.0, 1.0, 0.5])
    second = _pred(tmp_path / 'second.pred.json', [3.0, 2.0, 0.5])
    out = tmp_path / 'room.FCStd'
    build_document(scan, first, out, corners)
    old = out.read_bytes()
    # a full disk for FreeCAD: files may not grow beyond 2 KiB, so the save itself fails
    full_disk = tmp_path / 'freecadcmd-on-a-full-disk'
    full_disk.write_text('#!/bin/bash\nulimit -f 2\nexec freecadcmd "$@"\n')
    full_disk.chmod(0o755)
    with pytest.raises(FreecadFailed, match='could not write a complete document'):
        build_document(scan, second, out, corners, freecadcmd=str(full_disk))
    assert out.read_bytes() == old
    build_document(scan, second, out, corners)
    assert out.read_bytes() != old
    assert sorted(p.name for p in tmp_path.iterdir() if 'FCStd' in p.name) == ['room.FCStd']


def test_freecad_timeout_ends_the_whole_process_group(tmp_path):
    pid_file = tmp_path / 'helper.pid'
    fake = tmp_path / 'freecadcmd'
    fake.write_text(f'#!/bin/sh\nsleep 300 &\necho $! > {pid_file}\nexec sleep 300\n')
    fake.chmod(0o755)
    scan = tmp_path / 'scan.txt'
    scan.write_text('0 0 0 1 2 3\n')
    start = time.monotonic()
    proc = run('-m', 'configurator', 'freecad', '--scan', scan, '--predictions',
               _pred(tmp_path / 'p.pred.json', [1.0, 1.0, 0.5]), '--corners',
               _corners_json(tmp_path / 'c.json'), '--out', tmp_path / 'room.FCStd',
               '--freecadcmd', fake, '--timeout', '2')
    assert_clean_error(proc, 1, 'did not finish within 2 s')
    assert time.monotonic() - start < 60
    helper = psutil.Process(int(pid_file.read_text())) if psutil.pid_exists(
        int(pid_file.read_text())) else None
    assert helper is None or not alive([helper]), 'FreeCAD\'s child process survived'


def test_freecad_result_without_warnings_is_a_clear_failure(tmp_path):
    fake = tmp_path / 'freecadcmd'  # a FreeCAD whose macro reports success but no lists
    fake.write_text('#!/bin/sh\necho \'{"format": "synthdet.freecad-result/1", "status": "ok", '
                    '"objects": []}\' > "$SYNTHDET_RESULT"\n')
    fake.chmod(0o755)
    scan = tmp_path / 'scan.txt'
    scan.write_text('0 0 0 1 2 3\n')
    proc = run('-m', 'configurator', 'freecad', '--scan', scan, '--predictions',
               _pred(tmp_path / 'p.pred.json', [1.0, 1.0, 0.5]), '--corners',
               _corners_json(tmp_path / 'c.json'), '--out', tmp_path / 'room.FCStd',
               '--freecadcmd', fake)
    assert_clean_error(proc, 1, 'result has no "warnings" list')


# --------------------------------------------------------------------------------- converter


def test_class_names_come_from_the_whole_name_and_any_suffix_case(tmp_path):
    raw = _area_for_conversion(tmp_path / 'raw', 1, 200)
    ann = raw / S3DIS_DIR / 'Area_1' / 'office_1' / 'Annotations'
    (ann / 'table_1.txt').rename(ann / 'table_1.TXT')
    (ann / 'yumi_1.txt').rename(ann / 'yumi_robot_1.txt')
    with pytest.warns(UnknownClassWarning, match="yumi_robot"):
        summary = convert_s3dis(raw, tmp_path / 'out', workers=1)
    assert summary.instances_per_class['table'] == 1  # .TXT is converted
    assert summary.instances_per_class['yumi'] == 0  # yumi_robot is not a yumi ...
    assert list(summary.unknown_classes) == ['yumi_robot']  # ... but clutter, with a warning
    semantic = np.fromfile(tmp_path / 'out' / 'semantic_mask' / 'Area_1_office_1.bin', np.int64)
    assert SEMANTIC_CLASSES.index('yumi') not in semantic
    assert SEMANTIC_CLASSES.index('table') in semantic


def test_create_data_exit_codes_and_float32_overflow(tmp_path):
    raw = _area_for_conversion(tmp_path / 'raw', 1, 200)
    chair = raw / S3DIS_DIR / 'Area_1' / 'office_1' / 'Annotations' / 'chair_1.txt'
    chair.write_text(chair.read_text() + '1e39 0 0 1 2 3\n')  # finite, but not in float32
    proc = run(*_create_data(raw, tmp_path / 'out'))
    assert_clean_error(proc, 2, str(chair), 'overflows float32')
    proc = run(*_create_data(raw, tmp_path / 'out', '--on-error', 'skip'))
    assert_clean_error(proc, 2, 'no room could be converted')
    not_a_folder = tmp_path / 'file'
    not_a_folder.write_text('')
    proc = run(*_create_data(raw, not_a_folder / 'out'))
    assert_clean_error(proc, 1, str(not_a_folder))


def test_dataset_stats_reads_info_pickles_as_plain_data(tmp_path):
    marker = tmp_path / 'MARKER'
    for name, data in (('empty', b''), ('garbage', b'\x80\x05not a pickle'),
                       ('code', pickle.dumps({'x': OpensMarker(marker)}))):
        folder = tmp_path / name
        folder.mkdir()
        (folder / 's3dis_infos_Area_1.pkl').write_bytes(data)
        proc = run(REPO / 'tools' / 'dataset_stats.py', folder)
        assert_clean_error(proc, 2, str(folder / 's3dis_infos_Area_1.pkl'))
    assert not marker.exists()
