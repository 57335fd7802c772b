"""The project's Python tools as the benchmarks run them (``python ARGS`` from the repository
root): each as a new interpreter, what a user runs, its start-up included (the default), or
forked from one server process that imported the stack once (``forked=True``, the benchmarks'
``--fork-tools``): each tool still runs from its command line in a process of its own, but
without the start-up of its interpreter and imports (several CPU seconds for every tool that
loads the detector). The smoke runs of the benchmarks use the second way.

The server is multiprocessing's fork server, started at the first forked tool with the
modules of :data:`PRELOAD` imported (bpy first: bpy and open3d ship different ``libtbb``s and
the first one loaded wins); it ends with the process that started it, which waits for it (its
CPU time then counts in that process's children's, as ``time`` shows it). A forked tool gets the
environment given to it; OpenMP reads ``OMP_NUM_THREADS`` when it loads (in the server), so
the tool's value is also set through ``torch.set_num_threads``.
"""
from __future__ import annotations

import argparse
import atexit
import json
import logging
import multiprocessing
import multiprocessing.forkserver
import os
import resource
import runpy
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# imported once by the fork server: what the tools the benchmarks run import (bpy first)
PRELOAD = ('bpy', 'torch', 'MinkowskiEngine', 'mmengine.runner', 'mmdet3d.apis',
           'mmdet3d.datasets', 'mmdet3d.engine', 'mmdet3d.evaluation', 'mmdet3d.models',
           'mmdet3d.structures', 'mmdet3d.visualization', 'projects.synthdet.models',
           'projects.synthdet.datasets.synthdet_s3dis',
           'projects.synthdet.evaluation.indoor_metric',
           'projects.synthdet.datasets.s3dis_converter', 'projects.synthdet.bootstrap',
           'projects.synthdet.inference.detector', 'projects.synthdet.evaluation.real_scans',
           'generator.pipeline', 'configurator.corners', 'configurator.labels', 'synthdet.scan_io',
           'benchmarks.tool_runs')


class ForkedTool:
    """A tool running in a child of the fork server, with the part of ``subprocess.Popen``'s
    interface the benchmarks use: ``poll``, ``wait``, ``terminate``, ``returncode``; and
    once it ended, ``peak_kb``, its peak resident memory (its own or a child's, the larger), and
    ``cpu_seconds``, the user and system CPU time of it and its children (not the server's)."""

    def __init__(self, args: Sequence[str | os.PathLike], env: Mapping[str, str], stdout: Path,
                 stderr: Path | None) -> None:
        context = multiprocessing.get_context('forkserver')
        context.set_forkserver_preload(list(PRELOAD))
        _stop_server_at_exit()
        self.args = [str(arg) for arg in args]
        self.returncode: int | None = None
        self.peak_kb: int | None = None
        self.cpu_seconds: float | None = None
        handle, usage_path = tempfile.mkstemp(prefix='synthdet-tool-', suffix='.json')
        os.close(handle)
        self._usage_file = Path(usage_path)
        self._process = context.Process(
            target=_run_in_child,
            args=(self.args, dict(env), str(stdout), None if stderr is None else str(stderr),
                  str(self._usage_file)),
            daemon=False)
        self._process.start()

    def poll(self) -> int | None:
        if self.returncode is None and self._process.exitcode is not None:
            self._finish()
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is not None:
            return self.returncode
        self._process.join(timeout)
        if self._process.exitcode is None:
            raise subprocess.TimeoutExpired(self.args, timeout)
        return self.poll()

    def terminate(self) -> None:
        if self.poll() is None:
            self._process.terminate()

    def _finish(self) -> None:
        self.returncode = self._process.exitcode  # a signal: -N, as Popen reports it
        try:
            usage = json.loads(self._usage_file.read_text())
            self.peak_kb, self.cpu_seconds = usage['peak_kb'], usage['cpu_seconds']
        except (OSError, ValueError, KeyError):
            pass  # killed before it wrote its usage
        self._usage_file.unlink(missing_ok=True)
        self._process.close()


def _stop_server_at_exit() -> None:
    """Once: at exit, end the fork server and wait for it (multiprocessing leaves it to end
    by itself once this process is gone, unwaited; ``_stop`` is how its own tests end it)."""
    server = multiprocessing.forkserver._forkserver
    if not getattr(server, '_synthdet_stop_registered', False):
        server._synthdet_stop_registered = True
        atexit.register(server._stop)


