"""Teaching and adapting measured on real labelled scans: three protocols side by side with the
model before them (docs/teach.md "Three protocols on real scans").

Usage: python benchmarks/bench_protocols.py SCANS_DIR --config configs/tr3d/exp2_cpu.py
           --checkpoint CKPT --data GENERATED_ROOT --work WORK
           [--protocols next known new unlabelled] [--new-rooms ROOM ...] [--score-thr 0.3]
           [--iters N] [--rounds R] [--refresh N] [--fork-tools]

SCANS_DIR holds labelled scans (``X.<suffix>`` with ``X.labels.json`` beside it) and may hold
unlabelled ones. A scan's room is its stem up to the first ``_`` (``scannet0001_living`` and
``scannet0001_rescan1`` are room ``scannet0001``); a stem holding ``_rescan`` is a rescan.

- ``next`` (the next scan of the same room): ``benchmarks/bench_teach.py`` corrects the first
  scan of every room that has rescans, fine-tunes on them and tests on the rescans;
- ``known`` (the next scan, the model unchanged): each rescan predicted with its room's first
  scan and labels as known objects (``tools/predict.py --known``,
  ``projects/synthdet/inference/known_objects.py``);
- ``new`` (a new room): the same on every scan of ``--new-rooms``, tested on every other
  labelled scan;
- ``unlabelled``: ``tools/adapt.py`` on every scan of the folder without its labels, tested on
  the labelled ones.

Each row: recall at IoU 0.25 per class, false positives per scan, phantom YuMis and 3D printers,
generated area 9 AP@0.25 per class (``tools/test.py``), before and after, and the minutes of
the fine-tune or the adaptation. A finished fine-tune in WORK is reused with its recorded
minutes, and so is a finished adaptation made by the same command. Prints the table and one
summary line per protocol; the figures go to ``WORK/protocols.json``. ``--iters`` (fine-tune
iterations), ``--rounds`` and ``--refresh`` (adaptation) shorten the runs for the smoke test.
Exit code 2 for bad input, 1 for a step that fails.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

from benchmarks import bench_teach
from benchmarks.bench_teach import (StepFailed, data_root_options, measure_model, run_measured,
                                    run_step)
from benchmarks.tool_runs import add_fork_tools_option
from projects.synthdet.evaluation.real_scans import (LabelledScan, evaluate_detections,
                                                     find_labelled_scans, labels_path)
from projects.synthdet.self_training import PSEUDO_LABEL_THR, UNSURE_THR
from synthdet.cli import OneLineParser, add_score_option
from synthdet.contracts import read_predictions
from synthdet.scan_io import SCAN_SUFFIXES

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / 'configs' / 'tr3d'
PROTOCOLS = ('next', 'known', 'new', 'unlabelled')
TITLES = {'next': 'teach, next scan', 'known': 'known objects, next scan',
          'new': 'teach, new room', 'unlabelled': 'adapt, unlabelled'}
REPORTED_CLASSES = ('table', 'chair', 'sofa')
GOAL_AREA9 = 0.9  # every class's AP@0.25 on generated area 9 after adapting
GOAL_MINUTES = 30.0


def room_of(stem: str) -> str:
    """The room a scan shows: its stem up to the first ``_``."""
    return stem.split('_')[0]


def is_rescan(stem: str) -> bool:
    """Whether the scan is a later scan of its room."""
    return '_rescan' in stem


def split(scans: list[LabelledScan], protocol: str,
          new_rooms: list[str]) -> tuple[list[LabelledScan], list[LabelledScan]]:
    """The teaching and the test scans of a teach protocol; ``ValueError`` when either is
    empty."""
    stems = [item.scan.stem for item in scans]
    if protocol == 'next':
        rescanned = {room_of(stem) for stem in stems if is_rescan(stem)}
        train = [item for item in scans
                 if room_of(item.scan.stem) in rescanned and not is_rescan(item.scan.stem)]
        test = [item for item in scans if is_rescan(item.scan.stem)]
    else:
        train = [item for item in scans if room_of(item.scan.stem) in new_rooms]
        test = [item for item in scans if room_of(item.scan.stem) not in new_rooms]
    if not train or not test:
        raise ValueError(f'protocol {protocol}: {len(train)} scans to teach on and {len(test)} '
                         'to test on: each needs one at least')
    return train, test


def linked_scans(folder: Path, scans: list[LabelledScan]) -> Path:
    """A fresh ``folder`` holding links to the scans and their labels files."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    for item in scans:
        for path in (item.scan, labels_path(item.scan)):
            (folder / path.name).symlink_to(path.resolve())
    return folder


