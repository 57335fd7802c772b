"""Run the project's tools in a subprocess, as a user would (shared by the tool tests)."""
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_tool(*args, timeout: float = 900) -> subprocess.CompletedProcess:
    """Run ``python <args>`` from the repository root; fail with its output on a non-zero exit.

    One OpenMP thread unless the caller chose otherwise: MinkowskiEngine's CPU kernels run
    slower with a thread per core on a shared 2-core machine.
    """
    env = {**os.environ, 'OMP_NUM_THREADS': os.environ.get('OMP_NUM_THREADS', '1')}
    proc = subprocess.run([sys.executable, *map(str, args)],
                          cwd=REPO,
                          capture_output=True,
                          text=True,
                          timeout=timeout,
                          env=env)
    assert proc.returncode == 0, f'{args[0]} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}'
    return proc
