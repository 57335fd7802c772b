"""The shared start of ``tools/train.py``, ``test.py`` and ``predict.py``.

Command-line options common to the tools (numbers checked against their ranges with short
messages), config loading with ``--cfg-options`` (a ``.py`` config is code: loading it runs it
and imports its ``custom_imports``, which registers the plugin's modules with mmdet3d; a JSON
or YAML config is data, refused if it would import or run anything: ``data_config``; a file
that is not a config is one line naming it), the work directory and the launcher (output
paths are checked by ``synthdet.outputs``). Checkpoints are loaded weights-only
(``projects/synthdet/checkpoint.py``); nothing here changes how ``torch.load`` unpickles.

Importing this module loads neither torch nor mmengine: a tool builds its parser and refuses
bad options (``--cfg-options bogus``, ``--device gpu``) before its heavy imports.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Callable, NoReturn

from projects.synthdet.config_checks import ConfigValueError, check_config_values
from projects.synthdet.data_config import ConfigFileError, check_data_config, is_data_config
from projects.synthdet.shipped_model import split_model_arguments
from synthdet.cli import add_int_option, add_score_option, float_in, int_in, shown

if TYPE_CHECKING:
    from mmengine.config import Config


ErrorTypes = tuple[type[BaseException], ...]


def run_tool(main: Callable[[], object],
             prog: str,
             bad_input: ErrorTypes | Callable[[], ErrorTypes],
             failure: ErrorTypes = (OSError, )) -> NoReturn:
    """Run a tool's ``main`` with the project's exit codes (README, "Safety"): 0 on success,
    2 with one line for ``bad_input`` errors, 1 with one line for ``failure`` errors.

    ``bad_input`` may be a function returning the error types, called only when ``main``
    fails: a tool whose errors live in modules that load torch parses its options first."""
    try:
        main()
    except Exception as error:  # sorted into the two kinds below; anything else is a bug
        kinds = bad_input() if callable(bad_input) else bad_input
        if not isinstance(error, (*kinds, *failure)):
            raise
        print(f'{prog}: error: {error}', file=sys.stderr)
        sys.exit(2 if isinstance(error, kinds) else 1)
    sys.exit(0)


SEED_RANGE = (0, 2**32 - 1)  # numpy's and torch's seeds


CONFIG_KEY = re.compile(r'[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_0-9][A-Za-z0-9_]*)*')
DEVICE = re.compile(r'cpu|cuda(:\d{1,4})?')


class ConfigOptionsAction(argparse.Action):
    """``--cfg-options key=value ...``: every item must be ``dotted.key=value`` (a usage error
    naming the item otherwise); the values are read as mmengine's ``DictAction`` reads them
    (numbers, booleans, None, lists and tuples)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: list[str], option_string: str | None = None) -> None:
        for item in values:
            key = item.split('=', 1)[0]
            if '=' not in item or not CONFIG_KEY.fullmatch(key):
                raise argparse.ArgumentError(
                    self, f'expected key=value items such as train_cfg.max_epochs=2, got '
                    f'{shown(item, 40)!r}')
        from mmengine.config import DictAction
        try:
            DictAction(self.option_strings, self.dest)(parser, namespace, values, option_string)
        except (ValueError, IndexError, AssertionError) as error:  # unbalanced brackets
            raise argparse.ArgumentError(self, f'cannot read the values ({error})') from None


def device_name(text: str) -> str:
    """An argparse ``type``: ``cpu``, ``cuda`` or ``cuda:N`` (checked against this machine's
    devices by :func:`check_device` once torch is loaded)."""
    if not DEVICE.fullmatch(text):
        raise argparse.ArgumentTypeError(f'expected cpu, cuda or cuda:N, got {shown(text)}')
    return text


class DeviceError(ValueError):
    """A ``--device`` this machine does not have."""


def check_device(device: str | None) -> str:
    """The device to run on: ``device``, or ``cuda:0`` when a GPU is present and ``cpu``
    otherwise for None; :class:`DeviceError` for a CUDA device this machine lacks."""
    import torch
    if device is None:
        return 'cuda:0' if torch.cuda.is_available() else 'cpu'
    if device.startswith('cuda'):
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        index = int(device.partition(':')[2] or 0)
        if index >= count:
            raise DeviceError(f'--device {device}: this machine has '
                              f'{count or "no"} CUDA device{"" if count == 1 else "s"}; '
                              'use --device cpu')
    return device


