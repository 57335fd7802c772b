"""Every benchmark in ``benchmarks/`` runs at its smallest size from its command line: it exits
0 and ends with its headline line in the documented format with finite figures. A changed
signature that a benchmark uses then fails here, not in the docs. A new
``benchmarks/bench_<name>.py`` needs an entry in ``SMOKE``, keyed by its file name.

The benchmarks run one after the other in this test process, each as ``python
benchmarks/bench_<name>.py ARGS`` runs it (the script's ``__main__`` path, with its arguments
in ``sys.argv``), so that the stack is imported once, not once per benchmark; the tools they
start are forked from one process that imported it (``--fork-tools``,
``benchmarks/tool_runs.py``). One light benchmark also runs as a process of its own."""
from __future__ import annotations

import json
import math
import os
import re
import runpy
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import pytest

from tests.checkpoints import initial_checkpoint

REPO = Path(__file__).resolve().parents[2]
NUMBER = r'(?P<{}>[-+]?\d[\d,]*(?:\.\d+)?)'  # a figure as the benchmarks print it


def figure(name: str) -> str:
    """Regex group ``name`` matching one printed figure (checked to be finite)."""
    return NUMBER.format(name)


class Smoke(NamedTuple):
    """The smallest arguments of a benchmark and the regex of its last line; ``with_model``:
    the arguments end with a checkpoint of the tiny config's model, made for the run."""
    args: list[str]
    headline: str
    with_model: bool = False


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
              figure('infer_2cm') + r' of 2 cm, x' + figure('infer_1cm') + ' of 1 cm'),
    'bench_corners.py':
        Smoke(['--rooms', '1', '--points', '5000', '--timing-rooms', '0', '--generate',
               '0'],
              r'corners, generator rooms: .+; all rooms \(mean error, right count, right '
              r'order\): traced ' + figure('traced') + r' cm \(worst [\d.]+\) / \d+% / '
              r'\d+%; paper .+; convex hull ' + figure('hull') + ' cm .+'),
    # an untrained model: only its surest boxes, so that the FreeCAD document stays small
    'bench_hall.py':
        Smoke(['--points', '30000', '--hall-size', '8', '7', '--rooms', '1',
               '--room-points', '10000', '--score-thr', '0.9', '--fork-tools', '--config',
               'configs/tr3d/tiny.py', '--checkpoint'],
              r'hall ' + figure('points') + r'M points -> FCStd: ' + figure('seconds') +
              r' s, peak ' + figure('peak') + r' GB; windowed recall ' + figure('hall') +
              ' vs room recall ' + figure('rooms'),
              with_model=True),
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
               '--workers', '1', '--sample-points', '100', '--fork-tools'],
              r'2 processes x 1 thread vs 1 process x 2 threads: x' + figure('ratio') +
              r' faster per iteration of 4 rooms \(' + figure('two') + ' s vs ' +
              figure('one') + r' s\)'),
    'bench_train_recipe.py':
        Smoke(['--rooms-per-area', '1', '--points', '5000', '--iters', '1', '--warmup', '0',
               '--profile-iters', '1', '--workers', '1', '--fork-tools'],
              r'make exp2-cpu training: previous ' + figure('previous') + r' min, today ' +
              figure('today') + r' min: x' + figure('ratio') + ' faster'),
    'bench_scan_io.py':
        Smoke(['--points', '20000', '--room-points', '5000', '--chunk', '5000'],
              r'scan_io \d+M-point LAZ: streamed load_scan peak ' + figure('streamed') +
              r' GB in \d+ s vs read-all ' + figure('whole') + r' GB in \d+ s: ' +
              figure('ratio') + 'x less memory'),
    'bench_real_scans.py':
        Smoke(['--generate', '1', '--fork-tools', '--config', 'configs/tr3d/tiny.py',
               '--checkpoint'],
              r'real scans: recall ' + figure('recall') + r' at IoU 0\.25, ' +
              figure('fp') + r' false positives per room, ' + figure('phantoms') +
              r' phantom yumi/3d printer \(' + figure('rooms') + r' rooms\)',
              with_model=True),
    'bench_freecad.py':
        Smoke(['--sizes', '12', '24'],
              r'freecad documents: ' + figure('count') + r' detections ' + figure('seconds') +
              r' s \(build ' + figure('build') + r' s, save ' + figure('save') + r' s\), ' +
              figure('each') + r' ms each; per-detection time at \S+ / at \S+: ' +
              figure('ratio') + r'x \(build ' + figure('build_ratio') + r'x, save ' +
              figure('save_ratio') + r'x; CPU time ' + figure('cpu_ratio') + r'x\)'),
    # its whole run at a tiny scale, headline included, is
    # tests/test_benchmarks/test_bench_domain_shift.py's
    'bench_domain_shift.py': 'tests/test_benchmarks/test_bench_domain_shift.py',
    # its whole run at a tiny scale, headline included, is
    # tests/test_benchmarks/test_bench_teach.py's
    'bench_teach.py': 'tests/test_benchmarks/test_bench_teach.py',
    # its whole run at a tiny scale, summary lines included, is
    # tests/test_benchmarks/test_bench_protocols.py's
    'bench_protocols.py': 'tests/test_benchmarks/test_bench_protocols.py',
}


