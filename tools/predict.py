"""Detect objects in scans and write one ``<scan>.pred.json`` per scan.

Usage: python tools/predict.py CONFIG CHECKPOINT POINTS... --out DIR [--score-thr 0.3]
                               [--device cpu|cuda:0] [--seed 0] [--cfg-options k=v ...]

POINTS are ``.bin`` (float32 N x 6), S3DIS ``.txt`` or ``.ply`` scans (x y z r g b, colours
0-255), read with ``synthdet.scan_io.read_scan``. The scan is shifted so that its minimum
is at the origin, like the converted training data, and passed through the config's test
pipeline with mmdet3d's inference API; the detections are shifted back, so they are in the
input scan's own frame (``"format": "synthdet.predictions/1"``, see docs/training.md).

Every scan is read and checked before the model is loaded; the checkpoint is loaded weights-only
(``projects/synthdet/checkpoint.py``). Bad scans, refused checkpoints and clashing outputs end
with one line naming the file and exit code 2.
"""
import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's `projects`

import torch  # noqa: E402
from mmdet3d.apis import inference_detector, init_model  # noqa: E402
from mmengine.runner import set_random_seed  # noqa: E402

from projects.synthdet.bootstrap import add_cfg_options, load_config  # noqa: E402
from projects.synthdet.checkpoint import CheckpointError, load_model_weights  # noqa: E402
from synthdet.contracts import PREDICTIONS_FORMAT, write_predictions  # noqa: E402
from synthdet.scan_io import ScanFormatError, read_scan  # noqa: E402


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description='Detect objects in scans with a checkpoint.')
    parser.add_argument('config', help='config file, e.g. configs/tr3d/exp2.py')
    parser.add_argument('checkpoint', help='checkpoint file')
    parser.add_argument('points', nargs='+', help='scans: .bin (float32 N x 6), .txt or .ply')
    parser.add_argument('--out', required=True, help='output directory for <scan>.pred.json')
    parser.add_argument(
        '--score-thr',
        type=float,
        default=0.3,
        help='keep detections with at least this score (default 0.3)')
    parser.add_argument('--device', default='cuda:0' if torch.cuda.is_available() else 'cpu')
    parser.add_argument('--seed', type=int, default=0, help='seed of the point sampling')
    add_cfg_options(parser)
    return parser.parse_args(argv)


def output_path(scan: Path, out_dir: Path) -> Path:
    """``<out_dir>/<scan stem>.pred.json``."""
    return out_dir / f'{scan.stem}.pred.json'


def detect(model: torch.nn.Module, points: np.ndarray, score_thr: float, seed: int) -> list[dict]:
    """Run the model on an ``(N, 6)`` scan (colours 0-255); detections in the scan's frame."""
    shift = points[:, :3].min(axis=0)
    shifted = points.astype(np.float32)
    shifted[:, :3] = points[:, :3] - shift
    set_random_seed(seed)
    result, _ = inference_detector(model, shifted)
    pred = result.pred_instances_3d
    keep = pred.scores_3d >= score_thr
    boxes = pred.bboxes_3d[keep]
    centres = boxes.gravity_center.cpu().numpy().astype(np.float64) + shift
    sizes = boxes.dims.cpu().numpy().astype(np.float64)
    yaws = boxes.yaw.cpu().numpy().astype(np.float64)
    scores = pred.scores_3d[keep].cpu().numpy()
    labels = pred.labels_3d[keep].cpu().numpy()
    classes = model.dataset_meta['classes']
    if not all(np.isfinite(a).all() for a in (centres, sizes, yaws, scores)):
        raise ValueError('the model returned non-finite boxes or scores')
    order = np.argsort(-scores, kind='stable')
    return [{
        'class': classes[labels[i]],
        'score': round(float(scores[i]), 6),
        'center': [round(float(v), 6) for v in centres[i]],
        'size': [round(float(v), 6) for v in sizes[i]],
        'yaw': round(float(yaws[i]), 6),
    } for i in order]


class BadInput(ValueError):
    """A scan, checkpoint or argument predict cannot use; the message names the file."""


def check_scans(scans: list[Path], out_dir: Path) -> dict[Path, Path]:
    """Read every scan once (errors name the file) and map each output path to its scan."""
    targets: dict[Path, Path] = {}
    for scan in scans:
        target = output_path(scan, out_dir)
        if target in targets:
            raise BadInput(f'{scan} and {targets[target]} would both be written to {target}; '
                           'predict them into different --out directories')
        try:
            read_scan(scan)
        except (ScanFormatError, OSError) as error:
            raise BadInput(str(error)) from None
        targets[target] = scan
    return targets


def load_model(cfg, checkpoint: str, device: str) -> torch.nn.Module:
    """Build the config's model and load the checkpoint's weights weights-only."""
    model = init_model(cfg, None, device=device)
    try:
        meta = load_model_weights(model, checkpoint)
    except CheckpointError as error:
        raise BadInput(str(error)) from None
    if not isinstance(meta.get('dataset_meta'), dict) or 'classes' not in meta['dataset_meta']:
        raise BadInput(f'{checkpoint}: the checkpoint\'s meta names no classes (dataset_meta)')
    model.dataset_meta = meta['dataset_meta']
    return model


def main(argv: list[str] | None = None) -> list[Path]:
    """Predict every scan and write its JSON; returns the written paths."""
    args = parse_args(argv)
    out_dir = Path(args.out)
    targets = check_scans([Path(p) for p in args.points], out_dir)
    model = load_model(load_config(args.config, args.cfg_options), args.checkpoint, args.device)
    model_name = Path(args.config).stem
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for target, scan in tqdm(targets.items(), desc='predict', unit='scan'):
        try:
            detections = detect(model, read_scan(scan), args.score_thr, args.seed)
        except ValueError as error:
            raise RuntimeError(f'{scan}: {error}') from None
        document = {
            'format': PREDICTIONS_FORMAT,
            'scan': str(scan),
            'model': model_name,
            'classes': list(model.dataset_meta['classes']),
            'detections': detections,
        }
        write_predictions(target, document)
        written.append(target)
    return written


if __name__ == '__main__':
    try:
        main()
    except BadInput as error:
        print(f'predict.py: error: {error}', file=sys.stderr)
        sys.exit(2)
    except (RuntimeError, OSError) as error:
        print(f'predict.py: error: {error}', file=sys.stderr)
        sys.exit(1)
