"""Every benchmark in ``benchmarks/`` runs at its smallest size, as its own process with the
project's interpreter: it exits 0 and ends with its headline line in the documented format
with finite figures. A changed signature that a benchmark uses then fails here, not in the
docs. A new ``benchmarks/bench_<name>.py`` needs an entry in ``SMOKE``, keyed by its file name."""
from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import pytest

REPO = Path(__file__).resolve().parents[1]
NUMBER = r'(?P<{}>[-+]?\d[\d,]*(?:\.\d+)?)'  # a figure as the benchmarks print it


def figure(name: str) -> str:
    """Regex group ``name`` matching one printed figure (checked to be finite)."""
    return NUMBER.format(name)


class Smoke(NamedTuple):
    """The smallest arguments of a benchmark and the regex of its last line; ``with_model``:
    the arguments end with a checkpoint of the tiny config's model, made for the run; ``slow``:
    over 30 s even at this size (processes that load the detector or train it)."""
    args: list[str]
    headline: str
    with_model: bool = False
    slow: bool = False


SMOKE: dict[str, Smoke | str] = {
    'bench_scanner.py':
        Smoke(['--rays', '2000', '--slow-rays', '100', '--scan-points', '2000',
               '--repeats', '1', '--batch-rays', '4096'],
              r'scanner vs fastest bpy loop \(bpy \S+ loop\), 1 thread each, median of 1: '
              r'default sensor scans with glass ' + figure('scan') + r'x rays/s \(paper '
              r'[\d.]+x(?:, \w+ [\d.]+x)*\); bare ray casting ' +
              figure('bare') + r'x; our scan / bare Embree cast ' + figure('bound') + 'x'),
    'bench_writer.py':
        Smoke(['--points', '2000', '--repeats', '1'],
              r'text writer speedup vs the fastest alternative \(.+\), best of 1: ' +
              figure('ratio') + 'x'),
    'bench_generate.py':
        Smoke(['--rooms-per-area', '1', '--points', '5000', '--workers', '1'],
              r'3x50 rooms x 5,000 points, 1 workers: ' + figure('seconds') +
              r' s \(.+\) = ' + figure('ratio') + 'x of the 10-minute goal'),
    'bench_convert.py':
        Smoke(['--rooms', '2', '--points-per-object', '1000', '--workers', '2',
               '--repeats', '1'],
              r'convert speedup vs mmdet3d at equal parallelism: ' + figure('one') +
              r'x \(1 process each\), ' + figure('two') + r'x \(2 each\); synthdet 2 '
              r'workers vs mmdet3d as shipped: ' + figure('shipped') + r'x; CPU-time '
              r'ratio \(1 process each\): ' + figure('cpu') + 'x'),
    'bench_model.py':
        Smoke(['--points', '500', '--iters', '1', '--threads', '1', '--in-process'],
              r'2 cm \+ fine level \(CPU seconds\): train x' + figure('train_2cm') +
              r' of 2 cm, x' + figure('train_1cm') + r' of 1 cm; inference x' +
              figure('infer_2cm') + r' of 2 cm, x' + figure('infer_1cm') + ' of 1 cm',
              slow=True),
    'bench_corners.py':
        Smoke(['--rooms', '1', '--points', '5000', '--timing-rooms', '0', '--generate',
               '0'],
              r'corners, generator rooms: .+; all rooms \(mean error, right count, right '
              r'order\): traced ' + figure('traced') + r' cm \(worst [\d.]+\) / \d+% / '
              r'\d+%; paper .+; convex hull ' + figure('hull') + ' cm .+'),
    # an untrained model: only its surest boxes, so that the FreeCAD document stays small
    'bench_hall.py':
        Smoke(['--points', '30000', '--hall-size', '8', '7', '--rooms', '1',
               '--room-points', '10000', '--score-thr', '0.9', '--config',
               'configs/tr3d/tiny.py', '--checkpoint'],
              r'hall ' + figure('points') + r'M points -> FCStd: ' + figure('seconds') +
              r' s, peak ' + figure('peak') + r' GB; windowed recall ' + figure('hall') +
              ' vs room recall ' + figure('rooms'),
              with_model=True,
              slow=True),
    'bench_sensors.py':
        Smoke(['--rooms', '1', '--points', '5000', '--repeats', '1'],
              r'sensors: slowest \S+ ' + figure('seconds') + r' s per 1M-point room \(' +
              figure('ratio') + r'x the aimed paper sensor\)'),
    'bench_structure_thinning.py':
        Smoke(['--rooms', '1', '--points', '20000', '--sample', '2000'],
              r'voxel grid first: 10th-percentile voxels per object paper ' +
              figure('paper') + 'x, tls ' + figure('tls') + 'x, tablet ' +
              figure('tablet') + 'x'),
    'bench_dist_train.py':
        Smoke(['--rooms-per-area', '1', '--points', '5000', '--iters', '1', '--warmup', '0',
               '--workers', '1', '--sample-points', '100'],
              r'2 processes x 1 thread vs 1 process x 2 threads: x' + figure('ratio') +
              r' faster per iteration of 4 rooms \(' + figure('two') + ' s vs ' +
              figure('one') + r' s\)',
              slow=True),
    'bench_scan_io.py':
        Smoke(['--points', '20000', '--room-points', '5000', '--chunk', '5000'],
              r'scan_io \d+M-point LAZ: streamed load_scan peak ' + figure('streamed') +
              r' GB in \d+ s vs read-all ' + figure('whole') + r' GB in \d+ s: ' +
              figure('ratio') + 'x less memory'),
    'bench_real_scans.py':
        Smoke(['--generate', '1', '--config', 'configs/tr3d/tiny.py', '--checkpoint'],
              r'real scans: recall ' + figure('recall') + r' at IoU 0\.25, ' +
              figure('fp') + r' false positives per room, ' + figure('phantoms') +
              r' phantom yumi/3d printer \(' + figure('rooms') + r' rooms\)',
              with_model=True,
              slow=True),
    'bench_freecad.py':
        Smoke(['--sizes', '12', '24'],
              r'freecad documents: ' + figure('count') + r' detections ' + figure('seconds') +
              r' s \(build ' + figure('build') + r' s, save ' + figure('save') + r' s\), ' +
              figure('each') + r' ms each; per-detection time at \S+ / at \S+: ' +
              figure('ratio') + r'x \(build ' + figure('build_ratio') + r'x, save ' +
              figure('save_ratio') + r'x; CPU time ' + figure('cpu_ratio') + r'x\)'),
    # its whole run at a tiny scale, headline included, is tests/test_bench_domain_shift.py's
    'bench_domain_shift.py': 'tests/test_bench_domain_shift.py',
    # its whole run at a tiny scale, headline included, is tests/test_bench_teach.py's
    'bench_teach.py': 'tests/test_bench_teach.py',
}


