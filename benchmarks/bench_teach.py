"""Teach synthdet a factory, measured: documents of real rooms corrected in FreeCAD as a user
would, a fine-tune on them, and the model before and after on held-out rooms and generated area 9
(docs/teach.md "Measured").

Usage: python benchmarks/bench_teach.py SCANS_DIR --train ROOM [ROOM ...]
           --config configs/tr3d/exp2_cpu.py --checkpoint CKPT --data GENERATED_ROOT
           --data-root DATA_ROOT --work WORK [--finetune-config configs/tr3d/teach_finetune.py]
           [--iters N] [--score-thr 0.3] [--busy-file FILE] [--freecadcmd freecadcmd]
           [--fork-tools]

SCANS_DIR holds labelled scans (``X.<suffix>`` with ``X.labels.json`` beside it); ``--train``
names the training rooms by their stem, every other labelled scan is held out. GENERATED_ROOT
holds the generated areas' info pickles and ``.bin`` files (read only); they are linked, file by
file, into DATA_ROOT, which also receives the user rooms' area 10.

1. ``tools/scan2cad.py`` on each training room (the synthetic model) -> ``WORK/documents``;
2. each document corrected in ``freecadcmd`` (the runner of ``python -m configurator``) like a
   user in the property editor: its parts greedily matched to the true boxes (per class by
   IoU, the real-scan evaluation's rule), the unmatched ones and the alternatives not switched
   in deleted, each matched part moved, turned and resized (placement, parameter sheet) onto
   its box, each missed object added with ``editing.add_part`` (the macro's "Add synthdet
   object"), the document marked reviewed and saved. True boxes that overlap (a chair under a
   table) stay as they are: ``labels`` accepts them;
3. ``python -m configurator labels`` on each corrected document (labels and an S3DIS room of
   area 10, checked against the boxes the correction aimed at), ``tools/create_data.py``;
4. ``tools/train.py`` with the fine-tune config from the checkpoint, its wall time measured
   (``--iters N``: N iterations instead of the config's epochs, without validation); a
   finished fine-tune in WORK is reused;
5. the model before and after: ``tools/eval_scans.py``'s library on the held-out rooms and
   ``tools/test.py`` on generated area 9.

Prints a table and ends with the line ``teach: held-out recall A -> B at IoU 0.25, false
positives per room C -> D, area 9 mAP@0.25 E -> F (N training rooms, M held-out rooms,
fine-tune T min)``; all figures go to ``WORK/teach.json``. Exit code 2 for bad input, 1 for a
step that fails (one line naming it). ``--fork-tools`` runs the Python tools forked from one
process that imported the stack once (``benchmarks/tool_runs.py``): the same steps without a
start-up per tool, for the benchmark's smoke run.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from benchmarks.tool_runs import add_fork_tools_option, start_tool
from configurator.freecad_cli import run_freecad_process
from configurator.labels import read_document
from projects.synthdet.config_helpers import area_info_file
from projects.synthdet.evaluation.real_scans import (
    IOU_THR, LabelledScan, assign_greedy, box_array, find_labelled_scans, format_result)
from synthdet.contracts import read_labels
from synthdet.geometry import box_corners_xy
from synthdet.info_files import RAW_DIR
from synthdet.processes import work_folder
from synthdet.cli import OneLineParser

REPO = Path(__file__).resolve().parents[1]

USER_AREA = 10  # the area teach_finetune.py trains the user's rooms as
TEST_AREA = 9
LINKED_FOLDERS = ('points', 'instance_mask', 'semantic_mask')
FREECAD_DIR = REPO / 'configurator' / 'freecad'
CORRECTION_SCRIPT = REPO / 'benchmarks' / 'teach_correction.py'  # runs in freecadcmd
LABELS_TOLERANCE = 0.002  # metres: the labels round to the millimetre
GOAL_RECALL_GAIN = 0.2
GOAL_MAP_DROP = 0.02


class StepFailed(RuntimeError):
    """A step of the benchmark failed (exit code 1)."""


# --------------------------------------------------------------------------- the correction


def assign_parts(parts: list[dict], truth: list[dict]) -> dict[int, int]:
    """Which true box each part takes: per class, parts in document order, each the unmatched
    true box of its class it overlaps most, at 3D IoU >= ``IOU_THR`` (the evaluation's rule)."""
    taken: dict[int, int] = {}
    for name in dict.fromkeys(box['class'] for box in parts):
        mine = [i for i, box in enumerate(parts) if box['class'] == name]
        theirs = [j for j, box in enumerate(truth) if box['class'] == name]
        assigned = assign_greedy(box_array([truth[j] for j in theirs]),
                                 box_array([parts[i] for i in mine]))
        taken.update((part, theirs[j]) for part, j in zip(mine, assigned) if j >= 0)
    return taken


def correction_plan(parts: list[dict], truth: list[dict]) -> dict:
    """What a user changes: the parts to keep and their target boxes (every other part is
    deleted), and the true boxes to add."""
    taken = assign_parts(parts, truth)
    boxes = [{key: box[key] for key in ('class', 'center', 'size', 'yaw')} for box in truth]
    return {
        'edit': [{
            'name': parts[i]['name'],
            'box': boxes[j]
        } for i, j in taken.items()],
        'add': [box for j, box in enumerate(boxes) if j not in taken.values()],
    }


def correct_document(document: Path,
                     plan: dict,
                     out: Path,
                     freecadcmd: str,
                     timeout: float = 600.0) -> dict:
    """Apply ``plan`` to ``document`` in ``freecadcmd`` and save the result as ``out``."""
    with work_folder('synthdet-teach') as work:
        plan_path, result = work / 'plan.json', work / 'result.json'
        plan_path.write_text(
            json.dumps(
                dict(
                    plan,
                    document=str(document.resolve()),
                    out=str(out.resolve()),
                    freecad_dir=str(FREECAD_DIR),
                    repo=str(REPO))),
            encoding='utf-8')
        env = dict(os.environ, SYNTHDET_CORRECTION=str(plan_path), SYNTHDET_RESULT=str(result))
        report = run_freecad_process([freecadcmd, str(CORRECTION_SCRIPT)], env, work, timeout,
                                     result)
    if report.get('status') != 'ok' or report['invalid']:
        raise StepFailed(f'{document}: the correction failed in FreeCAD: '
                         f'{report.get("error") or report["invalid"]}')
    return report


def labels_deviation(written: list[dict], aimed: list[dict]) -> float:
    """How far the written labels are from the boxes the correction aimed at: the largest
    difference (metres) of a corner of an aimed box's footprint, its bottom or its top from the
    written box of its class nearest to it; infinite when the counts differ."""
    if len(written) != len(aimed):
        return math.inf
    worst = 0.0
    for box in aimed:
        same = [b for b in written if b['class'] == box['class']]
        if not same:
            return math.inf
        worst = max(worst, min(_box_difference(box, other) for other in same))
    return worst


def _box_difference(first: dict, second: dict) -> float:
    """The largest distance between matching footprint corners (a box turned by a half turn
    is the same box), bottoms and tops of two boxes."""
    a = box_corners_xy(first['center'], first['size'], first['yaw'])
    b = box_corners_xy(second['center'], second['size'], second['yaw'])
    corners = min(np.abs(a - np.roll(b, shift, axis=0)).max() for shift in (0, 2))
    heights = [
        abs((first['center'][2] + sign * first['size'][2] / 2.0) -
            (second['center'][2] + sign * second['size'][2] / 2.0)) for sign in (-1, 1)
    ]
    return float(max(corners, *heights))


# --------------------------------------------------------------------------- the steps


def run_step(what: str, command: list[str], log: Path, forked: bool = False) -> float:
    """Run ``python <command>`` from the repository root, its output into ``log``; ``forked``:
    forked from one process that imported the stack (``benchmarks/tool_runs.py``). Returns
    the CPU seconds (user and system) of the step's processes."""
    env = dict(os.environ, OMP_NUM_THREADS=os.environ.get('OMP_NUM_THREADS', '1'))
    log.parent.mkdir(parents=True, exist_ok=True)
    log.write_bytes(b'')
    cpu_start = _children_cpu_seconds()
    process = start_tool(command, log, env=env, forked=forked)
    code = process.wait()
    if code != 0:
        tail = log.read_text(encoding='utf-8', errors='replace').strip().splitlines()[-1:]
        raise StepFailed(f'{what} failed (exit {code}, {log}): {" ".join(tail)}')
    return process.cpu_seconds if forked else _children_cpu_seconds() - cpu_start


def room_name(scan: Path) -> str:
    """The S3DIS room a scan becomes (``labels``' default: its stem's letters and digits)."""
    return ''.join(c for c in scan.stem if c.isalnum()) + '_1'


def link_generated_areas(source: Path, target: Path, areas: list[int]) -> None:
    """Link the areas' info pickles and ``.bin`` files of ``source`` into ``target``, file by
    file (the converter then writes the user area beside them, never into ``source``)."""
    if source.resolve() == target.resolve():
        raise ValueError(f'{target}: the data root must not be the generated data\'s folder')
    target.mkdir(parents=True, exist_ok=True)
    pairs = []
    for area in areas:
        info = source / area_info_file(area)
        if not info.is_file():
            raise ValueError(f'{info}: info pickle not found')
        pairs.append((info, target / info.name))
        for folder in LINKED_FOLDERS:
            (target / folder).mkdir(exist_ok=True)
            pairs += [(path, target / folder / path.name)
                      for path in sorted((source / folder).glob(f'Area_{area}_*'))]
    for path, link in pairs:
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(path.resolve())


def data_root_options(config: Path, data_root: Path) -> list[str]:
    """``--cfg-options`` pointing every dataset of ``config`` at ``data_root``."""
    from mmengine.config import Config
    cfg = Config.fromfile(str(config), import_custom_modules=False)
    root = f'{data_root.resolve()}/'
    options = [
        f'train_dataloader.dataset.dataset.datasets.{i}.data_root={root}'
        for i in range(len(cfg.train_dataloader.dataset.dataset.datasets))
    ]
    return options + [
        f'{loader}.dataset.data_root={root}' for loader in ('val_dataloader', 'test_dataloader')
    ]


def iteration_options(iters: int) -> list[str]:
    """``--cfg-options`` training ``iters`` iterations (one checkpoint at the end, no
    validation) instead of the config's epochs."""
    return [
        'train_cfg._delete_=True', 'train_cfg.type=IterBasedTrainLoop',
        f'train_cfg.max_iters={iters}', 'default_hooks.checkpoint.by_epoch=False',
        f'default_hooks.checkpoint.interval={iters}', 'val_cfg=None', 'val_dataloader=None',
        'val_evaluator=None'
    ]


def fine_tune(args: argparse.Namespace, options: list[str]) -> dict:
    """Train (or reuse a finished fine-tune in WORK): its ``checkpoint``, wall ``seconds``,
    ``cpu_seconds`` (None when not measured) and whether it was ``reused``."""
    work = args.work / 'finetune'
    record = work / 'wall_time.json'
    if record.is_file():
        done = json.loads(record.read_text())
        if Path(done['checkpoint']).is_file():
            return {'cpu_seconds': None, **done, 'reused': True}
    command = [
        'tools/train.py',
        str(args.finetune_config), '--work-dir',
        str(work), '--cfg-options', f'load_from={args.checkpoint.resolve()}', *options
    ]
    if args.iters:  # no validation: its loader's options go
        command = [item for item in command if not item.startswith('val_dataloader.')]
        command += iteration_options(args.iters)
    if args.busy_file:
        args.busy_file.write_text(f'fine-tune in {work} since {time.ctime()}\n')
    start = time.perf_counter()
    try:
        cpu_seconds = run_step('the fine-tune (tools/train.py)', command,
                               args.work / 'logs' / 'train.log', args.fork_tools)
    finally:
        if args.busy_file:
            args.busy_file.unlink(missing_ok=True)
    seconds = time.perf_counter() - start
    done = {
        'checkpoint': (work / 'last_checkpoint').read_text().strip(),
        'seconds': seconds,
        'cpu_seconds': cpu_seconds
    }
    record.write_text(json.dumps(done))
    return {**done, 'reused': False}


def _children_cpu_seconds() -> float:
    """User and system CPU seconds of the ended child processes (and theirs): on a shared
    machine the fine-tune's wall time grows with the other jobs, its CPU time much less."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def evaluate_held_out(config: Path, checkpoint: Path, scans: list[LabelledScan], out: Path,
                      score_thr: float) -> dict:
    """``tools/eval_scans.py``'s evaluation of ``checkpoint`` on the held-out scans."""
    from projects.synthdet.bootstrap import load_config
    from projects.synthdet.evaluation.real_scans import evaluate_scans
    cfg = load_config(config)
    result = evaluate_scans(
        cfg, checkpoint, scans, out, score_thr=score_thr, report=lambda line: None)
    (out / 'summary.txt').write_text(format_result(result) + '\n')
    return result


def test_area(config: Path,
              checkpoint: Path,
              options: list[str],
              work: Path,
              forked: bool = False) -> dict:
    """``tools/test.py`` on generated area 9 (``forked``: see :func:`run_step`): its Table 3
    rows."""
    table = work / 'table3.json'
    run_step(f'tools/test.py of {checkpoint.name}', [
        'tools/test.py',
        str(config),
        str(checkpoint), '--work-dir',
        str(work), '--out',
        str(table), '--cfg-options', f'test_dataloader.dataset.ann_file='
        f'{area_info_file(TEST_AREA)}', *options
    ], work / 'test.log', forked)
    return json.loads(table.read_text())['rows']


def measure_model(config: Path, checkpoint: Path, scans: list[LabelledScan], data_root: Path,
                  eval_dir: Path, area_dir: Path, score_thr: float, forked: bool) -> dict:
    """A model on the labelled ``scans`` (figures and pictures in ``eval_dir``) and on
    generated area 9 of ``data_root`` (``area_dir``): ``held_out`` and ``area9``."""
    held = evaluate_held_out(config, checkpoint, scans, eval_dir, score_thr)
    rows = test_area(config, checkpoint, data_root_options(config, data_root), area_dir, forked)
    return {'held_out': held, 'area9': rows}


# --------------------------------------------------------------------------- the report


def _figure(value: float | None, digits: int = 3) -> str:
    return '-' if value is None else f'{value:.{digits}f}'


def goals(results: dict) -> dict:
    """Whether each goal is met: held-out recall up >= 0.2, false positives per room not above
    the synthetic model's, area 9 mAP@0.25 down <= 0.02."""
    before, after = results['before'], results['after']
    gain = (after['held_out']['overall_recall'] or 0.0) - (
        before['held_out']['overall_recall'] or 0.0)
    drop = before['area9']['mAP@0.25']['mean'] - after['area9']['mAP@0.25']['mean']
    return {
        'recall_gain':
        gain,
        'recall_goal_met':
        gain >= GOAL_RECALL_GAIN - 1e-9,
        'false_positive_goal_met': (after['held_out']['false_positives_per_room']
                                    <= before['held_out']['false_positives_per_room']),
        'area9_drop':
        drop,
        'area9_goal_met':
        drop <= GOAL_MAP_DROP + 1e-9,
    }


def report(results: dict) -> str:
    """The table (held-out recall per class and false positives per room, area 9 AP@0.25 per
    class) and the headline as the last line."""
    before, after = results['before'], results['after']
    classes = before['held_out']['classes']
    lines = [
        f'held-out rooms ({", ".join(results["held_out"])}): recall at IoU '
        f'{IOU_THR:g} per class (found/true), false positives per room'
    ]
    lines.append('model'.ljust(8) + ''.join(c.rjust(14) for c in classes) + 'all'.rjust(8) +
                 'FP/room'.rjust(9))
    for name, figures in (('before', before), ('after', after)):
        held = figures['held_out']
        cells = []
        for c in classes:
            total = held['total'][c]
            cells.append('-' if not total or not total['truth'] else
                         f'{held["recall"][c]:.2f} {total["found"]}/{total["truth"]}')
        lines.append(
            name.ljust(8) + ''.join(cell.rjust(14)
                                    for cell in cells) + _figure(held['overall_recall']).rjust(8) +
            _figure(held['false_positives_per_room'], 2).rjust(9))
    area_classes = [c for c in before['area9']['mAP@0.25'] if c != 'mean']
    lines += [
        '', f'generated area {TEST_AREA}: AP@0.25 per class (tools/test.py)',
        'model'.ljust(8) + ''.join(c.rjust(11) for c in area_classes) + 'mAP'.rjust(8)
    ]
    for name, figures in (('before', before), ('after', after)):
        row = figures['area9']['mAP@0.25']
        lines.append(
            name.ljust(8) + ''.join(_figure(row[c]).rjust(11)
                                    for c in area_classes) + _figure(row['mean']).rjust(8))
    cpu = results.get('fine_tune_cpu_seconds')
    lines += [
        '', f'fine-tune: {results["fine_tune_seconds"] / 60.0:.1f} min wall'
        f'{"" if cpu is None else f", {cpu / 60.0:.1f} min CPU (all its processes)"}'
    ]
    changes = []
    for c in classes:
        first, last = before['held_out']['recall'][c], after['held_out']['recall'][c]
        if first is not None and last is not None:
            changes.append(f'{c} {last - first:+.2f}')
    lines.append('held-out recall change per class: ' + (', '.join(changes) or 'none'))
    lines.append(f'area {TEST_AREA} AP@0.25 change per class: ' + ', '.join(
        f'{c} {after["area9"]["mAP@0.25"][c] - before["area9"]["mAP@0.25"][c]:+.3f}'
        for c in area_classes if before['area9']['mAP@0.25'][c] is not None
        and after['area9']['mAP@0.25'][c] is not None))
    met = results['goals']
    lines += [
        '', f'goals: held-out recall {met["recall_gain"]:+.3f} (up >= {GOAL_RECALL_GAIN}: '
        f'{"met" if met["recall_goal_met"] else "not met"}), false positives per room not '
        f'above before: {"met" if met["false_positive_goal_met"] else "not met"}, area '
        f'{TEST_AREA} mAP@0.25 {-met["area9_drop"]:+.3f} (down <= {GOAL_MAP_DROP}: '
        f'{"met" if met["area9_goal_met"] else "not met"})'
    ]
    lines.append(
        f'teach: held-out recall {_figure(before["held_out"]["overall_recall"])} -> '
        f'{_figure(after["held_out"]["overall_recall"])} at IoU {IOU_THR:g}, false positives '
        f'per room {_figure(before["held_out"]["false_positives_per_room"], 2)} -> '
        f'{_figure(after["held_out"]["false_positives_per_room"], 2)}, area {TEST_AREA} '
        f'mAP@0.25 {_figure(before["area9"]["mAP@0.25"]["mean"])} -> '
        f'{_figure(after["area9"]["mAP@0.25"]["mean"])} ({len(results["train"])} training '
        f'rooms, {len(results["held_out"])} held-out rooms, fine-tune '
        f'{results["fine_tune_seconds"] / 60.0:.1f} min)')
    return '\n'.join(lines)


# --------------------------------------------------------------------------- main


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('scans', type=Path, help='folder of labelled scans')
    parser.add_argument('--train', nargs='+', required=True, help='training rooms (scan stems)')
    parser.add_argument('--config', type=Path, required=True, help='the synthetic model config')
    parser.add_argument('--checkpoint', type=Path, required=True, help='its checkpoint')
    parser.add_argument(
        '--data',
        type=Path,
        required=True,
        help='generated data root with areas 7, 8, 9 (read only)')
    parser.add_argument(
        '--data-root',
        type=Path,
        required=True,
        help='data root of this run: links to --data and the user area')
    parser.add_argument('--work', type=Path, required=True, help='output folder')
    parser.add_argument(
        '--finetune-config', type=Path, default=REPO / 'configs' / 'tr3d' / 'teach_finetune.py')
    parser.add_argument('--iters', type=int, help='train N iterations instead of the epochs')
    parser.add_argument('--score-thr', type=float, default=0.3)
    parser.add_argument('--busy-file', type=Path, help='a file present while the fine-tune runs')
    parser.add_argument('--freecadcmd', default='freecadcmd')
    add_fork_tools_option(parser)
    return parser.parse_args(argv)


def training_rooms(args: argparse.Namespace) -> tuple[list[LabelledScan], list[LabelledScan]]:
    """The labelled scans split into the training rooms (``--train``) and the held-out rest."""
    scans, _ = find_labelled_scans([args.scans])
    by_stem = {item.scan.stem: item for item in scans}
    missing = [name for name in args.train if name not in by_stem]
    if missing:
        raise ValueError(f'{args.scans}: no labelled scan {", ".join(missing)}')
    held_out = [item for item in scans if item.scan.stem not in args.train]
    if not held_out:
        raise ValueError(f'{args.scans}: no labelled scan is left to hold out')
    return [by_stem[name] for name in args.train], held_out


def make_user_area(args: argparse.Namespace, train: list[LabelledScan]) -> list[dict]:
    """Steps 1-3 for every training room; what each correction did."""
    documents, raw = args.work / 'documents', args.work / 'rooms' / RAW_DIR
    documents.mkdir(parents=True, exist_ok=True)
    done = []
    for item in train:
        stem = item.scan.stem
        document, corrected = documents / f'{stem}.FCStd', documents / f'{stem}.corrected.FCStd'
        run_step(f'scan2cad of {item.scan.name}', [
            'tools/scan2cad.py',
            str(item.scan), '--config',
            str(args.config), '--checkpoint',
            str(args.checkpoint), '--out',
            str(document), '--score-thr',
            str(args.score_thr), '--freecadcmd', args.freecadcmd
        ], args.work / 'logs' / f'scan2cad_{stem}.log', args.fork_tools)
        parts = read_document(document, args.freecadcmd)['boxes']
        truth = item.labels['boxes']
        plan = correction_plan(parts, truth)
        edited = correct_document(document, plan, corrected, args.freecadcmd)
        run_step(f'labels of {corrected.name}', [
            '-m', 'configurator', 'labels',
            str(corrected), '--scan',
            str(item.scan), '--out',
            str(raw), '--area',
            str(USER_AREA), '--room',
            room_name(item.scan), '--freecadcmd', args.freecadcmd
        ], args.work / 'logs' / f'labels_{stem}.log', args.fork_tools)
        written = read_labels(raw / f'{stem}.labels.json')['boxes']
        deviation = labels_deviation(written, truth)
        if deviation > LABELS_TOLERANCE:
            raise StepFailed(f'{corrected}: its labels differ from the boxes of the correction '
                             f'({1000.0 * deviation:.1f} mm off)')
        print(
            f'[teach] {stem}: {len(parts)} parts (and '
            f'{edited["deleted"] + edited["edited"] - len(parts)} alternatives not switched in), '
            f'{edited["deleted"]} deleted, '
            f'{edited["edited"]} moved/resized, {edited["added"]} added -> {len(written)} '
            f'labels (within {1000.0 * deviation:.1f} mm of the aimed boxes)',
            flush=True)
        done.append({
            'room': stem,
            'parts': len(parts),
            'labels': len(written),
            **{
                key: edited[key]
                for key in ('deleted', 'edited', 'added')
            }
        })
    link_generated_areas(args.data, args.data_root, [7, 8, TEST_AREA])
    run_step('tools/create_data.py', [
        'tools/create_data.py', 's3dis', '--root-path',
        str(raw.parent), '--out-dir',
        str(args.data_root), '--areas',
        str(USER_AREA)
    ], args.work / 'logs' / 'create_data.log', args.fork_tools)
    return done


def run(args: argparse.Namespace) -> dict:
    """Every step; the results document."""
    train, held_out = training_rooms(args)
    args.work.mkdir(parents=True, exist_ok=True)
    corrections = make_user_area(args, train)
    options = data_root_options(args.finetune_config, args.data_root)
    tuned = fine_tune(args, options)
    checkpoint = Path(tuned['checkpoint'])
    print(
        f'[teach] fine-tune: {tuned["seconds"] / 60.0:.1f} min'
        f'{" (reused)" if tuned["reused"] else ""} -> {checkpoint}',
        flush=True)
    results = {
        'train': [item.scan.stem for item in train],
        'held_out': [item.scan.stem for item in held_out],
        'corrections': corrections,
        'fine_tune_seconds': tuned['seconds'],
        'fine_tune_cpu_seconds': tuned['cpu_seconds']
    }
    for name, config, model in (('before', args.config, args.checkpoint),
                                ('after', args.finetune_config, checkpoint)):
        results[name] = measure_model(config, model, held_out, args.data_root,
                                      args.work / 'eval' / name, args.work / 'area9' / name,
                                      args.score_thr, args.fork_tools)
    results['goals'] = goals(results)
    return results


def run_measured(name: str, inputs: list[Path], measure: Callable[[], dict], out: Path,
                 describe: Callable[[dict], str]) -> int:
    """Check that the ``inputs`` exist, ``measure``, write the figures to ``out`` and print
    ``describe(figures)``: exit code 0; 2 for bad input, 1 for a failing step (one line)."""
    try:
        for path in inputs:
            if not path.is_file():
                raise ValueError(f'{path}: file not found')
        results = measure()
    except ValueError as error:  # LabelsError, LabelsInputError, a bad argument
        print(f'{name}: bad input: {error}', file=sys.stderr)
        return 2
    except (RuntimeError, OSError) as error:  # StepFailed, FreecadFailed
        print(f'{name}: failed: {error}', file=sys.stderr)
        return 1
    out.write_text(json.dumps(results, indent=1))
    print(describe(results))
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    return run_measured('bench_teach', [args.config, args.checkpoint, args.finetune_config],
                        lambda: run(args), args.work / 'teach.json', report)


if __name__ == '__main__':
    sys.exit(main())