def _run_in_child(args: list[str], env: dict[str, str], stdout: str, stderr: str | None,
                  usage_file: str) -> None:
    """In the forked child: the tool's output into the files, its environment, its command
    line, then the tool as ``python ARGS`` runs it; exit handlers the tool registered run at the
    end (those of the server are not this tool's)."""
    atexit._clear()
    out = os.open(stdout, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    err = out if stderr is None else os.open(stderr, os.O_WRONLY | os.O_CREAT | os.O_APPEND,
                                             0o644)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(out, 1)
    os.dup2(err, 2)
    os.environ.clear()
    os.environ.update(env)
    os.chdir(REPO)
    multiprocessing.set_start_method(None, force=True)  # a new interpreter's default, not ours
    if 'torch' in sys.modules and env.get('OMP_NUM_THREADS', '').isdigit():
        sys.modules['torch'].set_num_threads(int(env['OMP_NUM_THREADS']))
    try:
        if args[0] == '-m':
            sys.argv = [args[1], *args[2:]]
            sys.path.insert(0, str(REPO))
            runpy.run_module(args[1], run_name='__main__', alter_sys=True)
        else:
            script = (REPO / args[0]).resolve()
            sys.argv = [str(script), *args[1:]]
            sys.path.insert(0, str(script.parent))
            runpy.run_path(str(script), run_name='__main__')
    finally:
        atexit._run_exitfuncs()
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        usage = [resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                     resource.RUSAGE_CHILDREN)]
        Path(usage_file).write_text(
            json.dumps({
                'peak_kb': max(u.ru_maxrss for u in usage),
                'cpu_seconds': sum(u.ru_utime + u.ru_stime for u in usage)
            }))


def add_fork_tools_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--fork-tools`` to a benchmark's ``parser``: its tools run forked (see above)."""
    parser.add_argument(
        '--fork-tools',
        action='store_true',
        help='run the tools forked from one process that imported the stack once (a quick '
        'check of the benchmark: no start-up per tool)')


def start_tool(args: Sequence[str | os.PathLike],
               stdout: Path,
               stderr: Path | None = None,
               env: Mapping[str, str] | None = None,
               forked: bool = False) -> subprocess.Popen | ForkedTool:
    """Start ``python ARGS`` from the repository root, its output appended to ``stdout`` (and
    its error output to ``stderr``, or to ``stdout`` when None)."""
    env = dict(os.environ if env is None else env)
    if forked:
        return ForkedTool(args, env, stdout, stderr)
    with open(stdout, 'ab') as out:
        err = subprocess.STDOUT if stderr is None else open(stderr, 'ab')
        try:
            return subprocess.Popen([sys.executable, *map(str, args)],
                                    cwd=REPO,
                                    stdout=out,
                                    stderr=err,
                                    env=env)
        finally:
            if stderr is not None:
                err.close()


def run_tool(args: Sequence[str | os.PathLike],
             env: Mapping[str, str] | None = None,
             forked: bool = False,
             timeout: float | None = None) -> subprocess.CompletedProcess:
    """Run ``python ARGS`` from the repository root to its end; its output captured as text
    (``stdout``, ``stderr``) and, forked, ``peak_kb`` and ``cpu_seconds`` as :class:`ForkedTool`
    has them (else None)."""
    if not forked:
        done = subprocess.run([sys.executable, *map(str, args)],
                              cwd=REPO,
                              env=None if env is None else dict(env),
                              capture_output=True,
                              text=True,
                              timeout=timeout)
        done.peak_kb = done.cpu_seconds = None
        return done
    with tempfile.TemporaryDirectory(prefix='synthdet-tool-') as folder:
        stdout, stderr = Path(folder) / 'stdout', Path(folder) / 'stderr'
        tool = start_tool(args, stdout, stderr, env, forked=True)
        try:
            code = tool.wait(timeout)
        except subprocess.TimeoutExpired:
            tool.terminate()
            tool.wait()
            raise
        done = subprocess.CompletedProcess([sys.executable, *map(str, args)], code,
                                           stdout.read_text(errors='replace'),
                                           stderr.read_text(errors='replace'))
    done.peak_kb, done.cpu_seconds = tool.peak_kb, tool.cpu_seconds
    return done
