"""Train a synthdet TR3D model with mmengine's Runner.

Usage: python tools/train.py CONFIG [--work-dir DIR] [--resume [CKPT]] [--trust-checkpoint]
                             [--cfg-options k=v ...] [--amp] [--auto-scale-lr]
                             [--launcher {none,pytorch,slurm,mpi}]

``--amp`` trains with mixed precision (mmengine's AmpOptimWrapper, GPUs only) and
``--auto-scale-lr`` scales the learning rate by the total batch size (processes x batch per
process) over the config's ``auto_scale_lr.base_batch_size``, as mmdet3d's train tool does.

Checkpoints are loaded weights-only (projects/synthdet/checkpoint.py); ``--trust-checkpoint``
unpickles the one resumed checkpoint fully, and only one inside the work directory. The resumed
checkpoint is checked before training starts: a missing file, one that is not a checkpoint (a
text file, a truncated one), one refused by the weights-only load and one without training state
(an inference checkpoint) each end with one line naming the file and exit code 2. At the end
the final weights are also written as ``<work_dir>/inference.pth`` (state_dict and meta only).
"""
from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from projects.synthdet.bootstrap import parse_runner_args, runner_config
from synthdet.cli import OneLineParser
from synthdet.info_files import InfoFileError
from synthdet.outputs import OutputFailed, check_output_dir

if TYPE_CHECKING:
    from mmengine.config import Config

INFERENCE_CHECKPOINT = 'inference.pth'


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = OneLineParser(description='Train a synthdet 3D detector.')
    parser.add_argument('config', help='config file, e.g. configs/tr3d/exp2.py')
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
        '--amp', action='store_true', help='mixed-precision training (needs a GPU)')
    parser.add_argument(
        '--auto-scale-lr',
        action='store_true',
        help='scale the learning rate by the total batch size / auto_scale_lr.base_batch_size')
    return parse_runner_args(parser, 'logs and checkpoints (default work_dirs/<config>)', argv)


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
    from mmengine.runner import find_latest_checkpoint

    from projects.synthdet.checkpoint import (CheckpointError, check_resumable,
                                              trusted_resume_path)
    cfg = runner_config(args)
    apply_precision_and_lr_options(cfg, args.amp, args.auto_scale_lr)
    if args.resume == 'auto':
        cfg.resume, cfg.load_from = True, None
    elif args.resume:
        cfg.resume, cfg.load_from = True, args.resume
    resume = cfg.load_from if args.resume != 'auto' else find_latest_checkpoint(cfg.work_dir)
    if args.trust_checkpoint:
        if not args.resume or resume is None:
            raise CheckpointError(f'{cfg.work_dir}: --trust-checkpoint needs --resume and a '
                                  'checkpoint to resume from')
        cfg.load_from = trusted_resume_path(resume, cfg.work_dir)
    elif args.resume and resume is not None:
        check_resumable(resume)  # a bad file is one line here, not a traceback in mmengine
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

    Returns 0, 2 with a one-line message for a bad option or a checkpoint the weights-only
    load refuses, or 1 with one line when the work dir cannot be written (checked first) or a
    write fails (a full disk).
    """
    args = parse_args(argv)  # bad options end here, before torch and mmengine are loaded
    import torch
    from mmengine.dist import is_main_process
    from mmengine.runner import Runner

    from projects.synthdet.checkpoint import TRAINING_CHECKPOINT_TYPES, CheckpointError, refused
    if args.amp and not torch.cuda.is_available():
        print('train: error: --amp needs a CUDA GPU (mmengine\'s AmpOptimWrapper); none found',
              file=sys.stderr)
        return 2
    try:
        cfg = build_config(args)
        check_output_dir(cfg.work_dir, '--work-dir')
    except (CheckpointError, ValueError) as error:  # OutputRefused too
        print(f'train: error: {error}', file=sys.stderr)
        return 2
    except OutputFailed as error:  # a work dir this process cannot write in
        print(f'train: error: {error}', file=sys.stderr)
        return 1
    try:
        with torch.serialization.safe_globals(TRAINING_CHECKPOINT_TYPES):
            Runner.from_cfg(cfg).train()
        if is_main_process():
            published = publish_final_checkpoint(cfg.work_dir)
            if published is not None:
                print(f'inference checkpoint (weights and meta only): {published}')
    except pickle.UnpicklingError as error:  # raised by mmengine's weights-only resume
        hint = 'if it is your own, resume it with --trust-checkpoint'
        print(f'train: error: {refused(cfg.load_from or cfg.work_dir, error, hint)}',
              file=sys.stderr)
        return 2
    except InfoFileError as error:  # an info pickle that is not plain data (it may hold code)
        print(f'train: error: {error}', file=sys.stderr)
        return 2
    except OutputFailed as error:  # the inference checkpoint: the message names it
        print(f'train: error: {error}', file=sys.stderr)
        return 1
    except OSError as error:  # a full disk, a work dir gone: a run-time failure
        print(f'train: error: {error.filename or cfg.work_dir}: {error.strerror or error}',
              file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
