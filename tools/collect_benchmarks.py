"""Run the benchmarks and collect their last lines into docs/benchmarks.md (``make bench``).

    python tools/collect_benchmarks.py [--only scanner convert ...] [--out docs/benchmarks.md]
        [--log-dir work_dirs/bench]

Every ``benchmarks/bench_<name>.py`` runs in turn, as its own process, with the arguments of
``ARGUMENTS`` (the documented, paper-scale settings; a benchmark not listed runs without
arguments). Each one prints a side-by-side comparison measured in that one run and ends with a
ratio line. The report lists, per benchmark, the exact command, the last line, the wall time
and the machine's load average before and after (the machine may be shared: ratios measured
within one run are more robust to load than absolute times), followed by the tail of every
output. Full outputs stay in ``--log-dir``. With ``--only``, the other benchmarks' rows are
taken from their logs of an earlier run, if any.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
# Arguments per benchmark: the settings their docs report (paper scale where there is one).
ARGUMENTS = {
    'scanner': [],
    'writer': [],
    'generate': ['--rooms-per-area', '50', '--points', '1000000', '--workers', '2'],
    'convert': ['--rooms', '20', '--points-per-object', '18000', '--workers', '2'],
    'model': ['--points', '100000', '--iters', '3', '--threads', '1'],
    'corners': [],
    'hall': ['--checkpoint', 'work_dirs/demo/train/epoch_5.pth'],  # the model of `make demo`
}
WHAT = {
    'scanner': 'ray casting: per-ray bpy `scene.ray_cast` loop vs batched Embree scanner',
    'writer': 'S3DIS text formatting: per-line Python vs vectorised writer',
    'generate':
    'generation wall time, 3 areas x 50 rooms x 1M points, 2 workers, vs the 10 min goal',
    'convert': 'conversion: mmdet3d collect + S3DISData vs synthdet convert_s3dis',
    'model': 'TR3D train step, inference and peak memory, 1 cm vs 2 cm voxels',
    'corners': 'room corners: traced outline vs convex-hull baseline (error, count, time)',
    'hall': '30M-point generated hall as LAZ -> FCStd (time, memory); windowed vs room recall',
}
# The issues' goals, shown next to the results.
GOALS = {
    'scanner': '>= 30x',
    'generate': '<= 600 s for 150 rooms',
    'convert': '>= 3x',
    'corners': 'traced <= 3 cm, >= 95% right count, <= 1 s per 1M points',
    'hall': 'windowed recall >= 0.95 x room recall, peak < 8 GB',
}
TAIL_LINES = 25


def discover() -> list[str]:
    """Benchmark names (``bench_<name>.py``), the known ones first in ``ARGUMENTS`` order."""
    found = {p.stem[len('bench_'):] for p in (REPO_ROOT / 'benchmarks').glob('bench_*.py')}
    return [n for n in ARGUMENTS if n in found] + sorted(found - set(ARGUMENTS))


def command_of(name: str) -> list[str]:
    return [f'benchmarks/bench_{name}.py', *ARGUMENTS.get(name, [])]


def run_benchmark(name: str, log_dir: Path) -> dict:
    """Run one benchmark, echo its output live, keep it in ``<log_dir>/<name>.log`` and return
    its record (command, exit code, wall seconds, load averages, last line)."""
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
    }
    text = ''.join(output).replace('\r', '\n')
    lines = [line for line in text.splitlines() if line.strip() and '%|' not in line]
    record['last_line'] = lines[-1].strip() if lines else ''
    record['tail'] = lines[-TAIL_LINES:]
    log_dir.mkdir(parents=True, exist_ok=True)
    (log_dir / f'{name}.log').write_text(text)
    (log_dir / f'{name}.json').write_text(json.dumps(record, indent=1) + '\n')
    return record


def machine() -> str:
    """CPU model and core count, for the report's header."""
    model = platform.processor() or 'unknown CPU'
    cpuinfo = Path('/proc/cpuinfo')
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith('model name'):
                model = line.split(':', 1)[1].strip()
                break
    return f'{model}, {os.cpu_count()} cores, Python {platform.python_version()}'


def render(records: list[dict], not_run: list[str]) -> str:
    """docs/benchmarks.md from the benchmark records (and the benchmarks without one)."""
    lines = [
        '# Benchmarks',
        '',
        'Written by `make bench` (`tools/collect_benchmarks.py`), which runs every '
        '`benchmarks/bench_*.py` one after the other and collects the last line of each. Every '
        'benchmark measures both sides of its comparison in the same run, on the same input. '
        f'Machine: {machine()}. Load average = 1/5/15-minute load before and after the run; the '
        'project machine is shared with other jobs, so absolute times vary with it more than '
        'the ratios do.',
        '',
        '| benchmark | what | result (last line) | goal | wall s | load before | load after | '
        'finished |',
        '|---|---|---|---|---|---|---|---|',
    ]
    for r in records:
        result = r['last_line'] if r['returncode'] == 0 else f'FAILED (exit {r["returncode"]})'
        lines.append(f'| `{r["name"]}` | {WHAT.get(r["name"], "")} | {result} | '
                     f'{GOALS.get(r["name"], "")} | {r["seconds"]} | '
                     f'{" / ".join(map(str, r["load_before"]))} | '
                     f'{" / ".join(map(str, r["load_after"]))} | {r["finished"]} |')
    for name in not_run:
        lines.append(f'| `{name}` | {WHAT.get(name, "")} | not run in this collection | '
                     f'{GOALS.get(name, "")} | | | | |')
    lines += ['', '## Outputs', '']
    for r in records:
        lines += [f'### {r["name"]}', '', f'`{r["command"]}`', '', '```', *r['tail'], '```', '']
    return '\n'.join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument(
        '--only', nargs='+', metavar='NAME', help='run only these benchmarks (bench_<NAME>.py)')
    parser.add_argument('--out', type=Path, default=REPO_ROOT / 'docs/benchmarks.md')
    parser.add_argument('--log-dir', type=Path, default=REPO_ROOT / 'work_dirs/bench')
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
    records = []
    for name in names:
        if args.only and name not in args.only:
            previous = args.log_dir / f'{name}.json'
            if previous.is_file():
                records.append(json.loads(previous.read_text()))
            continue
        print(f'[bench] {name}: {" ".join(command_of(name))}', flush=True)
        records.append(run_benchmark(name, args.log_dir))
        print(
            f'[bench] {name}: {records[-1]["seconds"]} s, exit {records[-1]["returncode"]}',
            flush=True)
    done = {r['name'] for r in records}
    args.out.write_text(render(records, [n for n in names if n not in done]))
    print(f'[bench] wrote {args.out}')
    return 0 if all(r['returncode'] == 0 for r in records) else 1


if __name__ == '__main__':
    sys.exit(main())