def teach(args: argparse.Namespace, protocol: str, scans: list[LabelledScan]) -> dict:
    """One teach protocol through ``benchmarks/bench_teach.py``: its figures before and after
    and the fine-tune's minutes."""
    train, test = split(scans, protocol, args.new_rooms)
    work = args.work / protocol
    command = [
        linked_scans(work / 'scans', train + test), '--train',
        *[item.scan.stem for item in train], '--config', args.config, '--checkpoint',
        args.checkpoint, '--data', args.data, '--data-root', work / 'data', '--work',
        work / 'run', '--finetune-config', args.finetune_config, '--score-thr', args.score_thr
    ]
    if args.iters:
        command += ['--iters', args.iters]
    if args.fork_tools:
        command.append('--fork-tools')
    if bench_teach.main([str(item) for item in command]) != 0:
        raise StepFailed(f'protocol {protocol}: benchmarks/bench_teach.py failed')
    results = json.loads((work / 'run' / 'teach.json').read_text(encoding='utf-8'))
    return {
        'train': results['train'],
        'test': results['held_out'],
        'before': results['before'],
        'after': results['after'],
        'minutes': results['fine_tune_seconds'] / 60.0
    }


def known_objects(args: argparse.Namespace, scans: list[LabelledScan]) -> dict:
    """The next scan of each room with the first scan's labels as known objects
    (``tools/predict.py --known``), the model itself unchanged; the minutes are the predictions'."""
    train, test = split(scans, 'next', args.new_rooms)
    work = args.work / 'known'
    first = {room_of(item.scan.stem): item.scan for item in train}
    before = measure_model(args.config, args.checkpoint, test, args.data, work / 'before' / 'eval',
                           work / 'before' / 'area9', args.score_thr, args.fork_tools)
    start, entries, classes = time.perf_counter(), [], []
    for item in test:
        out = work / 'after' / item.scan.stem
        run_step('tools/predict.py', [
            'tools/predict.py', str(args.config), str(args.checkpoint), str(item.scan), '--known',
            str(first[room_of(item.scan.stem)]), '--out', str(out), '--score-thr',
            str(args.score_thr)
        ], out / 'predict.log', args.fork_tools)
        predictions = read_predictions(out / f'{item.scan.stem}.pred.json')
        entries.append((item.scan.stem, item.labels, predictions['detections']))
        classes = predictions['classes']
    held = evaluate_detections(entries, classes, args.score_thr)
    return {
        'train': [path.stem for path in first.values()],
        'test': [item.scan.stem for item in test],
        'before': before,
        'after': {'held_out': held, 'area9': before['area9']},  # the same model
        'minutes': (time.perf_counter() - start) / 60.0
    }


def adapt(args: argparse.Namespace, scans: list[LabelledScan]) -> dict:
    """The unlabelled protocol: ``tools/adapt.py`` on the whole folder (or its finished run in
    WORK), the model before and after on the labelled scans."""
    work = args.work / 'unlabelled'
    adapted, record = work / 'adapted.pth', work / 'adapt_time.json'
    command = [
        'tools/adapt.py',
        str(args.scans), '--config',
        str(args.adapt_config), '--checkpoint',
        str(args.checkpoint), '--work',
        str(work / 'adapt'), '--out',
        str(adapted)
    ]
    command += [f'--{key}={value}' for key, value in (('rounds', args.rounds),
                                                       ('refresh', args.refresh),
                                                       ('unsure-thr', args.unsure_thr),
                                                       ('score-thr', args.pseudo_thr))
                if value is not None]  # the thresholds always: a default that changes reruns
    command += ['--cfg-options', *data_root_options(args.adapt_config, args.data)]
    done = json.loads(record.read_text(encoding='utf-8')) if record.is_file() else {}
    if not adapted.is_file() or done.get('command') != command:
        start = time.perf_counter()
        run_step('tools/adapt.py', command, work / 'adapt.log', args.fork_tools)
        record.write_text(json.dumps({'command': command,
                                      'seconds': time.perf_counter() - start}))
    minutes = json.loads(record.read_text(encoding='utf-8'))['seconds'] / 60.0
    row = {
        'train': [path.name for path in sorted(args.scans.iterdir())
                  if path.is_file() and path.suffix.lower() in SCAN_SUFFIXES],
        'test': [item.scan.stem for item in scans],
        'minutes': minutes
    }
    for name, config, model in (('before', args.config, args.checkpoint),
                                ('after', args.adapt_config, adapted)):
        row[name] = measure_model(config, model, scans, args.data, work / name / 'eval',
                                  work / name / 'area9', args.score_thr, args.fork_tools)
    return row


def goals(protocol: str, row: dict) -> dict[str, bool]:
    """Each goal of the protocol, met or not."""
    before, after = row['before']['held_out'], row['after']['held_out']
    recall, recall_before = after['overall_recall'] or 0.0, before['overall_recall'] or 0.0
    false, false_before = after['false_positives_per_room'], before['false_positives_per_room']
    area9 = [value for name, value in row['after']['area9']['mAP@0.25'].items()
             if name != 'mean' and value is not None]
    met = {
        'area 9 >= 0.9 in every class': min(area9, default=0.0) >= GOAL_AREA9,
        f'<= {GOAL_MINUTES:g} minutes': row['minutes'] <= GOAL_MINUTES
    }
    if protocol in ('next', 'known'):
        met.update({'recall >= 0.9': recall >= 0.9, '<= 0.5 false positives per scan':
                    false <= 0.5, 'no phantom': after['phantoms'] == 0})
    elif protocol == 'new':
        met.update({'recall +0.15': recall - recall_before >= 0.15 - 1e-9,
                    'no more false positives': false <= false_before})
    else:
        met.update({'recall +0.10': recall - recall_before >= 0.10 - 1e-9,
                    '30 % fewer false positives': false <= 0.7 * false_before + 1e-9})
    return met


