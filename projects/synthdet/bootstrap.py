"""The shared start of ``tools/train.py``, ``test.py`` and ``predict.py``.

Command-line options common to the tools (numbers checked against their ranges with short
messages), config loading with ``--cfg-options`` (a ``.py`` config is code: loading it runs it
and imports its ``custom_imports``, which registers the plugin's modules with mmdet3d; a JSON
or YAML config is data, refused if it would import or run anything: ``data_config``; a file
that is not a config is one line naming it), the checks of output paths before any work, the
work directory and the launcher. Checkpoints are loaded weights-only
(``projects/synthdet/checkpoint.py``); nothing here changes how ``torch.load`` unpickles.
"""
import argparse
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Callable, NoReturn

from mmengine.config import Config, DictAction

from projects.synthdet.data_config import ConfigFileError, check_data_config, is_data_config
from projects.synthdet.distributed import prepare_distributed
from synthdet.outputs import OutputRefused, check_output


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


def shown(text: object, limit: int = 24) -> str:
    """``text`` for a message: at most ``limit`` characters (a 300-digit number is cut)."""
    text = str(text)
    return text if len(text) <= limit else f'{text[:limit - 3]}...'


def int_in(low: int, high: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``[low, high]``, with a short message otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected an integer, got {shown(text)}') from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f'expected an integer from {low:,} to {high:,}, got {shown(text)}')
        return value

    return parse


def float_in(low: float, high: float, include_low: bool = True) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in ``[low, high]`` (``(low, high]`` without
    ``include_low``), with a short message otherwise."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected a number, got {shown(text)}') from None
        if not (math.isfinite(value) and (low <= value if include_low else low < value)
                and value <= high):
            interval = f'{"[" if include_low else "("}{low:g}, {high:g}]'
            raise argparse.ArgumentTypeError(
                f'expected a number in {interval}, got {shown(text)}')
        return value

    return parse


OutputPathError = OutputRefused  # an output path that cannot be written; the message names it


def _nearest_existing(path: Path) -> Path:
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def _check_can_create_in(folder: Path, output: Path) -> None:
    """Create and remove a temporary file in ``folder``: the one check that also holds for root
    and read-only file systems."""
    try:
        descriptor, name = tempfile.mkstemp(prefix='.write-check-', dir=folder)
    except OSError as error:
        raise OutputPathError(f'{output}: cannot write in {folder} '
                              f'({error.strerror or type(error).__name__})') from None
    os.close(descriptor)
    os.unlink(name)


def check_output_dir(path: str | Path, option: str = '--out') -> None:
    """:class:`OutputPathError` unless ``path`` is a writable folder or can be created as one
    (the folder is not created; a probe file is created and removed); a file, device or FIFO
    is refused by ``synthdet.outputs.check_output``."""
    path = check_output(path, option, folder=True)
    existing = _nearest_existing(path)
    if not existing.is_dir():
        raise OutputPathError(f'{path}: cannot be created ({existing} is a file)')
    _check_can_create_in(existing, path)


def check_output_file(path: str | Path, make_parents: bool = False, option: str = '--out') -> None:
    """:class:`OutputPathError` unless the file ``path`` can be written: not a folder, device
    or FIFO (``synthdet.outputs.check_output``), in a writable folder that exists (or, with
    ``make_parents``, can be created). The file is not created; a probe file beside it is
    created and removed."""
    path = check_output(path, option)
    if make_parents:
        check_output_dir(path.parent)
        return
    if not path.parent.is_dir():
        raise OutputPathError(f'{path}: the folder {path.parent} does not exist')
    _check_can_create_in(path.parent, path)


SEED_RANGE = (0, 2**32 - 1)  # numpy's and torch's seeds


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
        type=float_in(0.0, 1.0),
        default=0.3,
        help='keep detections with at least this score, in [0, 1] (default 0.3)')
    parser.add_argument('--device', default='cuda:0' if torch.cuda.is_available() else 'cpu')
    parser.add_argument(
        '--seed',
        type=int_in(*SEED_RANGE),
        default=0,
        help=f'seed of the point sampling, {SEED_RANGE[0]} to {SEED_RANGE[1]} (default 0)')
    parser.add_argument(
        '--tta',
        action='store_true',
        help="test-time augmentation: the config's tta_pipeline and tta_model (8x the time)")
    parser.add_argument(
        '--voxel',
        type=float_in(0.0, 10.0, include_low=False),
        default=voxel,
        help='keep one point per voxel of this size (m, at most 10) while reading '
        '(default: %(default)s)')
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


def parse_runner_args(parser: argparse.ArgumentParser, work_dir_help: str,
                      argv: list[str] | None = None) -> argparse.Namespace:
    """Add the options every runner tool has (``--work-dir``, described by ``work_dir_help``,
    ``--cfg-options``, ``--launcher`` and ``--local-rank``) to ``parser`` and parse the command
    line; sets ``LOCAL_RANK``."""
    parser.add_argument('--work-dir', help=work_dir_help)
    add_cfg_options(parser)
    parser.add_argument(
        '--launcher',
        choices=['none', 'pytorch', 'slurm', 'mpi'],
        default='none',
        help='job launcher for distributed runs (tools/dist_train.sh uses pytorch)')
    parser.add_argument('--local-rank', '--local_rank', type=int, default=0)
    args = parser.parse_args(argv)
    os.environ.setdefault('LOCAL_RANK', str(args.local_rank))
    return args


CONFIG_SUFFIXES = ('.py', '.json', '.yml', '.yaml')  # the files mmengine's Config reads


def check_config_path(path: str | Path) -> None:
    """:class:`ConfigFileError` for a CONFIG that is missing or not a config file by its name."""
    path = Path(path)
    if not path.is_file():
        raise ConfigFileError(f'{path}: config file not found')
    if path.suffix.lower() not in CONFIG_SUFFIXES:
        raise ConfigFileError(f'{path}: not a config file (expected '
                              f'{", ".join(CONFIG_SUFFIXES)}, e.g. configs/tr3d/exp2.py)')


def load_config(path: str | Path, cfg_options: dict | None = None) -> Config:
    """Load a config and apply ``--cfg-options``; :class:`ConfigFileError` naming the file
    (and line) if it cannot be loaded. A ``.py`` config is Python code, run with its
    ``custom_imports``; a JSON or YAML config is data, refused if it would import or run code
    (``data_config.check_data_config``, which registers the plugin's classes) and read without
    mmengine's text substitutions (what was checked is what is read)."""
    check_config_path(path)
    data_only = is_data_config(path)
    if data_only:
        check_data_config(path)
    try:
        cfg = Config.fromfile(path, use_predefined_variables=not data_only,
                              use_environment_variables=not data_only)
        if cfg_options:
            cfg.merge_from_dict(cfg_options)
    except SyntaxError as error:
        raise ConfigFileError(f'{path}:{error.lineno}: not a config file (invalid Python: '
                              f'{error.msg})') from None
    except Exception as error:  # mmengine raises what the file's code raises
        message = str(error).strip().split('\n')[0] or type(error).__name__
        raise ConfigFileError(f'{path}: cannot load the config ({shown(message, 160)})') from None
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
