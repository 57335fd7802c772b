"""Tool runs as jobs of a multi-step benchmark: ``--jobs`` of them at a time, each with one
OpenMP thread and its output in a log of its own, with progress lines while they run."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.tool_runs import ForkedTool, start_tool
from synthdet.work_dir import StepError


@dataclass
class Job:
    """One tool run: ``python ARGS`` from the repository root, its output in ``log``."""
    name: str
    args: list[str]
    log: Path
    process: subprocess.Popen | ForkedTool | None = None
    started: float = 0.0
    shown: str = field(default='', repr=False)


def last_log_line(log: Path) -> str:
    """The last non-empty line of a log, progress bars (carriage returns) included."""
    if not log.is_file():
        return ''
    with open(log, 'rb') as handle:
        handle.seek(max(0, log.stat().st_size - 4096))
        tail = handle.read().decode(errors='replace')
    lines = [line.strip() for line in tail.replace('\r', '\n').splitlines() if line.strip()]
    return lines[-1][:160] if lines else ''


def run_jobs(jobs: list[Job], parallel: int, progress_every: float, label: str,
             forked: bool = False) -> None:
    """Run ``jobs``, ``parallel`` at a time, with one OpenMP thread each (``forked``: forked
    from one process that imported the stack, ``benchmarks/tool_runs.py``); print when each
    starts and ends and, every ``progress_every`` seconds, the newest log line of each running
    one, each line headed ``[label]``. Raises ``StepError`` naming the log of the first job that
    fails (after the others end)."""
    waiting, running, failed = list(jobs), [], []
    try:
        _run_until_done(waiting, running, failed, parallel, progress_every, label, forked)
    finally:  # interrupted: stop the jobs still running
        for job in running:
            job.process.terminate()
            job.process.wait()
    if failed:
        job = failed[0]
        raise StepError(f'{job.name}: `{" ".join(job.args)}` exited with '
                        f'{job.process.returncode}; see {job.log}')


def _run_until_done(waiting: list[Job], running: list[Job], failed: list[Job], parallel: int,
                    progress_every: float, label: str, forked: bool) -> None:
    env = dict(os.environ, OMP_NUM_THREADS='1', PYTHONUNBUFFERED='1', PYTHONWARNINGS='ignore')
    last_shown = time.monotonic()
    while waiting or running:
        while waiting and len(running) < parallel and not failed:
            job = waiting.pop(0)
            job.log.parent.mkdir(parents=True, exist_ok=True)
            command = [sys.executable, *job.args]
            job.log.write_text('$ ' + ' '.join(command) + '\n')
            job.process = start_tool(job.args, job.log, env=env, forked=forked)
            job.started = time.monotonic()
            running.append(job)
            print(f'[{label}] {job.name}: started (log {job.log})', flush=True)
        if not running:
            break
        time.sleep(0.5)
        for job in [j for j in running if j.process.poll() is not None]:
            running.remove(job)
            seconds = time.monotonic() - job.started
            if job.process.returncode:
                failed.append(job)
                print(
                    f'[{label}] {job.name}: FAILED (exit {job.process.returncode}) after '
                    f'{seconds:.0f} s',
                    flush=True)
            else:
                cpu = getattr(job.process, 'cpu_seconds', None)  # known for forked tools
                print(f'[{label}] {job.name}: done in {seconds:.0f} s' +
                      ('' if cpu is None else f' ({cpu:.1f} CPU s)'),
                      flush=True)
        if time.monotonic() - last_shown >= progress_every:
            last_shown = time.monotonic()
            for job in running:
                line = last_log_line(job.log)
                if line and line != job.shown:
                    job.shown = line
                    print(f'[{label}] {job.name}: {line}', flush=True)
        if failed and not running:
            break