def _recall_cells(held: dict) -> str:
    cells = []
    for name in REPORTED_CLASSES:
        total = held['total'].get(name)
        if total and total['truth']:
            cells.append(f'{name} {total["found"]}/{total["truth"]}')
    return ', '.join(cells)


def summary_line(protocol: str, row: dict) -> str:
    """``teach, next scan: recall A (was B), F false positives per scan (was G), P phantom``."""
    before, after = row['before']['held_out'], row['after']['held_out']
    return (f'{TITLES[protocol]}: recall {after["overall_recall"] or 0.0:.2f} (was '
            f'{before["overall_recall"] or 0.0:.2f}), {after["false_positives_per_room"]:.1f} '
            f'false positives per scan (was {before["false_positives_per_room"]:.1f}), '
            f'{after["phantoms"]} phantom')


def report(rows: dict[str, dict]) -> str:
    """The table of every protocol run, then one summary line each."""
    lines = []
    for protocol, row in rows.items():
        lines.append(f'{TITLES[protocol]}: taught on {", ".join(row["train"])}; tested on '
                     f'{len(row["test"])} scans ({row["minutes"]:.1f} min)')
        for name in ('before', 'after'):
            held, area9 = row[name]['held_out'], row[name]['area9']['mAP@0.25']
            per_class = ' '.join(f'{key} {value:.3f}' for key, value in area9.items()
                                 if key != 'mean' and value is not None)
            lines.append(
                f'  {name:6s} recall {held["overall_recall"] or 0.0:.3f} ({_recall_cells(held)}), '
                f'{held["false_positives_per_room"]:.2f} false positives per scan, '
                f'{held["phantoms"]} phantoms; area 9 AP@0.25 {per_class}')
        lines.append('  goals: ' + ', '.join(f'{goal} {"met" if met else "NOT met"}'
                                             for goal, met in row['goals'].items()))
    lines.append('')
    lines += [summary_line(protocol, row) for protocol, row in rows.items()]
    return '\n'.join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('scans', type=Path, help='folder of (mostly labelled) scans')
    parser.add_argument('--config', type=Path, required=True, help='the synthetic model config')
    parser.add_argument('--checkpoint', type=Path, required=True, help='its checkpoint')
    parser.add_argument('--data', type=Path, required=True,
                        help='generated data root with areas 7, 8, 9 (read only)')
    parser.add_argument('--work', type=Path, required=True, help='output folder')
    parser.add_argument('--protocols', nargs='+', choices=PROTOCOLS, default=list(PROTOCOLS),
                        help='the protocols to run (default: all)')
    parser.add_argument('--new-rooms', nargs='+', default=['scannet0000', 'scannet0001'],
                        help='the rooms a new-room protocol teaches on')
    parser.add_argument('--finetune-config', type=Path, default=CONFIGS / 'teach_finetune.py',
                        help='the next-scan and new-room fine-tune config '
                        '(default configs/tr3d/teach_finetune.py)')
    parser.add_argument('--adapt-config', type=Path, default=CONFIGS / 'adapt_selftrain.py',
                        help='the self-training config (default configs/tr3d/adapt_selftrain.py)')
    add_score_option(parser, '--score-thr', 0.3, 'lowest score of a detection counted')
    parser.add_argument('--iters', type=int, help='fine-tune iterations instead of the epochs')
    parser.add_argument('--rounds', type=int, help="adaptation rounds (tools/adapt.py's default)")
    parser.add_argument('--refresh', type=int, help='adaptation iterations per round')
    add_score_option(parser, '--unsure-thr', UNSURE_THR, "the adaptation's --unsure-thr")
    add_score_option(parser, '--pseudo-thr', PSEUDO_LABEL_THR, "the adaptation's --score-thr")
    add_fork_tools_option(parser)
    return parser.parse_args(argv)


def run(args: argparse.Namespace) -> dict:
    """Every protocol asked for; its figures and goals."""
    scans, _ = find_labelled_scans([args.scans])
    rows = {}
    for protocol in args.protocols:
        if protocol == 'unlabelled':
            row = adapt(args, scans)
        elif protocol == 'known':
            row = known_objects(args, scans)
        else:
            row = teach(args, protocol, scans)
        rows[protocol] = {**row, 'goals': goals(protocol, row)}
    return rows


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    return run_measured('bench_protocols',
                        [args.config, args.checkpoint, args.finetune_config, args.adapt_config],
                        lambda: run(args), args.work / 'protocols.json', report)


if __name__ == '__main__':
    sys.exit(main())
