"""The shared start of ``tools/train.py``, ``test.py`` and ``predict.py``.

Command-line options common to the tools, config loading with ``--cfg-options`` (loading a
config imports its ``custom_imports``, which registers the plugin's modules with mmdet3d), the
work directory and the launcher. Checkpoints are loaded weights-only
(``projects/synthdet/checkpoint.py``); nothing here changes how ``torch.load`` unpickles.
"""
import argparse
import os
import sys
from pathlib import Path
from typing import Callable, NoReturn

from mmengine.config import Config, DictAction

from projects.synthdet.distributed import prepare_distributed


def run_tool(main: Callable[[], object],
             prog: str,
             bad_input: tuple[type[BaseException], ...],
             failure: tuple[type[BaseException], ...] = (OSError, )) -> NoReturn:
    """Run a tool's ``main`` with the project's exit codes (README, "Safety"): 0 on success,
    2 with one line for ``bad_input`` errors, 1 with one line for ``failure`` errors."""
    try:
        main()
    except bad_input as error:
        print(f'{prog}: error: {error}', file=sys.stderr)
        sys.exit(2)
    except failure as error:
        print(f'{prog}: error: {error}', file=sys.stderr)
        sys.exit(1)
    sys.exit(0)


def add_cfg_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--cfg-options key=value ...``."""
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=DictAction,
        help='override config keys, e.g. train_cfg.max_epochs=2 '
        'test_dataloader.dataset.ann_file=s3dis_infos_Area_9.pkl')


def add_detection_arguments(parser: argparse.ArgumentParser, voxel: float | None) -> None:
    """Add the options of detecting in scans (``predict.py``, ``scan2cad.py``): ``--score-thr``,
    ``--device``, ``--seed``, ``--tta`` and the reading options ``--voxel`` (default ``voxel``;
    None keeps every point) and ``--columns``."""
    import torch
    parser.add_argument(
        '--score-thr',
        type=float,
        default=0.3,
        help='keep detections with at least this score (default 0.3)')
    parser.add_argument('--device', default='cuda:0' if torch.cuda.is_available() else 'cpu')
    parser.add_argument('--seed', type=int, default=0, help='seed of the point sampling')
    parser.add_argument(
        '--tta',
        action='store_true',
        help="test-time augmentation: the config's tta_pipeline and tta_model (8x the time)")
    parser.add_argument(
        '--voxel',
        type=float,
        default=voxel,
        help='keep one point per voxel of this size (m) while reading (default: %(default)s)')
    parser.add_argument('--columns', help='text scans: the columns, e.g. x,y,z,r,g,b or x,y,z,i')
    add_cfg_options(parser)


class TTAConfigError(ValueError):
    """``--tta`` with a config that lacks ``tta_model`` or ``tta_pipeline``."""


def tta_settings(cfg: Config) -> tuple[dict, list]:
    """The config's ``tta_model`` (without its ``module``) and ``tta_pipeline`` for ``--tta``;
    ``TTAConfigError`` naming the config file if it lacks one."""
    if not cfg.get('tta_model') or not cfg.get('tta_pipeline'):
        raise TTAConfigError(
            f'{cfg.filename}: --tta needs tta_model and tta_pipeline in the config')
    return dict(cfg.tta_model), list(cfg.tta_pipeline)


def add_runner_arguments(parser: argparse.ArgumentParser, work_dir_help: str) -> None:
    """Add ``--work-dir``, ``--cfg-options``, ``--launcher`` and ``--local-rank``."""
    parser.add_argument('--work-dir', help=work_dir_help)
    add_cfg_options(parser)
    parser.add_argument(
        '--launcher',
        choices=['none', 'pytorch', 'slurm', 'mpi'],
        default='none',
        help='job launcher for distributed runs (tools/dist_train.sh uses pytorch)')
    parser.add_argument('--local-rank', '--local_rank', type=int, default=0)


def parse_runner_args(parser: argparse.ArgumentParser,
                      argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line of a tool with ``add_runner_arguments``; sets ``LOCAL_RANK``."""
    args = parser.parse_args(argv)
    os.environ.setdefault('LOCAL_RANK', str(args.local_rank))
    return args


def load_config(path: str | Path, cfg_options: dict | None = None) -> Config:
    """Load a config (registering its ``custom_imports``) and apply ``--cfg-options``."""
    cfg = Config.fromfile(path)
    if cfg_options:
        cfg.merge_from_dict(cfg_options)
    return cfg


def runner_config(args: argparse.Namespace) -> Config:
    """The config for mmengine's Runner: ``load_config`` plus the launcher and the work dir
    (``--work-dir``, else the config's ``work_dir``, else ``work_dirs/<config name>``); on a
    machine without CUDA a ``pytorch`` launcher uses gloo (``distributed.prepare_distributed``)."""
    cfg = load_config(args.config, args.cfg_options)
    cfg.launcher = args.launcher
    prepare_distributed(cfg)
    if args.work_dir:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir') is None:
        cfg.work_dir = str(Path('work_dirs') / Path(args.config).stem)
    return cfg
