"""Turn a training checkpoint into an inference checkpoint (state_dict and meta only).

Usage: python tools/publish_model.py IN_FILE OUT_FILE

Like mmdet's ``publish_model``: the optimizer, parameter scheduler and message hub are dropped,
``meta`` keeps only plain values (classes, epoch, config text, ...), and the output is named
``<OUT_FILE stem>-<first 8 hex digits of its SHA-256>.pth``. The input is loaded weights-only
(a checkpoint that holds anything else is refused, exit 2); the output loads with plain
``torch.load(weights_only=True)``.
"""
import argparse
import os
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))

from projects.synthdet.checkpoint import (  # noqa: E402
    CheckpointError, load_checkpoint_file, save_inference_checkpoint, sha256_prefix)


def publish(in_file: str | Path, out_file: str | Path) -> Path:
    """Write the inference checkpoint of ``in_file`` as ``<out stem>-<sha256[:8]>.pth``."""
    out_file = Path(out_file)
    written = save_inference_checkpoint(load_checkpoint_file(in_file), out_file)
    final = out_file.with_name(f'{out_file.stem}-{sha256_prefix(written)}.pth')
    os.replace(written, final)
    return final


def main(argv: list[str] | None = None) -> int:
    """Publish IN_FILE; returns 0, or 2 with a one-line message for a refused input."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('in_file', help='training checkpoint, e.g. work_dirs/exp2/epoch_12.pth')
    parser.add_argument('out_file', help='output name, e.g. tr3d_exp2.pth')
    args = parser.parse_args(argv)
    try:
        final = publish(args.in_file, args.out_file)
    except CheckpointError as error:
        print(f'publish_model.py: error: {error}', file=sys.stderr)
        return 2
    except OSError as error:
        print(
            f'publish_model.py: error: {args.out_file}: cannot write ({error.strerror})',
            file=sys.stderr)
        return 1
    print(f'published {final}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
