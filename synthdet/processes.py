"""Process hygiene: pool workers and child programs end with their parent, SIGINT and SIGTERM
stop a CLI cleanly, temporary folders of killed runs are cleaned.

Standard library only. A worker pool calls :func:`die_with_parent` as (or in) its initializer;
a child program is started with :func:`ends_with_parent` as its ``preexec_fn``; a CLI runs its
work inside :func:`stop_on_signals` and turns :class:`Interrupted` into a one-line message and
the exit code ``128 + signal number`` (130 for SIGINT, 143 for SIGTERM).
"""
from __future__ import annotations
import ctypes
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

_PR_SET_PDEATHSIG = 1  # linux/prctl.h
_WATCH_INTERVAL = 0.2  # seconds between parent checks where prctl is unavailable


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived (raised in the main thread by :func:`stop_on_signals`)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        """The shell's convention for a process ended by this signal: 128 + its number."""
        return 128 + self.signum


def die_with_parent(parent_pid: int) -> None:
    """End this worker process as soon as ``parent_pid`` (its parent) ends, even by ``kill -9``.

    On Linux the kernel sends SIGKILL when the parent dies (``prctl(PR_SET_PDEATHSIG)``);
    elsewhere a daemon thread checks the parent every 0.2 s. If the parent is already gone, the
    worker exits at once. SIGINT is ignored: the parent handles Ctrl-C and stops its pool.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    armed = False
    if sys.platform.startswith('linux'):
        libc = ctypes.CDLL(None, use_errno=True)
        armed = libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    if os.getppid() != parent_pid:  # the parent died before the death signal was armed
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent_pid, ), daemon=True).start()


def ends_with_parent(parent_pid: int) -> Callable[[], None]:
    """A ``preexec_fn`` for ``subprocess.Popen``: the child program gets SIGKILL as soon as
    ``parent_pid`` (the process starting it, from its main thread) ends, ``kill -9`` included.

    The kernel's parent-death signal (``prctl(PR_SET_PDEATHSIG)``, Linux) survives ``exec``;
    a child whose parent died before it was armed exits at once. Elsewhere it does nothing.
    """

    def arm() -> None:
        if not sys.platform.startswith('linux'):
            return
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(1)

    return arm


def process_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (one of another user counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextmanager
def work_folder(prefix: str) -> Iterator[Path]:
    """A new temporary folder ``<tmp>/<prefix>-<pid>-<random>`` for the block, removed after it.

    Folders of the same ``prefix`` whose process no longer exists (killed before it could
    remove its own) are removed first.
    """
    root = Path(tempfile.gettempdir())
    for stale in root.glob(f'{prefix}-*-*'):
        pid = stale.name[len(prefix) + 1:].split('-', 1)[0]
        if pid.isdigit() and not process_alive(int(pid)) and stale.is_dir() \
                and not stale.is_symlink():
            shutil.rmtree(stale, ignore_errors=True)
    folder = Path(tempfile.mkdtemp(prefix=f'{prefix}-{os.getpid()}-', dir=root))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def parent_alive(parent_pid: int) -> bool:
    """Whether this process's parent is still ``parent_pid`` (an orphan is re-parented)."""
    return os.getppid() == parent_pid


def _watch_parent(parent_pid: int) -> None:
    while parent_alive(parent_pid):
        time.sleep(_WATCH_INTERVAL)
    os._exit(1)


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM raise :class:`Interrupted` in the main thread.

    ``finally`` blocks and context managers (a worker pool's shutdown, the removal of partial
    files) then run as for any exception. The previous handlers are restored afterwards.
    """

    def interrupt(signum: int, frame: object) -> None:
        raise Interrupted(signum)

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