def test_every_benchmark_has_a_smoke_run():
    found = {p.name for p in (REPO / 'benchmarks').glob('bench_*.py')}
    assert sorted(found - set(SMOKE)) == [], 'benchmarks without an entry in SMOKE'
    assert sorted(set(SMOKE) - found) == [], 'SMOKE entries without a benchmark'
    for name, smoke in SMOKE.items():
        if isinstance(smoke, str):  # run by another test file, which must name it
            assert name in (REPO / smoke).read_text(), name


def run_script(script: Path, args: list[str], capfd) -> tuple[int, str, str]:
    """``python SCRIPT ARGS`` in this process (its ``__main__`` path, from the repository root):
    its exit code and the text it wrote to standard output and standard error."""
    capfd.readouterr()
    argv, cwd = sys.argv, os.getcwd()
    sys.argv = [str(script), *args]
    os.chdir(REPO)
    try:
        runpy.run_path(str(script), run_name='__main__')
        code = 0
    except SystemExit as stop:  # as the interpreter maps it to an exit code
        if stop.code is None or isinstance(stop.code, int):
            code = stop.code or 0
        else:
            print(stop.code, file=sys.stderr)
            code = 1
    finally:
        sys.argv = argv
        os.chdir(cwd)
    out, err = capfd.readouterr()
    return code, out, err


@pytest.fixture(scope='module')
def checkpoint(tmp_path_factory) -> Path:
    """The tiny config's checkpoint, made once for the benchmarks that load a model."""
    return initial_checkpoint(REPO / 'configs/tr3d/tiny.py',
                              tmp_path_factory.mktemp('model') / 'initialised.pth')


def check_headline(name: str, code: int, out: str, err: str) -> None:
    """Exit 0 and the last line in the documented format, its figures finite."""
    assert code == 0, out[-2000:] + err[-4000:]
    lines = [line for line in out.splitlines() if line.strip()]
    assert lines, err[-2000:]
    headline = re.fullmatch(SMOKE[name].headline, lines[-1].strip())
    assert headline, f'last line not in the documented format: {lines[-1]!r}'
    for key, value in headline.groupdict().items():
        assert math.isfinite(float(value.replace(',', ''))), f'{key} = {value}'


@pytest.mark.parametrize('name', [name for name, run in SMOKE.items() if isinstance(run, Smoke)])
def test_benchmark_smoke_run(name, request, capfd, monkeypatch):
    smoke = SMOKE[name]
    args = [*smoke.args, str(request.getfixturevalue('checkpoint'))] if smoke.with_model \
        else smoke.args
    monkeypatch.setenv('OMP_NUM_THREADS', '1')
    check_headline(name, *run_script(REPO / 'benchmarks' / name, args, capfd))


@pytest.mark.parametrize('name', sorted(SMOKE))
def test_every_benchmark_answers_help_from_its_command_line(name, capfd):
    code, out, err = run_script(REPO / 'benchmarks' / name, ['--help'], capfd)
    assert code == 0 and out.startswith('usage: '), out[-2000:] + err[-2000:]


def test_a_light_benchmark_runs_as_its_own_process():
    """The command line as a user types it (the interpreter's own start-up and ``sys.path``)."""
    name = 'bench_writer.py'
    done = subprocess.run([sys.executable, f'benchmarks/{name}', *SMOKE[name].args],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=300)
    check_headline(name, done.returncode, done.stdout, done.stderr)


# a record's finish time as the benchmark runner writes it
FINISHED = time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime(86400 * 20_000))


def test_the_page_names_command_machine_and_date_and_no_path_of_the_machine(tmp_path):
    from tools import collect_benchmarks
    output_dir = tmp_path / 'kept'
    output_dir.mkdir()
    record = {
        'name': 'scanner', 'command': '.venv/bin/python benchmarks/bench_scanner.py',
        'returncode': 0, 'seconds': 1.0, 'load_before': [0.1, 0.2, 0.3],
        'load_after': [0.4, 0.5, 0.6], 'finished': FINISHED,
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
            f'Some CPU, 2 cores, Python 3.11.7, {FINISHED}, commit abc1234' in page)
    row = next(line for line in page.splitlines() if line.startswith('| `scanner`'))
    assert 'Some CPU, 2 cores' in row and FINISHED in row
