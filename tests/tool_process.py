"""Run the project's tools in a subprocess, as a user would (shared by the tool tests)."""
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Callable

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


def special_files(folder: Path, suffix: str, device: str) -> tuple[Path, Path, Path]:
    """A FIFO, a symbolic link to the character ``device`` and an empty folder in ``folder``,
    named ``fifo<suffix>``, ``device<suffix>`` and ``folder<suffix>``: paths a tool must name,
    never read or write as files."""
    fifo, link, empty = (folder / f'{name}{suffix}' for name in ('fifo', 'device', 'folder'))
    os.mkfifo(fifo)
    link.symlink_to(device)
    empty.mkdir()
    return fifo, link, empty


def train_tiny(data_root: Path, ann_file: str, work: Path, epochs: int,
               pipeline: Callable | None = None) -> list[dict]:
    """Train ``configs/tr3d/tiny.py`` on ``ann_file`` of ``data_root`` for ``epochs`` with
    ``tools/train.py`` (seed 0, a log line per iteration, no validation) and return the logged
    scalar records; ``pipeline(cfg)``, if given, makes the training pipeline."""
    from mmengine.config import Config
    cfg = Config.fromfile(REPO / 'configs' / 'tr3d' / 'tiny.py')
    train_set = cfg.train_dataloader.dataset.dataset.datasets[0]
    if pipeline is not None:
        train_set.pipeline = pipeline(cfg)
    train_set.data_root = f'{data_root}/'
    train_set.ann_file = ann_file
    config = work.parent / f'{work.name}_tiny.py'
    cfg.dump(config)
    run_tool('tools/train.py', config, '--work-dir', work, '--cfg-options',
             f'train_cfg.max_epochs={epochs}', 'default_hooks.logger.interval=1', 'val_cfg=None',
             'val_dataloader=None', 'val_evaluator=None', 'randomness.seed=0')
    [scalars] = work.glob('*/vis_data/scalars.json')
    return [json.loads(line) for line in scalars.read_text().splitlines()]
