"""Train a synthdet TR3D model with mmengine's Runner.

Usage: python tools/train.py CONFIG [--work-dir DIR] [--resume [CKPT]] [--cfg-options k=v ...]
                             [--launcher {none,pytorch,slurm,mpi}]
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's `projects`

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
    add_runner_arguments(parser, 'logs and checkpoints (default work_dirs/<config>)')
    return parse_runner_args(parser, argv)


def build_config(args: argparse.Namespace) -> Config:
    """Load the config and apply the command-line overrides and the resume choice."""
    cfg = runner_config(args)
    if args.resume == 'auto':
        cfg.resume, cfg.load_from = True, None
    elif args.resume:
        cfg.resume, cfg.load_from = True, args.resume
    return cfg


def main(argv: list[str] | None = None) -> None:
    """Build the Runner from the config and train."""
    Runner.from_cfg(build_config(parse_args(argv))).train()


if __name__ == '__main__':
    main()
