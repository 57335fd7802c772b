"""Run the benchmarks, keep their outputs in docs/benchmarks/ and write docs/benchmarks.md
from them (``make bench``).

    python tools/collect_benchmarks.py [--only scanner convert ...] [--render-only]
        [--out docs/benchmarks.md] [--output-dir docs/benchmarks]

Every ``benchmarks/bench_<name>.py`` runs in turn, as its own process, with the arguments of
``ARGUMENTS`` (the documented, paper-scale settings; a benchmark not listed runs without
arguments). The benchmarks of ``OPT_IN`` run only when ``--only`` names them (``domain_shift``:
hours of training; ``real_scans``, ``teach`` need a checkpoint and labelled scans, so are run
directly with them); their kept outputs are still shown. Each one prints a side-by-side comparison
measured in that one run and ends with a summary line. Its full output (without progress-bar lines)
is kept in ``docs/benchmarks/<name>.txt`` and its record (exact command, exit code, wall time, the
machine's load average before and after, the finishing time, the machine kind: CPU model, cores,
Python, and the commit) in ``docs/benchmarks/<name>.json``. Absolute paths of the machine are
scrubbed from what is kept (:func:`scrub`): the checkout becomes relative, an installed package
``site-packages/...``, a temporary folder ``$TMPDIR/...``.
``docs/benchmarks.md`` is then written from all kept outputs: a table of the last lines and
the end of every output (:func:`shown_output`). With ``--only``, the other benchmarks keep their earlier outputs;
``--render-only`` runs nothing and rewrites the page from the kept outputs.
The machine may be shared: ratios measured within one run are more robust to load than
absolute times, and the load is printed with every output.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from synthdet.cli import OneLineParser
from synthdet.outputs import write_text

REPO_ROOT = Path(__file__).resolve().parents[1]
# Arguments per benchmark: the settings their docs report (paper scale where there is one).
ARGUMENTS = {
    'scanner': [],
    'writer': [],
    'generate': ['--rooms-per-area', '50', '--points', '1000000', '--workers', '2'],
    'convert':
    ['--rooms', '20', '--points-per-object', '18000', '--workers', '2', '--repeats', '2'],
    'model': ['--points', '100000', '--iters', '3', '--threads', '1'],
    'corners': [],
    'hall': ['--checkpoint', 'work_dirs/demo/train/epoch_5.pth'],  # the model of `make demo`
    'sensors': ['--rooms', '2', '--repeats', '2'],
    'structure_thinning': ['--rooms', '4'],
    'dist_train': ['--rooms-per-area', '4', '--iters', '16', '--warmup', '4'],
    'train_recipe': ['--rooms-per-area', '4', '--iters', '16', '--warmup', '4'],
    'freecad': ['--sizes', '500', '1000', '2000', '4000', '10000'],
    'domain_shift': [],  # its defaults are the documented scale (about 1.5 h on 2 cores)
}
# Run only when named, e.g. `make bench BENCH_ARGS="--only domain_shift"` (docs/results.md).
OPT_IN = {'domain_shift', 'real_scans', 'teach'}
WHAT = {
    'scanner':
    'ray casting: batched Embree scanner vs per-ray bpy `BVHTree`, `Object` and '
    '`scene` `ray_cast` loops on the same rays; the default sensor models\' 1M-point scans '
    '(glass passes, noise) with Embree vs the `BVHTree` loop as ray engine, where the time goes '
    'and the bare Embree cast of the same rays; 1 thread each',
    'writer':
    'S3DIS text formatting: vectorised writer vs per-line Python and `np.savetxt`',
    'generate':
    'generation wall time, 3 areas x 50 rooms x 1M points, 2 workers, vs the 10 min goal',
    'convert':
    'conversion: synthdet convert_s3dis vs mmdet3d collect + S3DISData, equal '
    'parallelism',
    'model':
    'TR3D train step, inference and peak memory, 1 cm vs 2 cm voxels vs 2 cm with a 16 cm level',
    'corners':
    'room corners: traced outline vs the paper\'s method and a convex hull (error, '
    'count, order, time)',
    'hall': '30M-point generated hall as LAZ -> FCStd (time, memory); windowed vs room recall',
    'sensors': 'generation time of the same 1M-point rooms per sensor model (paper aimed and '
    'uniform, TLS, tablet)',
    'structure_thinning':
    'points and 2 cm voxels on objects among 40,000 sampled per room and sensor: `PointSample` '
    'alone vs `ThinRoomStructure` first vs `VoxelGridSample` before both',
    'dist_train':
    'exp2_cpu training speed: 2 processes x 1 thread (`tools/dist_train.sh`, gloo) vs 1 '
    'process x 2 threads, batch of 4 rooms',
    'train_recipe':
    'exp2_cpu training: where an iteration\'s time goes (loader steps, voxelisation, backbone, '
    'neck, head, backward, optimiser) and the whole `make exp2-cpu` training: TR3D\'s full '
    'neck, structure found anew every epoch and a validation per epoch vs `exp2_cpu.py`',
    'freecad':
    'FreeCAD document of 500 to 10,000 synthetic detections (one parametric part each): build '
    'and save time per detection, wall and CPU seconds of the FreeCAD process',
    'domain_shift':
    'TR3D at CPU scale trained on the paper profile vs the mixed default, tested on held-out '
    'generator profiles (about 1.5 h; only with `--only domain_shift`)',
}
# Each benchmark's goal, shown next to its result.
GOALS = {
    'scanner': '>= 10x the fastest bpy loop in rays/s, 1 thread each',
    'generate': '<= 600 s for 150 rooms',
    'convert': '>= 3x at equal parallelism',
    'train_recipe': '>= 2x the previous recipe, <= 60 min on 2 idle cores',
    'corners': 'traced <= 3 cm, >= 95% right count, <= 1 s per 1M points',
    'hall': 'windowed recall >= 0.95 x room recall, peak < 8 GB',
    'sensors': 'a 1M-point room in seconds with every model',
    'freecad': '10,000 detections in under a minute, time per detection flat (no quadratic step)',
    'domain_shift': 'mixed model: drop <= 0.05 mAP@0.25 on every held-out profile',
}
# How to read an output, shown under its command; repeated runs and what earlier code gave are
# in docs/history.md, the page's dates and commits come from the kept records.
NOTES = {
    'scanner': [
        '',
        'The scans\' ratio stays below the bare casting ratio: the work besides casting (ray '
        'generation, noise, the laser scanner\'s spacing filter, labelling) costs both ray '
        'engines the same time; the `scan/bare` column shows how far each Embree scan is from '
        'its bare cast, and the table of where the time goes shows what keeps the laser scanner '
        'furthest from the goal: its spacing filter. Repeated runs and earlier versions: '
        '[history.md](history.md).'
    ],
    'convert': [
        '',
        'The `sys s` column is the system time of each run. The VM hands free 2 MiB blocks back '
        'to its host (free page reporting), and memory taken from them costs a host fault per '
        '4 KiB page when first touched; the converter therefore reuses its room arrays in 4 KiB '
        'pages and writes 64 KiB per call, which keeps its system time small and its run-to-run '
        'spread narrow. Repeated runs and earlier versions: [history.md](history.md).'
    ],
    'domain_shift': [
        '',
        '`make bench` runs it only when named (`--only domain_shift`, about 1.5 h of training): '
        'the output is that of the run on the date shown. Its rooms came from the laser '
        'scanner without its one-return-per-centimetre export ([history.md](history.md)); a new '
        'run measures the generator as it is.'
    ],
}
OUTPUT_DIR = REPO_ROOT / 'docs' / 'benchmarks'
# The page shows the end of each output (its comparison and summary line); the kept text file
# holds all of it.
SHOWN_LINES = 40
# A Python warning as printed to stderr (`file:line: XWarning: message`), followed by the
# indented source line it points at.
PYTHON_WARNING = re.compile(r'^\S+:\d+: \w*Warning\b')


def discover() -> list[str]:
    """Benchmark names (``bench_<name>.py``), the known ones first in ``ARGUMENTS`` order."""
    found = {p.stem[len('bench_'):] for p in (REPO_ROOT / 'benchmarks').glob('bench_*.py')}
    return [n for n in ARGUMENTS if n in found] + sorted(found - set(ARGUMENTS))


def command_of(name: str) -> list[str]:
    return [f'benchmarks/bench_{name}.py', *ARGUMENTS.get(name, [])]


def scrub(text: str) -> str:
    """``text`` without the absolute paths of this machine: the checkout's own paths relative to
    it, installed packages from ``site-packages/``, temporary folders as ``$TMPDIR/``, any other
    absolute folder as ``.../`` before the file's name."""
    text = text.replace(f'{REPO_ROOT}/', '').replace(str(REPO_ROOT), '.')
    text = re.sub(r'(?<![\w.~$])(?:/[\w.+-]+)+/site-packages/', 'site-packages/', text)
    for temporary in sorted({tempfile.gettempdir(), '/tmp'}, key=len, reverse=True):
        text = re.sub(rf'(?<![\w.~$]){re.escape(temporary)}/', '$TMPDIR/', text)
    # the random name of a folder made by tempfile.mkdtemp() tells nothing
    text = re.sub(r'\$TMPDIR/tmp\w{8}/', '$TMPDIR/<random>/', text)
    return ABSOLUTE_FOLDER.sub('.../', text)


