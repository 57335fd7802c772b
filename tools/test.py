"""Evaluate a checkpoint with mmengine's Runner and print the paper's Table 3.

Usage: python tools/test.py CONFIG CHECKPOINT [--work-dir DIR] [--out JSON] [--cfg-options k=v ...]
                            [--show-dir DIR [--score-thr T]] [--sensor MODEL]
                            [--box-fit] [--false-positives] [--tta]
                            [--launcher {none,pytorch,slurm,mpi}]

The numbers are mmdet3d's IndoorMetric (per-class average precision at 3D IoU 0.25 and 0.5 and
their mean over the evaluated classes). The table has a row per IoU threshold and a column per
class plus the mean; a class without ground truth in the test set is shown as "-" (null in
the JSON) and left out of the mean, as in the paper (``projects/synthdet/evaluation/``). The
JSON (``"format": "synthdet.table3/1"``) goes to ``<work_dir>/table3.json`` unless --out is given,
the text next to it (``table3.txt``). ``--show-dir`` saves a top-view picture of every test scan
with its ground truth and the predictions scoring at least ``--score-thr``
(``projects/synthdet/visualization.py``); the threshold affects the pictures only, as in
mmdet3d's test tool. ``--sensor`` tests only the generated rooms that one of the generator's
sensor models scanned (their ``meta.json``), for a table per sensor. The checkpoint is loaded
weights-only (``projects/synthdet/checkpoint.py``): one that holds anything else is refused, as
is a ``--sensor`` whose rooms cannot be found (exit 2). The config, ``--out``, ``--show-dir``,
the test split's info pickle (read as plain data) and the checkpoint are checked, in that
order, before the model is built (one line naming the file, exit 2). ``--box-fit`` adds a
table of how well
the predicted boxes fit the true ones per class (median best IoU, the share below IoU 0.25 and
0.5, size ratios per axis and centre distance; ``projects/synthdet/evaluation/box_fit.py``),
printed and written to ``box_fit.json`` / ``box_fit.txt`` next to Table 3.
``--tta`` tests the config's ``tta_pipeline`` (every scene flipped four ways, two point samples
each) with its ``tta_model`` around the model, which fuses the passes per class
(``projects/synthdet/models/tta.py``); the config must have both (exit 2 otherwise).
``--false-positives`` adds, per class and IoU threshold, what the false positives hit (a
duplicate, another class, a loose box, or the annotation of the scan's points inside them, e.g.
``clutter/crate``) with the AP the class would have without each cause
(``projects/synthdet/evaluation/false_positives.py``), in ``false_positives.json`` / ``.txt``.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from projects.synthdet.bootstrap import (ConfigFileError, ErrorTypes, TTAConfigError,
                                         parse_runner_args, run_tool, runner_config, tta_settings)
from synthdet.cli import OneLineParser, add_score_option
from synthdet.contracts import SENSOR_MODELS
from synthdet.info_files import InfoFileError, load_info_pickle, rooms_scanned_by
from synthdet.outputs import OutputRefused, check_output_dir, check_output_file

if TYPE_CHECKING:
    from mmengine.config import Config


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = OneLineParser(description='Test a synthdet 3D detector (Table 3).')
    parser.add_argument('config', help='config file, e.g. configs/tr3d/exp2.py')
    parser.add_argument('checkpoint', help='checkpoint file')
    parser.add_argument('--out', help='Table 3 JSON path (default <work_dir>/table3.json)')
    parser.add_argument(
        '--show-dir', help='save a top-view picture of every test scan (truth and predictions)')
    add_score_option(parser, '--score-thr', 0.1,
                     'lowest score of the predictions drawn with --show-dir')
    parser.add_argument(
        '--sensor',
        choices=SENSOR_MODELS,
        help='test only the generated rooms this generator sensor scanned (meta.json)')
    parser.add_argument(
        '--box-fit',
        action='store_true',
        help='also tabulate how well the predicted boxes fit the true ones (box_fit.json)')
    parser.add_argument(
        '--tta',
        action='store_true',
        help="test-time augmentation: the config's tta_pipeline and tta_model (flips and "
        'point samples, fused)')
    parser.add_argument(
        '--false-positives',
        action='store_true',
        help='also tabulate what the false positives hit, per class (false_positives.json)')
    return parse_runner_args(parser, 'logs and table3.json (default work_dirs/<config>)', argv)


def add_show_hook(cfg: Config, show_dir: str | None, score_thr: float) -> None:
    """With ``show_dir``, add the hook that draws every test scan (``TopViewHook``)."""
    if show_dir:
        from projects.synthdet.visualization import TopViewHook
        cfg.custom_hooks = [
            *cfg.get('custom_hooks', []),
            dict(type=TopViewHook.__name__, out_dir=show_dir, score_thr=score_thr)
        ]


def add_metric(cfg: Config, metric: type) -> None:
    """Evaluate the test with ``metric`` (a registered metric class) as well."""
    evaluators = cfg.test_evaluator
    evaluators = list(evaluators) if isinstance(evaluators, (list, tuple)) else [evaluators]
    cfg.test_evaluator = [*evaluators, dict(type=metric.__name__)]


def use_test_time_augmentation(cfg: Config) -> None:
    """Test with the config's ``tta_pipeline`` and its ``tta_model`` wrapped around the
    ``model``, as mmdet3d's test tool does; ``TTAConfigError`` if the config lacks one."""
    tta_model, tta_pipeline = tta_settings(cfg)
    cfg.test_dataloader.dataset.pipeline = tta_pipeline
    cfg.model = dict(tta_model, module=cfg.model)


