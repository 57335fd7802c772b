"""Train a synthdet TR3D model with mmengine's Runner.

Usage: python tools/train.py CONFIG [--work-dir DIR] [--resume [CKPT]] [--trust-checkpoint]
                             [--cfg-options k=v ...] [--launcher {none,pytorch,slurm,mpi}]

Checkpoints are loaded weights-only (projects/synthdet/checkpoint.py); ``--trust-checkpoint``
unpickles the one resumed checkpoint fully, and only one inside the work directory. At the end
the final weights are also written as ``<work_dir>/inference.pth`` (state_dict and meta only).
"""
import argparse
import os
import pickle
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))  # the configs' custom_imports load `projects.synthdet`

import torch  # noqa: E402
from mmengine.config import Config, DictAction  # noqa: E402
from mmengine.dist import is_main_process  # noqa: E402
from mmengine.runner import Runner  # noqa: E402

INFERENCE_CHECKPOINT = 'inference.pth'


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description='Train a synthdet 3D detector.')
    parser.add_argument('config', help='config file, e.g. configs/tr3d/exp2.py')
    parser.add_argument('--work-dir', help='logs and checkpoints (default work_dirs/<config>)')
    parser.add_argument(
        '--resume',
        nargs='?',
        const='auto',
        help='resume from CKPT, or without a value from the latest checkpoint in the work dir')
    parser.add_argument(
        '--trust-checkpoint',
        action='store_true',
        help='unpickle the resumed checkpoint fully (runs code in it): only for a checkpoint of '
        'your own inside the work dir that the default weights-only load refuses')
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=DictAction,
        help='override config keys, e.g. train_cfg.max_epochs=2')
    parser.add_argument(
        '--launcher',
        choices=['none', 'pytorch', 'slurm', 'mpi'],
        default='none',
        help='job launcher for distributed training (tools/dist_train.sh uses pytorch)')
    parser.add_argument('--local-rank', '--local_rank', type=int, default=0)
    args = parser.parse_args(argv)
    os.environ.setdefault('LOCAL_RANK', str(args.local_rank))
    return args


def build_config(args: argparse.Namespace) -> Config:
    """Load the config and apply the command-line overrides."""
    cfg = Config.fromfile(args.config)
    cfg.launcher = args.launcher
    if args.cfg_options:
        cfg.merge_from_dict(args.cfg_options)
    if args.work_dir:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir') is None:
        cfg.work_dir = str(Path('work_dirs') / Path(args.config).stem)
    if args.resume == 'auto':
        cfg.resume, cfg.load_from = True, None
    elif args.resume:
        cfg.resume, cfg.load_from = True, args.resume
    if args.trust_checkpoint:
        from projects.synthdet.checkpoint import CheckpointError, trusted_resume_path
        from mmengine.runner import find_latest_checkpoint
        resume = cfg.load_from if args.resume != 'auto' else find_latest_checkpoint(cfg.work_dir)
        if not args.resume or resume is None:
            raise CheckpointError(f'{cfg.work_dir}: --trust-checkpoint needs --resume and a '
                                  'checkpoint to resume from')
        cfg.load_from = trusted_resume_path(resume, cfg.work_dir)
    return cfg


def publish_final_checkpoint(work_dir: str | Path) -> Path | None:
    """Write the last saved checkpoint of ``work_dir`` as ``<work_dir>/inference.pth``."""
    from projects.synthdet.checkpoint import load_checkpoint_file, save_inference_checkpoint
    last = Path(work_dir) / 'last_checkpoint'
    if not last.is_file():
        return None
    checkpoint = load_checkpoint_file(last.read_text().strip())
    return save_inference_checkpoint(checkpoint, Path(work_dir) / INFERENCE_CHECKPOINT)


def main(argv: list[str] | None = None) -> int:
    """Build the Runner from the config, train, and publish the final inference checkpoint.

    Returns 0, or 2 with a one-line message for a checkpoint the weights-only load refuses.
    """
    from projects.synthdet.checkpoint import TRAINING_CHECKPOINT_TYPES, CheckpointError, refused
    try:
        cfg = build_config(parse_args(argv))
        with torch.serialization.safe_globals(TRAINING_CHECKPOINT_TYPES):
            Runner.from_cfg(cfg).train()
    except CheckpointError as error:
        print(f'train.py: error: {error}', file=sys.stderr)
        return 2
    except pickle.UnpicklingError as error:  # raised by mmengine's weights-only resume
        hint = 'if it is your own, resume it with --trust-checkpoint'
        print(f'train.py: error: {refused(cfg.load_from or cfg.work_dir, error, hint)}',
              file=sys.stderr)
        return 2
    if is_main_process():
        published = publish_final_checkpoint(cfg.work_dir)
        if published is not None:
            print(f'inference checkpoint (weights and meta only): {published}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
