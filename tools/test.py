"""Evaluate a checkpoint with mmengine's Runner and print the paper's Table 3.

Usage: python tools/test.py CONFIG CHECKPOINT [--work-dir DIR] [--out JSON] [--cfg-options k=v ...]
                            [--launcher {none,pytorch,slurm,mpi}]

The numbers are mmdet3d's IndoorMetric (per-class average precision at 3D IoU 0.25 and 0.5 and
their mean over the evaluated classes). The table has a row per IoU threshold and a column per
class plus the mean; a class the test set neither contains nor predicts is shown as "-" (null
in the JSON), as in the paper. The JSON (`"format": "synthdet.table3/1"`) goes to
`<work_dir>/table3.json` unless --out is given. The checkpoint is loaded weights-only
(``projects/synthdet/checkpoint.py``): one that holds anything else is refused (exit 2).
"""
import argparse
import json
import os
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))  # the configs' custom_imports load `projects.synthdet`

from mmengine.config import Config, DictAction  # noqa: E402
from mmengine.dist import is_main_process  # noqa: E402
from mmengine.model import is_model_wrapper  # noqa: E402
from mmengine.runner import Runner  # noqa: E402

from projects.synthdet.checkpoint import CheckpointError, load_model_weights  # noqa: E402

TABLE3_FORMAT = 'synthdet.table3/1'
IOU_THRESHOLDS = (0.25, 0.5)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = argparse.ArgumentParser(description='Test a synthdet 3D detector (Table 3).')
    parser.add_argument('config', help='config file, e.g. configs/tr3d/exp2.py')
    parser.add_argument('checkpoint', help='checkpoint file')
    parser.add_argument('--work-dir', help='logs and table3.json (default work_dirs/<config>)')
    parser.add_argument('--out', help='Table 3 JSON path (default <work_dir>/table3.json)')
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=DictAction,
        help='override config keys, e.g. test_dataloader.dataset.ann_file=...')
    parser.add_argument(
        '--launcher',
        choices=['none', 'pytorch', 'slurm', 'mpi'],
        default='none',
        help='job launcher for distributed testing')
    parser.add_argument('--local-rank', '--local_rank', type=int, default=0)
    args = parser.parse_args(argv)
    os.environ.setdefault('LOCAL_RANK', str(args.local_rank))
    return args


def table3(metrics: dict,
           classes: list[str],
           iou_thresholds: tuple[float, ...] = IOU_THRESHOLDS) -> dict[str, dict]:
    """Arrange IndoorMetric results as Table 3: ``{'mAP@0.25': {class: AP, ..., 'mean': mAP}}``.

    A class without an ``<class>_AP_<thr>`` entry (neither in the ground truth nor predicted)
    gets ``None``. Raises ``KeyError`` if the metrics lack the mean for a threshold.
    """
    rows = {}
    for thr in iou_thresholds:
        key = f'{thr:.2f}'
        if f'mAP_{key}' not in metrics:
            raise KeyError(f'IndoorMetric results have no mAP_{key}: {sorted(metrics)}')
        row = {name: metrics.get(f'{name}_AP_{key}') for name in classes}
        row['mean'] = metrics[f'mAP_{key}']
        rows[f'mAP@{thr:g}'] = {k: None if v is None else float(v) for k, v in row.items()}
    return rows


def format_table3(rows: dict[str, dict]) -> str:
    """Render Table 3 rows as aligned text, '-' for missing classes."""
    columns = list(next(iter(rows.values())))
    width = max(9, *(len(c) + 1 for c in columns))
    lines = ['metric'.ljust(10) + ''.join(c.rjust(width) for c in columns)]
    for name, row in rows.items():
        cells = ('-' if row[c] is None else f'{row[c]:.3f}' for c in columns)
        lines.append(name.ljust(10) + ''.join(cell.rjust(width) for cell in cells))
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> dict:
    """Run the test loop, print Table 3 and write its JSON; returns the JSON document."""
    args = parse_args(argv)
    cfg = Config.fromfile(args.config)
    cfg.launcher = args.launcher
    if args.cfg_options:
        cfg.merge_from_dict(args.cfg_options)
    if args.work_dir:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir') is None:
        cfg.work_dir = str(Path('work_dirs') / Path(args.config).stem)
    cfg.load_from = None  # the weights come from the weights-only load below

    runner = Runner.from_cfg(cfg)
    model = runner.model.module if is_model_wrapper(runner.model) else runner.model
    load_model_weights(model, args.checkpoint)
    metrics = runner.test()
    classes = list(runner.test_dataloader.dataset.metainfo['classes'])
    rows = table3(metrics, classes)
    document = {
        'format': TABLE3_FORMAT,
        'config': str(args.config),
        'checkpoint': str(args.checkpoint),
        'test_set': str(cfg.test_dataloader.dataset.get('ann_file', '')),
        'classes': classes,
        'rows': rows,
        'metrics': {
            k: float(v)
            for k, v in metrics.items()
        },
    }
    if is_main_process():
        out = Path(args.out) if args.out else Path(cfg.work_dir) / 'table3.json'
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(document, indent=2) + '\n')
        print(f'Table 3 ({Path(args.config).stem}, {document["test_set"]}):')
        print(format_table3(rows))
        print(f'written to {out}')
    return document


if __name__ == '__main__':
    try:
        main()
    except CheckpointError as error:
        print(f'test.py: error: {error}', file=sys.stderr)
        sys.exit(2)