# an absolute folder path (a "/" not after a word character, then folder names, each with "/")
ABSOLUTE_FOLDER = re.compile(r'(?<![\w.~$/])/(?:[\w.+-]+/)+')


def git_commit() -> str:
    """The checkout's commit (short hash), or ``unknown``."""
    done = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'],
                          cwd=REPO_ROOT,
                          capture_output=True,
                          text=True)
    return done.stdout.strip() if done.returncode == 0 else 'unknown'


def run_benchmark(name: str, output_dir: Path) -> dict:
    """Run one benchmark, echo its output live, keep it in ``<output_dir>/<name>.txt`` and its
    record (command, exit code, wall seconds, load averages, last line) in ``<name>.json``."""
    command = [sys.executable, *command_of(name)]
    load_before = os.getloadavg()
    start = time.monotonic()
    output = []
    with subprocess.Popen(
            command,
            cwd=REPO_ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
            env=dict(os.environ, PYTHONUNBUFFERED='1')) as process:
        for line in process.stdout:
            output.append(line)
            sys.stdout.write(line)
    record = {
        'name': name,
        'command': '.venv/bin/python ' + ' '.join(command_of(name)),
        'returncode': process.returncode,
        'seconds': round(time.monotonic() - start, 1),
        'load_before': [round(x, 2) for x in load_before],
        'load_after': [round(x, 2) for x in os.getloadavg()],
        'finished': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC'),
        'machine': machine(),
        'commit': git_commit(),
    }
    text = scrub(''.join(output).replace('\r', '\n'))
    lines = [line.rstrip() for line in text.splitlines() if line.strip() and '%|' not in line]
    record['last_line'] = lines[-1].strip() if lines else ''
    write_text(output_dir / f'{name}.txt', '\n'.join(lines) + '\n')
    write_text(output_dir / f'{name}.json', json.dumps(record, indent=1) + '\n')
    return record


