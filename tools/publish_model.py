"""Turn a training checkpoint into an inference checkpoint (state_dict and meta only).

Usage: python tools/publish_model.py IN_FILE OUT_FILE [--half]

Like mmdet's ``publish_model``: the optimizer, parameter scheduler and message hub are dropped,
``meta`` keeps only plain values (classes, epoch, config text, ...), and the output is named
``<OUT_FILE stem>-<first 8 hex digits of its SHA-256>.pth``. The input is loaded weights-only
(a checkpoint that holds anything else, or a file that is not a checkpoint, is refused with one
line naming it, exit 2); the output loads with plain ``torch.load(weights_only=True)``. The output
folder is checked first (it must exist, exit 2 otherwise, and be writable, exit 1 otherwise);
the file is written under a temporary name and renamed into place (exit 1 if that fails);
OUT_FILE itself is never written, so IN_FILE may have the same name. ``--half`` stores the
floating-point weights in float16, half the size (the shipped model,
``projects/synthdet/weights/``); a model loads them into its float32 parameters.
"""
import sys
from pathlib import Path

from synthdet.cli import OneLineParser
from synthdet.outputs import OutputFailed, check_output_file


def publish(in_file: str | Path, out_file: str | Path, half: bool = False) -> Path:
    """Write the inference checkpoint of ``in_file`` as ``<out stem>-<sha256[:8]>.pth``
    (``half``: float16 weights)."""
    from projects.synthdet.checkpoint import load_checkpoint_file, save_inference_checkpoint
    return save_inference_checkpoint(
        load_checkpoint_file(in_file), out_file, digest_suffix=True, half=half)


def main(argv: list[str] | None = None) -> int:
    """Publish IN_FILE; returns 0, 2 with a one-line message for a refused input or an output
    path that cannot be written, 1 for a write that fails at run time."""
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('in_file', help='training checkpoint, e.g. work_dirs/exp2/epoch_12.pth')
    parser.add_argument('out_file', help='output name, e.g. tr3d_exp2.pth')
    parser.add_argument(
        '--half', action='store_true', help='store the floating-point weights in float16')
    args = parser.parse_args(argv)
    try:
        check_output_file(args.out_file)
        final = publish(args.in_file, args.out_file, args.half)
    except ValueError as error:  # CheckpointError, OutputRefused
        print(f'publish_model.py: error: {error}', file=sys.stderr)
        return 2
    except OutputFailed as error:
        print(f'publish_model.py: error: {error}', file=sys.stderr)
        return 1
    except (OSError, RuntimeError) as error:  # torch.save reports some write errors as these
        reason = error.strerror if isinstance(error, OSError) and error.strerror else error
        print(f'publish_model.py: error: {args.out_file}: cannot write ({reason})',
              file=sys.stderr)
        return 1
    print(f'published {final}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
