"""Adapt a synthetic model to the user's unlabelled scans by self-training with a mean teacher.

Usage: python tools/adapt.py SCANS_DIR --config configs/tr3d/adapt_selftrain.py
                             --checkpoint CKPT --work DIR --out ADAPTED.pth [--rounds 4]
                             [--refresh N] [--score-thr 0.4] [--unsure-thr 0.3]
                             [--agree-iou 0.5] [--runs 2]
                             [--seed 0] [--device cpu] [--voxel M] [--columns x,y,z,r,g,b]
                             [--cfg-options k=v ...]

SCANS_DIR holds the scans (every file of a format ``synthdet.scan_io`` reads, as
``tools/scan2cad.py``); each is read and prepared as ``tools/predict.py`` does. Every round:

1. the teacher detects every scan with test-time augmentation, once per seed (``--runs``
   seeds from ``--seed``); the pseudo-labels are the boxes scoring at least ``--score-thr``
   that every run finds (same class, axis-aligned 3D IoU >= ``--agree-iou``)
   (``projects/synthdet/self_training.py``); the other boxes scoring at least
   ``--unsure-thr`` become ignored regions, left out of the class loss;
2. the scans become S3DIS rooms of the config's ``adapt_area`` labelled by them (the rules of
   ``python -m configurator labels``), converted as ``tools/create_data.py`` does;
3. mmengine's Runner trains ``--refresh`` iterations (default: the config's
   ``refresh_iters``) on them mixed with the config's generated training areas, from the
   previous round's checkpoint; the teacher is the exponential moving average of the
   student's weights (``MeanTeacherEMAHook``).

The first round's teacher is ``--checkpoint``. ``--out`` receives the last teacher's weights
as an inference checkpoint (weights and plain meta). Everything else goes to ``--work``
(``round_<k>/``: ``pseudo_labels.json``, ``raw/``, ``data/``, ``train/``); a rerun with the
same ``--work`` and options continues after the last finished step (more ``--rounds`` add
rounds). Checkpoints are loaded weights-only. The config, checkpoint, scans, generated areas
and outputs are checked before any work: bad input ends with one line naming the file or
option and exit code 2, a failure at run time with exit code 1.
"""
import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mmengine.config import Config
from tqdm import tqdm

from projects.synthdet.bootstrap import add_cfg_options, check_device, load_config, run_tool
from projects.synthdet.checkpoint import load_checkpoint_file, save_inference_checkpoint
from projects.synthdet.datasets.s3dis_converter import convert_s3dis
from projects.synthdet.inference.detector import load_model
from projects.synthdet.inference.windows import WindowSpec, inference_settings
from projects.synthdet.config_helpers import area_info_file
from projects.synthdet.self_training import (PSEUDO_LABEL_THR, UNSURE_THR, PseudoLabelRule,
                                             add_ignored_regions, adapt_repeat, check_share,
                                             ignored_regions, pseudo_boxes, raw_area_dir,
                                             room_offset, round_config, teacher_pseudo_labels,
                                             train_round, write_pseudo_room)
from synthdet.cli import OneLineParser, add_score_option, float_in, int_in
from synthdet.contracts import write_json_atomic
from synthdet.outputs import check_output, readable
from synthdet.prepare import prepare_scan
from synthdet.scan_io import SCAN_SUFFIXES, load_scan

PSEUDO_LABELS_FORMAT = 'synthdet.pseudo_labels/1'


class BadInput(ValueError):
    """A scan, config, checkpoint, option or output adapt cannot use; names it."""