def add_cfg_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--cfg-options key=value ...``."""
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=ConfigOptionsAction,
        help='override config keys, e.g. train_cfg.max_epochs=2 '
        'test_dataloader.dataset.ann_file=s3dis_infos_Area_9.pkl')


def add_detection_arguments(parser: argparse.ArgumentParser, voxel: float | None) -> None:
    """Add the options of detecting in scans (``predict.py``, ``scan2cad.py``): ``--score-thr``,
    ``--device``, ``--seed``, ``--tta`` and the reading options ``--voxel`` (default ``voxel``;
    None keeps every point) and ``--columns``."""
    add_score_option(parser, '--score-thr', 0.3, 'keep detections with at least this score')
    parser.add_argument(
        '--device',
        type=device_name,
        help='cpu or cuda:N (default: cuda:0 when there is a GPU, else cpu)')
    add_int_option(parser, '--seed', *SEED_RANGE, 0, 'seed of the point sampling')
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


def add_known_option(parser: argparse.ArgumentParser) -> None:
    """``--known EARLIER_SCAN`` (``predict.py``, ``scan2cad.py``): an earlier, corrected scan
    of the same room (``projects/synthdet/inference/known_objects.py``)."""
    parser.add_argument(
        '--known',
        type=Path,
        help='an earlier scan of the same room with its corrected labels beside it '
        '(<scan stem>.labels.json, from python -m configurator labels): the objects found '
        'again there replace the detections, and only what changed is detected')


class TTAConfigError(ValueError):
    """``--tta`` with a config that lacks ``tta_model`` or ``tta_pipeline``."""


def parse_model_and_scans(parser: argparse.ArgumentParser, argv: list[str] | None,
                          scans_help: str, out_help: str,
                          no_scan: str) -> tuple[argparse.Namespace, list[str]]:
    """Parse ``[CONFIG CHECKPOINT] SCAN... --out OUT`` and the detection options
    (``predict.py``, ``eval_scans.py``): the arguments, with ``config`` and ``checkpoint`` None
    for the shipped model, and the scans; the parser's one-line error ``no_scan`` without one."""
    parser.add_argument('inputs', nargs='+', metavar='[CONFIG CHECKPOINT] SCAN',
                        help='a config file (.py, .json, .yaml) and its checkpoint, then '
                        f'{scans_help}; without a config, the shipped model')
    parser.add_argument('--out', required=True, help=out_help)
    add_detection_arguments(parser, voxel=None)
    args = parser.parse_args(argv)
    args.config, args.checkpoint, scans = split_model_arguments(args.inputs)
    if not scans:
        parser.error(no_scan)
    return args, scans


def tta_settings(cfg: Config) -> tuple[dict, list]:
    """The config's ``tta_model`` (without its ``module``) and ``tta_pipeline`` for ``--tta``;
    ``TTAConfigError`` naming the config file if it lacks one."""
    if not cfg.get('tta_model') or not cfg.get('tta_pipeline'):
        raise TTAConfigError(
            f'{cfg.filename}: --tta needs tta_model and tta_pipeline in the config')
    return dict(cfg.tta_model), list(cfg.tta_pipeline)


# what each distributed launcher sets, read by mmengine's init_dist
LAUNCH_ENVIRONMENT = {
    'pytorch': ('RANK', 'WORLD_SIZE', 'MASTER_ADDR', 'MASTER_PORT'),
    'slurm': ('SLURM_PROCID', 'SLURM_NTASKS', 'SLURM_NODELIST'),
    'mpi': ('OMPI_COMM_WORLD_RANK', 'OMPI_COMM_WORLD_SIZE', 'OMPI_COMM_WORLD_LOCAL_RANK'),
}


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
    parser.add_argument('--local-rank', '--local_rank', type=int_in(0, 4095), default=0)
    args = parser.parse_args(argv)
    missing = [name for name in LAUNCH_ENVIRONMENT.get(args.launcher, ())
               if name not in os.environ]
    if missing:
        parser.error(f'--launcher {args.launcher}: not started by that launcher '
                     f'({", ".join(missing)} not set); tools/dist_train.sh, dist_test.sh '
                     'and slurm_train.sh start distributed runs')
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
    from mmengine.config import Config
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
    try:
        check_config_values(cfg, str(path))
    except ConfigValueError as error:
        raise ConfigFileError(str(error)) from None
    return cfg


def runner_config(args: argparse.Namespace) -> Config:
    """The config for mmengine's Runner: ``load_config`` plus the launcher and the work dir
    (``--work-dir``, else the config's ``work_dir``, else ``work_dirs/<config name>``); on a
    machine without CUDA a ``pytorch`` launcher uses gloo (``distributed.prepare_distributed``)."""
    from projects.synthdet.distributed import prepare_distributed
    cfg = load_config(args.config, args.cfg_options)
    cfg.launcher = args.launcher
    prepare_distributed(cfg)
    if args.work_dir:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir') is None:
        cfg.work_dir = str(Path('work_dirs') / Path(args.config).stem)
    return cfg