def test_every_benchmark_has_a_smoke_run():
    found = {p.name for p in (REPO / 'benchmarks').glob('bench_*.py')}
    assert sorted(found - set(SMOKE)) == [], 'benchmarks without an entry in SMOKE'
    assert sorted(set(SMOKE) - found) == [], 'SMOKE entries without a benchmark'
    for name, smoke in SMOKE.items():
        if isinstance(smoke, str):  # run by another test file, which must name it
            assert name in (REPO / smoke).read_text(), name


def tiny_checkpoint(folder: Path) -> Path:
    """A checkpoint of ``configs/tr3d/tiny.py``'s model with its initial weights (seeded)."""
    import torch
    from mmdet3d.apis import init_model
    from mmengine.config import Config
    torch.manual_seed(0)
    config = Config.fromfile(str(REPO / 'configs/tr3d/tiny.py'))
    model = init_model(config, None, device='cpu')
    path = folder / 'initialised.pth'
    classes = list(config.test_dataloader.dataset.metainfo['classes'])
    torch.save({'state_dict': model.state_dict(), 'meta': {'dataset_meta': {'classes': classes}}},
               path)
    return path


def smoke_run(name: str, checkpoint: Future | None) -> subprocess.CompletedProcess:
    """Run one benchmark at its smallest size as its own process with one OpenMP thread."""
    smoke = SMOKE[name]
    args = [*smoke.args, str(checkpoint.result())] if smoke.with_model else smoke.args
    return subprocess.run([sys.executable, f'benchmarks/{name}', *args],
                          cwd=REPO,
                          env=dict(os.environ, OMP_NUM_THREADS='1'),
                          capture_output=True,
                          text=True,
                          timeout=600)