def kept_output(name: str, output_dir: Path) -> dict | None:
    """The record and output of an earlier run kept in ``output_dir``, if any."""
    record_path = output_dir / f'{name}.json'
    if not record_path.is_file():
        return None
    record = json.loads(record_path.read_text())
    record['output'] = scrub((output_dir / f'{name}.txt').read_text()).splitlines()
    return record


def machine() -> str:
    """CPU model, core count and Python version of this machine."""
    model = platform.processor() or 'unknown CPU'
    cpuinfo = Path('/proc/cpuinfo')
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith('model name'):
                model = line.split(':', 1)[1].strip()
                break
    return f'{model}, {os.cpu_count()} cores, Python {platform.python_version()}'


def shown_output(lines: list[str]) -> list[str]:
    """The lines of an output that the page shows: without Python's warnings (and the source
    line printed under each), at most the last ``SHOWN_LINES``."""
    shown, after_warning = [], False
    for line in lines:
        if after_warning and line.startswith(' '):
            after_warning = False
            continue
        after_warning = bool(PYTHON_WARNING.match(line))
        if not after_warning:
            shown.append(line)
    return shown[-SHOWN_LINES:]


def render(records: list[dict], not_run: list[str], output_dir: Path) -> str:
    """docs/benchmarks.md from the kept benchmark records (and the benchmarks without one)."""
    docs = REPO_ROOT / 'docs'
    # links relative to this page; in the text, the folder as seen from the repository root
    where = scrub(str(output_dir.relative_to(docs) if output_dir.is_relative_to(docs) else
                      output_dir))
    shown = scrub(str(output_dir))
    loads = [x for r in records for x in (r['load_before'][0], r['load_after'][0])]
    load = f'{min(loads)}-{max(loads)}' if loads else 'not measured'
    lines = [
        '# Benchmarks',
        '',
        'Written by `make bench` (`tools/collect_benchmarks.py`), which runs every '
        '`benchmarks/bench_*.py` one after the other (' +
        ', '.join(f'`{name}`' for name in sorted(OPT_IN)) + ' only when named with `--only`: '
        'hours of training, or a trained checkpoint and your labelled scans), keeps each full '
        f'output in `{shown}/<name>.txt` (progress bars left out, the machine\'s absolute paths '
        'scrubbed) '
        'and writes this page from them; `make bench BENCH_ARGS="--only scanner convert"` runs '
        'some again and keeps the others\' outputs. Every benchmark measures all sides of its '
        'comparison in the same run, on the same input, with the same warm-up, repeats and '
        'thread or process counts. Each figure comes with the command that printed it, the '
        'machine kind it ran on (CPU model, cores, Python), its date and the commit it ran at '
        '(where recorded). Load average = 1/5/15-minute load before and after the run; the '
        'project machine is shared with other jobs, so absolute times vary with it more than '
        f'the ratios do. The 1-minute load around these runs: {load} (on 2 cores, above 2 '
        'means jobs were waiting for a core). `tests/test_benchmarks/test_benchmarks.py` runs '
        'every benchmark at its smallest size in `make test`.',
        '',
        '| benchmark | what | result (last line) | goal | wall s | load before | load after | '
        'machine | finished |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for r in records:
        result = r['last_line'] if r['returncode'] == 0 else f'FAILED (exit {r["returncode"]})'
        lines.append(f'| `{r["name"]}` | {WHAT.get(r["name"], "")} | {scrub(result)} | '
                     f'{GOALS.get(r["name"], "")} | {r["seconds"]} | '
                     f'{" / ".join(map(str, r["load_before"]))} | '
                     f'{" / ".join(map(str, r["load_after"]))} | '
                     f'{r.get("machine", "not recorded")} | {r["finished"]} |')
    for name in not_run:
        lines.append(f'| `{name}` | {WHAT.get(name, "")} | not run yet | '
                     f'{GOALS.get(name, "")} | | | | | |')
    lines += ['', '## Outputs', '']
    for r in records:
        commit = f', commit {r["commit"]}' if r.get('commit') else ''
        shown = shown_output(r['output'])
        cut = ([] if len(shown) == len(r['output']) else
               ['', f'The last {len(shown)} lines of the output, without Python\'s warnings.'])
        lines += [
            f'### {r["name"]}', '', f'`{r["command"]}` ([{where}/{r["name"]}.txt]'
            f'({where}/{r["name"]}.txt)); {r.get("machine", "machine not recorded")}, '
            f'{r["finished"]}{commit}', *NOTES.get(r['name'], []), *cut, '', '```', *shown,
            '```', ''
        ]
    return '\n'.join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.split('\n')[0])
    parser.add_argument(
        '--only', nargs='+', metavar='NAME', help='run only these benchmarks (bench_<NAME>.py)')
    parser.add_argument('--out', type=Path, default=REPO_ROOT / 'docs/benchmarks.md')
    parser.add_argument(
        '--render-only',
        action='store_true',
        help='run nothing: rewrite the page from the kept outputs')
    parser.add_argument(
        '--output-dir',
        type=Path,
        default=OUTPUT_DIR,
        help='where each benchmark\'s output and record are kept')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    names = discover()
    unknown = sorted(set(args.only or []) - set(names))
    if unknown:
        print(
            f'collect_benchmarks: no benchmarks/bench_{unknown[0]}.py (have: '
            f'{", ".join(names)})',
            file=sys.stderr)
        return 2
    for name in names:
        if args.render_only or (args.only and name not in args.only) or (not args.only
                                                                         and name in OPT_IN):
            continue
        print(f'[bench] {name}: {" ".join(command_of(name))}', flush=True)
        record = run_benchmark(name, args.output_dir)
        print(f'[bench] {name}: {record["seconds"]} s, exit {record["returncode"]}', flush=True)
    kept = {name: kept_output(name, args.output_dir) for name in names}
    for name, record in kept.items():  # outputs kept before scrubbing existed: scrubbed now
        if record is not None:
            write_text(args.output_dir / f'{name}.txt', '\n'.join(record['output']) + '\n')
    records = [record for record in kept.values() if record is not None]
    write_text(
        args.out,
        render(records, [name for name, record in kept.items() if record is None],
               args.output_dir.resolve()))
    print(f'[bench] wrote {args.out}')
    return 0 if all(r['returncode'] == 0 for r in records) else 1


if __name__ == '__main__':
    sys.exit(main())