def select_sensor(cfg: Config, sensor: str | None) -> str:
    """With ``sensor``, keep only the test rooms that sensor scanned (mmengine's dataset
    ``indices``); returns the test set's name for the table."""
    dataset = cfg.test_dataloader.dataset
    name = str(dataset.get('ann_file', ''))
    if sensor:
        info_file = Path(dataset.get('data_root', '')) / name
        dataset.indices = rooms_scanned_by(info_file, sensor)
        if not dataset.indices:
            raise InfoFileError(f'{info_file}: no room scanned by the {sensor} sensor')
        name += f' ({sensor} rooms)'
    return name


def info_files(dataset: dict) -> list[Path]:
    """The info pickles a dataset config reads: its ``data_root`` joined with its ``ann_file``,
    and those of the datasets it wraps (``dataset``, ``datasets``)."""
    files = []
    if dataset.get('ann_file'):
        files.append(Path(dataset.get('data_root') or '') / str(dataset['ann_file']))
    wrapped = [dataset.get('dataset')] + list(dataset.get('datasets') or [])
    for inner in wrapped:
        if isinstance(inner, dict):
            files.extend(info_files(inner))
    return files


def check_test_data(cfg: Config) -> None:
    """Read the test split's info pickles (plain data only, ``InfoFileError`` naming a missing
    or broken one), so that they are found wrong before the checkpoint and the model load."""
    for info_file in info_files(cfg.test_dataloader.dataset):
        load_info_pickle(info_file)


def report(path: Path, document: dict, title: str, table: str) -> None:
    """Print a table under its title; write its document to ``path`` and the text beside it."""
    from projects.synthdet.evaluation.table_files import write_table
    text = f'{title}:\n{table}'
    print(text)
    print(f'written to {path} and {write_table(path, document, text)}')


def main(argv: list[str] | None = None) -> dict:
    """Run the test loop, print Table 3 and write it; returns the JSON document."""
    args = parse_args(argv)  # bad options end here, before torch and mmengine are loaded
    from mmengine.dist import is_main_process
    from mmengine.model import BaseTTAModel, is_model_wrapper
    from mmengine.runner import Runner

    from projects.synthdet.checkpoint import load_checkpoint_file, load_state_into
    from projects.synthdet.evaluation.box_fit import (SynthdetBoxFit, box_fit_document,
                                                      format_box_fit)
    from projects.synthdet.evaluation.false_positives import (
        SynthdetFalsePositives, false_positives_document, format_false_positives)
    from projects.synthdet.evaluation.table3 import format_table3, table3
    cfg = runner_config(args)
    check_output_dir(cfg.work_dir, '--work-dir')  # mmengine writes its logs there
    if args.out:
        check_output_file(args.out, make_parents=True)
    if args.show_dir:
        check_output_dir(args.show_dir, '--show-dir')
    if args.tta:
        use_test_time_augmentation(cfg)
    check_test_data(cfg)
    checkpoint = load_checkpoint_file(args.checkpoint)  # checked before the model is built
    cfg.load_from = None  # the weights come from the weights-only load below
    add_show_hook(cfg, args.show_dir, args.score_thr)
    if args.box_fit:
        add_metric(cfg, SynthdetBoxFit)
    if args.false_positives:
        add_metric(cfg, SynthdetFalsePositives)
    test_set = select_sensor(cfg, args.sensor)
    runner = Runner.from_cfg(cfg)
    model = runner.model.module if is_model_wrapper(runner.model) else runner.model
    load_state_into(model.module if isinstance(model, BaseTTAModel) else model, checkpoint,
                    args.checkpoint)
    del checkpoint
    metrics = runner.test()
    classes = list(runner.test_dataloader.dataset.metainfo['classes'])
    document = table3(metrics, classes, str(args.config), str(args.checkpoint), test_set)
    if is_main_process():
        out = Path(args.out) if args.out else Path(cfg.work_dir) / 'table3.json'
        stem = Path(args.config).stem
        report(out, document, f'Table 3 ({stem}, {document["test_set"]})', format_table3(document))
        if args.box_fit:
            fit = box_fit_document(metrics, classes, str(args.config), str(args.checkpoint),
                                   test_set)
            report(
                out.with_name('box_fit.json'), fit,
                f'Box fit ({stem}, {test_set}; best IoU of each true box, size ratios '
                f'prediction / truth, centre distance in m)', format_box_fit(fit))
        if args.false_positives:
            fps = false_positives_document(metrics, classes, str(args.config),
                                           str(args.checkpoint), test_set)
            report(
                out.with_name('false_positives.json'), fps,
                f'False positives ({stem}, {test_set}; per class and IoU threshold the AP, then '
                f'the causes that cost most: cause, count -> AP without them)',
                format_false_positives(fps))
    return document


def bad_inputs() -> ErrorTypes:
    """The errors that are bad input (exit 2), imported only when the test fails."""
    from projects.synthdet.checkpoint import CheckpointError
    return (CheckpointError, ConfigFileError, InfoFileError, OutputRefused, TTAConfigError)


if __name__ == '__main__':
    run_tool(main, 'test.py', bad_input=bad_inputs)