@pytest.fixture(scope='module')
def smoke_runs(request, tmp_path_factory) -> Iterator[dict[str, Future]]:
    """The smoke runs of the selected tests, started at once, two at a time (the benchmarks run
    one thread each; a 2-core machine then does the set in about half the wall time), slowest
    first, those that need the tiny checkpoint last: it is made in this process meanwhile."""
    selected = [
        item.callspec.params['name'] for item in request.session.items
        if item.originalname == 'test_benchmark_smoke_run'
    ]
    names = sorted(selected, key=lambda name: (not SMOKE[name].slow, SMOKE[name].with_model))
    with ThreadPoolExecutor(max_workers=1) as maker, ThreadPoolExecutor(max_workers=2) as runs:
        checkpoint = None
        if any(SMOKE[name].with_model for name in names):
            checkpoint = maker.submit(tiny_checkpoint, tmp_path_factory.mktemp('model'))
        try:
            yield {name: runs.submit(smoke_run, name, checkpoint) for name in names}
        finally:  # a failed test leaves the runs not started yet
            runs.shutdown(cancel_futures=True)


@pytest.mark.parametrize('name', [
    pytest.param(name, marks=[pytest.mark.slow] if smoke.slow else [])
    for name, smoke in SMOKE.items() if isinstance(smoke, Smoke)
])
def test_benchmark_smoke_run(name, smoke_runs):
    done = smoke_runs[name].result()
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    assert lines, done.stderr[-2000:]
    headline = re.fullmatch(SMOKE[name].headline, lines[-1].strip())
    assert headline, f'last line not in the documented format: {lines[-1]!r}'
    for key, value in headline.groupdict().items():
        assert math.isfinite(float(value.replace(',', ''))), f'{key} = {value}'


def test_the_page_names_command_machine_and_date_and_no_path_of_the_machine(tmp_path):
    from tools import collect_benchmarks
    output_dir = tmp_path / 'kept'
    output_dir.mkdir()
    record = {
        'name': 'scanner', 'command': '.venv/bin/python benchmarks/bench_scanner.py',
        'returncode': 0, 'seconds': 1.0, 'load_before': [0.1, 0.2, 0.3],
        'load_after': [0.4, 0.5, 0.6], 'finished': '2026-12-06 07:00 UTC',
        'machine': 'Some CPU, 2 cores, Python 3.11.7', 'commit': 'abc1234',
        'last_line': 'scanner vs fastest bpy loop: 12.0x'
    }
    (output_dir / 'scanner.json').write_text(json.dumps(record))
    (output_dir / 'scanner.txt').write_text(
        f'{REPO}/.venv/lib/python3.11/site-packages/x/__init__.py:1: UserWarning\n'
        '/elsewhere/venv/lib/python3.11/site-packages/y.py:2: warning\n'
        f'{tempfile.gettempdir()}/synthdet-bench-x/room.laz: 10 points\n'
        f'read {REPO}/work_dirs/a.pth and /data/scans/hall.e57 at 1/5/15-minute load, 9 rays/s\n'
        'scanner vs fastest bpy loop: 12.0x\n')
    page = collect_benchmarks.render([collect_benchmarks.kept_output('scanner', output_dir)], [],
                                     output_dir)
    assert str(REPO) not in page and tempfile.gettempdir() + '/' not in page
    assert re.findall(r'(?<![\w.~$/])/(?:[\w.+-]+/)+', page) == []
    assert 'read work_dirs/a.pth and .../hall.e57 at 1/5/15-minute load, 9 rays/s' in page
    assert '$TMPDIR/synthdet-bench-x/room.laz' in page
    assert ('`.venv/bin/python benchmarks/bench_scanner.py` ([' in page and
            'Some CPU, 2 cores, Python 3.11.7, 2026-12-06 07:00 UTC, commit abc1234' in page)
    row = next(line for line in page.splitlines() if line.startswith('| `scanner`'))
    assert 'Some CPU, 2 cores' in row and '2026-12-06 07:00 UTC' in row
