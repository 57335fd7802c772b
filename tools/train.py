"""Train a synthdet TR3D model with mmengine's Runner.

Usage: python tools/train.py CONFIG [--work-dir DIR] [--resume [CKPT]] [--cfg-options k=v ...]
                             [--amp] [--auto-scale-lr] [--launcher {none,pytorch,slurm,mpi}]

``--amp`` trains with mixed precision (mmengine's AmpOptimWrapper, GPUs only) and
``--auto-scale-lr`` scales the learning rate by the total batch size (processes x batch per
process) over the config's ``auto_scale_lr.base_batch_size``, as mmdet3d's train tool does.
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's `projects`

import torch  # noqa: E402
from mmengine.config import Config  # noqa: E402
from mmengine.runner import Runner  # noqa: E402

from projects.synthdet.bootstrap import (  # noqa: E402
    add_runner_arguments, parse_runner_args, runner_config)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description='Train a synthdet 3D detector.')
    parser.add_argument('config', help='config file, e.g. configs/tr3d/exp2.py')
    parser.add_argument(
        '--resume',
        nargs='?',
        const='auto',
        help='resume from CKPT, or without a value from the latest checkpoint in the work dir')
    parser.add_argument(
        '--amp', action='store_true', help='mixed-precision training (needs a GPU)')
    parser.add_argument(
        '--auto-scale-lr',
        action='store_true',
        help='scale the learning rate by the total batch size / auto_scale_lr.base_batch_size')
    add_runner_arguments(parser, 'logs and checkpoints (default work_dirs/<config>)')
    return parse_runner_args(parser, argv)


def apply_precision_and_lr_options(cfg: Config, amp: bool, auto_scale_lr: bool) -> None:
    """``--amp``: mmengine's AmpOptimWrapper with a dynamic loss scale; ``--auto-scale-lr``:
    enable the config's ``auto_scale_lr``. Raises ``ValueError`` where they cannot apply."""
    if amp:
        if cfg.optim_wrapper.type != 'AmpOptimWrapper':
            if cfg.optim_wrapper.type != 'OptimWrapper':
                raise ValueError(f'--amp needs optim_wrapper.type OptimWrapper, got '
                                 f'{cfg.optim_wrapper.type}')
            cfg.optim_wrapper.type = 'AmpOptimWrapper'
            cfg.optim_wrapper.loss_scale = 'dynamic'
    if auto_scale_lr:
        if 'base_batch_size' not in cfg.get('auto_scale_lr', {}):
            raise ValueError(f'{cfg.filename}: --auto-scale-lr needs '
                             'auto_scale_lr = dict(enable=False, base_batch_size=N)')
        cfg.auto_scale_lr.enable = True


def build_config(args: argparse.Namespace) -> Config:
    """Load the config and apply the command-line overrides and the resume choice."""
    cfg = runner_config(args)
    apply_precision_and_lr_options(cfg, args.amp, args.auto_scale_lr)
    if args.resume == 'auto':
        cfg.resume, cfg.load_from = True, None
    elif args.resume:
        cfg.resume, cfg.load_from = True, args.resume
    return cfg


def main(argv: list[str] | None = None) -> None:
    """Build the Runner from the config and train."""
    args = parse_args(argv)
    if args.amp and not torch.cuda.is_available():
        sys.exit('train: error: --amp needs a CUDA GPU (mmengine\'s AmpOptimWrapper); none found')
    try:
        cfg = build_config(args)
    except ValueError as error:
        sys.exit(f'train: error: {error}')
    Runner.from_cfg(cfg).train()


if __name__ == '__main__':
    main()