@dataclass
class Setup:
    """The checked inputs of a run."""

    cfg: Config
    scans: list[Path]
    spec: WindowSpec
    density: float
    repeat: int
    classes: list[str]
    rule: PseudoLabelRule


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Parse the command line."""
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('scans', type=Path, help='folder of unlabelled scans')
    parser.add_argument('--config', type=Path, required=True,
                        help='self-training config, e.g. configs/tr3d/adapt_selftrain.py')
    parser.add_argument('--checkpoint', type=Path, required=True, help='the synthetic model')
    parser.add_argument('--work', type=Path, required=True, help='work folder (resumable)')
    parser.add_argument('--out', type=Path, required=True, help='the adapted checkpoint')
    parser.add_argument('--rounds', type=int_in(1, 1000), default=4,
                        help='refreshes of the pseudo-labels (default 4)')
    parser.add_argument('--refresh', type=int_in(1, 10**6),
                        help="iterations per round (default: the config's refresh_iters)")
    add_score_option(parser, '--score-thr', PSEUDO_LABEL_THR,
                     'lowest fused score of a pseudo-label')
    add_score_option(parser, '--unsure-thr', UNSURE_THR, 'lowest score of a box that is an '
                     'ignored region when it is no pseudo-label (at most --score-thr)')
    parser.add_argument('--agree-iou', type=float_in(0.0, 1.0, include_low=False), default=0.5,
                        help='3D IoU at which the runs agree on a box (default 0.5)')
    parser.add_argument('--runs', type=int_in(1, 16), default=2,
                        help='test-time augmented runs, each seeded, that must agree (default 2)')
    parser.add_argument('--seed', type=int_in(0, 2**31 - 1), default=0,
                        help='seed of the point sampling and of training (default 0)')
    parser.add_argument('--device', default=None,
                        help='cpu, cuda or cuda:N (default: cuda:0 if present)')
    parser.add_argument('--voxel', type=float_in(0.0, 10.0, include_low=False),
                        help='keep one point per voxel of this size (m) while reading')
    parser.add_argument('--columns', help='text scans: the columns, e.g. x,y,z,r,g,b')
    add_cfg_options(parser)
    return parser.parse_args(argv)


def find_scans(folder: Path) -> list[Path]:
    """The scan files of ``folder`` by name; ``BadInput`` for a missing folder or none."""
    if not folder.is_dir():
        raise BadInput(f'{folder}: no such folder of scans')
    scans = sorted(path for path in folder.iterdir()
                   if path.is_file() and path.suffix.lower() in SCAN_SUFFIXES)
    if not scans:
        raise BadInput(f'{folder}: no scan ({", ".join(SCAN_SUFFIXES)})')
    return scans


def check_inputs(args: argparse.Namespace) -> tuple[Setup, object]:
    """Check every input before any work; the run's setup and the first round's teacher.
    Raises ``BadInput`` naming the file or option."""
    try:
        scans = find_scans(args.scans)
        check_output(args.out, '--out', inputs=[args.checkpoint, args.config, *scans])
        check_output(args.work, '--work', folder=True)
        cfg = load_config(args.config, args.cfg_options)
        check_share(cfg)
        spec, density = inference_settings(cfg, str(args.config))
        for scan in scans:
            load_scan(scan, voxel=args.voxel, columns=args.columns)
        repeat = adapt_repeat(cfg, len(scans))
        args.device = check_device(args.device)  # DeviceError, a ValueError
        teacher = load_model(cfg, str(args.checkpoint), args.device, tta=True)
    except (ValueError, OSError) as error:  # each names its file, option or config key
        raise BadInput(readable(str(error))) from None
    classes = list(teacher.dataset_meta['classes'])
    trained = list(cfg.train_dataloader.dataset.dataset.datasets[0].metainfo['classes'])
    if classes != trained:
        raise BadInput(f'{args.checkpoint}: its classes {classes} are not the config\'s '
                       f'{trained}')
    if args.unsure_thr > args.score_thr:
        raise BadInput(f'--unsure-thr {args.unsure_thr}: above --score-thr {args.score_thr}')
    rule = PseudoLabelRule(args.score_thr, args.agree_iou,
                           tuple(args.seed + run for run in range(args.runs)), args.unsure_thr)
    return Setup(cfg, scans, spec, density, repeat, classes, rule), teacher


def check_settings(args: argparse.Namespace, setup: Setup) -> None:
    """Record the run's settings in ``--work``; ``BadInput`` when it holds a run of others."""
    settings = {
        'config': str(args.config.resolve()),
        'checkpoint': str(args.checkpoint.resolve()),
        'scans': [scan.name for scan in setup.scans],
        'refresh': args.refresh or setup.cfg.refresh_iters,
        'score_thr': args.score_thr,
        'agree_iou': args.agree_iou,
        'unsure_thr': args.unsure_thr,
        'seeds': list(setup.rule.seeds),
        'voxel': args.voxel,
        'columns': args.columns,
        'cfg_options': {key: repr(value) for key, value in (args.cfg_options or {}).items()}
    }
    path = args.work / 'settings.json'
    if path.is_file():
        before = json.loads(path.read_text(encoding='utf-8'))
        changed = sorted(key for key in settings if before.get(key) != settings[key])
        if changed:
            raise BadInput(f'--work {args.work}: holds a run with other {", ".join(changed)}; '
                           'rerun with its options or use another --work')
    args.work.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, settings)


def prepared_scans(args: argparse.Namespace, setup: Setup) -> list[np.ndarray]:
    """Every scan read and prepared (levelled, turned, resampled to the training density) with
    ``--seed``: the same points in every round."""
    return [
        prepare_scan(load_scan(scan, voxel=args.voxel, columns=args.columns),
                     target_density=setup.density,
                     seed=args.seed).points
        for scan in tqdm(setup.scans, desc='prepare', unit='scan')
    ]


def pseudo_label_round(setup: Setup, teacher, points: list[np.ndarray], round_dir: Path) -> dict:
    """Pseudo-label every scan's prepared ``points`` with ``teacher``, write and convert the
    rooms; returns the round's ``pseudo_labels.json`` document, written last."""
    area = setup.cfg.adapt_area
    area_dir = raw_area_dir(round_dir / 'raw', area)
    area_dir.mkdir(parents=True, exist_ok=True)
    scans, regions = [], {}
    for index, (scan, scan_points) in enumerate(
            tqdm(list(zip(setup.scans, points)), desc=f'{round_dir.name}: pseudo-labels',
                 unit='scan')):
        found, unsure = teacher_pseudo_labels(teacher, scan_points, setup.spec, setup.rule)
        room = f'scan_{index + 1}'
        boxes = write_pseudo_room(area_dir / room, scan_points, pseudo_boxes(found, setup.classes))
        ignored = ignored_regions(unsure, found, setup.rule.agree_iou)
        regions[f'Area_{area}_{room}.bin'] = ignored - np.r_[room_offset(scan_points), 0, 0, 0]
        scans.append({'scan': scan.name, 'room': room, 'boxes': boxes,
                      'ignored_regions': [[round(float(v), 4) for v in box] for box in ignored],
                      'points': len(scan_points)})
    convert_s3dis(round_dir / 'raw', round_dir / 'data', areas=[area])
    add_ignored_regions(round_dir / 'data' / area_info_file(area), regions)
    document = {
        'format': PSEUDO_LABELS_FORMAT,
        'frame': 'prepared (floor at z = 0, walls along the axes)',
        'rule': {
            'score_thr': setup.rule.score_thr,
            'agree_iou': setup.rule.agree_iou,
            'unsure_thr': setup.rule.unsure_thr,
            'seeds': list(setup.rule.seeds)
        },
        'scans': scans
    }
    write_json_atomic(round_dir / 'pseudo_labels.json', document)
    return document


def adapt(args: argparse.Namespace) -> Path:
    """Run (or continue) every round and write ``--out``; returns it."""
    setup, teacher = check_inputs(args)
    check_settings(args, setup)
    refresh = args.refresh or setup.cfg.refresh_iters
    previous = args.checkpoint
    points = None  # prepared once, when a round first needs pseudo-labels
    for index in tqdm(range(1, args.rounds + 1), desc='adapt', unit='round'):
        round_dir = args.work / f'round_{index}'
        checkpoint = round_dir / 'train' / f'iter_{refresh}.pth'
        if not checkpoint.is_file():
            if teacher is None:  # the previous round's average, loaded weights-only
                teacher = load_model(setup.cfg, str(previous), args.device, tta=True)
            record = round_dir / 'pseudo_labels.json'
            if record.is_file():  # labelled before a stop during the round's training
                document = json.loads(record.read_text(encoding='utf-8'))
            else:
                points = points if points is not None else prepared_scans(args, setup)
                document = pseudo_label_round(setup, teacher, points, round_dir)
            count = sum(len(item['boxes']) for item in document['scans'])
            tqdm.write(f'{round_dir.name}: {count} pseudo-labels in {len(setup.scans)} scans')
            cfg = round_config(setup.cfg, round_dir / 'train', previous, round_dir / 'data',
                               setup.repeat, refresh, args.seed)
            checkpoint = train_round(cfg)
        previous, teacher = checkpoint, None
    out = save_inference_checkpoint(load_checkpoint_file(previous), args.out)
    print(f'adapt: wrote {readable(str(out))} (the teacher after {args.rounds} rounds of '
          f'{refresh} iterations)')
    return out


def main(argv: list[str] | None = None) -> Path:
    """Parse the command line and adapt."""
    return adapt(parse_args(argv))


if __name__ == '__main__':
    run_tool(main, 'adapt.py', bad_input=(BadInput, ), failure=(RuntimeError, OSError))
