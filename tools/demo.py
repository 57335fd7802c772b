"""The whole synthdet pipeline in one command (``make demo``): first a scan to a FreeCAD
document with the shipped model, then generate, convert, train, test, predict, room corners,
FreeCAD documents, pictures and a report.

    python tools/demo.py [--size tiny|demo] [--work-dir work_dirs/demo] [--force]

Every step runs a stage's own CLI with this interpreter as a subprocess, shows its progress and
keeps its log in ``WORK/logs/``. A step whose outputs exist is skipped, so a run that was
stopped continues where it stopped (training resumes from its newest checkpoint). Data never
goes to ``data/``: the generated areas and converted files live in ``WORK/data``.

Steps and outputs (``WORK`` = the work directory):
 0. a scan to a document        WORK/scan/factory_1.ply (a generated factory room of its own
                                seed, as a PLY a user hands over), then tools/scan2cad.py with
                                the shipped model: WORK/scan/factory_1.FCStd (+ .pred.json,
                                .corners.json) and WORK/scan/factory_1.FCStd.png (FreeCAD's view)
 1. generate areas 7-9          WORK/data/Stanford3dDataset_v1.2_Aligned_Version/Area_{7,8,9}
                                (annotations checked with tools/check_annotations.py)
 2. convert                     WORK/data/s3dis_infos_Area_{7,8,9}.pkl, points/, masks
 3. Table 1                     WORK/table1.json, WORK/table1.txt
 4. train (exp2_cpu, resized)   WORK/exp2_cpu_<size>.py, WORK/train/epoch_N.pth (the last one is tested)
 5. test, Table 3               WORK/table3.json, WORK/table3.txt
 6. predict held-out rooms of 9 WORK/predictions/<room>.pred.json
 7. Table 4                     WORK/table4.json, WORK/table4.txt
 8. corners                     WORK/rooms/<room>.corners.json (+ .corners.png)
 9. FreeCAD documents           WORK/rooms/<room>.FCStd
10. pictures                    WORK/rooms/<room>.png (GT, predictions, corners), <room>.ply
11. report                      WORK/REPORT.md
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from projects.synthdet.config_helpers import with_num_points
from synthdet.cli import OneLineParser, int_in
from synthdet.contracts import read_corners, read_predictions, read_room
from synthdet.info_files import RAW_DIR
from synthdet.outputs import OutputRefused, check_output_dir, write_text
from synthdet.work_dir import StepError, claim_work_dir

REPO_ROOT = Path(__file__).resolve().parents[1]

BASE_CONFIG = REPO_ROOT / 'configs/tr3d/exp2_cpu.py'
AREAS = (7, 8, 9)
TEST_AREA = 9
SCAN_AREA = 1  # the shipped model's scan: one factory room, not in areas 7-9
SCAN_SEED_OFFSET = 1000  # its seed, away from the training areas' seed


@dataclass(frozen=True)
class Size:
    """How big the demo is: data, training schedule and how many test rooms get a CAD model.
    The defaults are `make demo`'s size (about 30 minutes on 2 free cores)."""
    rooms_per_area: int = 12
    points: int = 200_000  # points per generated room
    scan_points: int = 1_000_000  # points of the scan that the shipped model turns into a document
    num_points: int = 40_000  # points sampled per room for the detector
    epochs: int = 5
    repeats: int = 2  # times the training areas are repeated per epoch
    batch_size: int = 4
    loader_workers: int = 1
    predict_rooms: int = 3  # rooms of area 9 that are predicted, get corners, CAD and pictures
    workers: int = 2  # generator and converter processes
    log_interval: int = 4
    score_thr: float = 0.3  # detections kept for Table 4, the FreeCAD documents and the pictures
    # head locations kept before NMS when predicting (the model's test_cfg.nms_pre); None keeps
    # the config's
    predict_candidates: int | None = None


SIZES = {
    # the smoke test: minutes on 2 cores; the model is far from converged: its scores stay near
    # the 1 % prior of its class bias (0.0100-0.0106 measured), so detections from 0.01 up are
    # kept, from its 10 best locations (about 20 boxes), to exercise the CAD and drawing steps
    'tiny':
    Size(rooms_per_area=2, points=30_000, scan_points=100_000, num_points=4_000, epochs=1,
         repeats=1, batch_size=2, loader_workers=0, predict_rooms=1, workers=1, log_interval=1,
         score_thr=0.01, predict_candidates=10),
    'demo': Size(),
}


class Demo:
    """The pipeline's steps over one work directory."""

    def __init__(self,
                 work_dir: Path,
                 size_name: str,
                 seed: int = 0,
                 threads: int | None = None,
                 python: str = sys.executable) -> None:
        self.work = work_dir.resolve()
        self.size_name = size_name
        self.size = SIZES[size_name]
        self.seed = seed
        self.python = python
        self.threads = threads
        self.data = self.work / 'data'
        self.raw = self.data / RAW_DIR
        self.logs = self.work / 'logs'
        self.rooms_dir = self.work / 'rooms'
        self.predictions = self.work / 'predictions'
        self.config = self.work / f'exp2_cpu_{size_name}.py'  # its stem names the model
        self.train_dir = self.work / 'train'
        self.scan_dir = self.work / 'scan'
        self.durations_file = self.work / 'durations.json'
        self.durations: dict[str, float] = (
            json.loads(self.durations_file.read_text()) if self.durations_file.is_file() else {})

    # ------------------------------------------------------------------ running commands
    def run(self, name: str, *args: str | os.PathLike) -> None:
        """Run ``python ARGS`` from the repository root, echo its output live (progress bars
        included) and keep it in ``logs/<name>.log``; raises on failure."""
        self.logs.mkdir(parents=True, exist_ok=True)
        log_path = self.logs / f'{name}.log'
        command = [self.python, *map(str, args)]
        env = dict(os.environ, PYTHONUNBUFFERED='1', PYTHONWARNINGS='ignore')
        if self.threads:
            env['OMP_NUM_THREADS'] = str(self.threads)
        with open(log_path, 'wb') as log, subprocess.Popen(
                command, cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                env=env) as process:
            log.write(('$ ' + ' '.join(command) + '\n').encode())
            for chunk in iter(lambda: process.stdout.read1(4096), b''):
                log.write(chunk)
                sys.stdout.buffer.write(chunk)
                sys.stdout.flush()
        if process.returncode != 0:
            raise StepError(f'{name}: `{" ".join(command)}` exited with {process.returncode}; '
                            f'see {log_path}')

    # ------------------------------------------------------------------ the steps
    def steps(self) -> list[tuple[str, Callable[[], bool], Callable[[], None]]]:
        """(name, outputs-exist check, action) of every step, in order."""
        return [
            ('scan2cad', lambda: self.shipped_document().with_suffix('.FCStd.png').is_file(),
             self.scan2cad),
            ('generate', self.generated, self.generate),
            ('convert', self.converted, self.convert),
            ('table1', lambda: (self.work / 'table1.json').is_file(), self.table1),
            ('train', self.trained, self.train),
            ('test', lambda: (self.work / 'table3.json').is_file(), self.test),
            ('predict', self.predicted, self.predict),
            ('table4', lambda: (self.work / 'table4.json').is_file(), self.table4),
            ('corners', lambda: self.all_exist('.corners.json'), self.corners),
            ('freecad', lambda: self.all_exist('.FCStd'), self.freecad),
            ('pictures', lambda: self.all_exist('.png'), self.pictures),
            ('report', lambda: False, self.report),
        ]

    def room_names(self, area: int) -> list[str]:
        """The generated rooms of an area that hold a ``meta.json``, in generation order."""
        folder = self.raw / f'Area_{area}'
        names = [p.parent.name for p in folder.glob('*/meta.json')] if folder.is_dir() else []
        return sorted(names, key=lambda name: int(name.rsplit('_', 1)[-1]))

    def held_out_rooms(self) -> list[str]:
        """The first rooms of the test area, which the detector never trained on."""
        return self.room_names(TEST_AREA)[:self.size.predict_rooms]

    def scan(self, room: str) -> Path:
        return self.raw / f'Area_{TEST_AREA}' / room / f'{room}.txt'

    def all_exist(self, suffix: str) -> bool:
        rooms = self.held_out_rooms()
        return bool(rooms) and all(
            (self.rooms_dir / f'{room}{suffix}').is_file() for room in rooms)

    def shipped_scan(self) -> Path:
        """The demo's own scan: a generated factory room written as PLY."""
        return self.scan_dir / f'Area_{SCAN_AREA}' / 'factory_1' / 'factory_1.ply'

    def shipped_document(self) -> Path:
        return self.scan_dir / 'factory_1.FCStd'

    def scan2cad(self) -> None:
        """A generated factory room as PLY -> ``tools/scan2cad.py`` with the shipped model ->
        the FreeCAD document and a picture of it as FreeCAD shows it."""
        if not self.shipped_scan().is_file():
            self.run('scan', '-m', 'generator', '--out', self.scan_dir, '--areas',
                     str(SCAN_AREA), '--rooms-per-area', '1', '--points',
                     str(self.size.scan_points), '--seed',
                     str(self.seed + SCAN_SEED_OFFSET), '--ply')
        document = self.shipped_document()
        self.run('scan2cad', 'tools/scan2cad.py', self.shipped_scan(), '--out', document,
                 '--seed', str(self.seed))
        self.configurator('screenshot', 'screenshot', document, '--out',
                          document.with_suffix('.FCStd.png'))

    def generated(self) -> bool:
        return all(len(self.room_names(area)) >= self.size.rooms_per_area for area in AREAS)

    def generate(self) -> None:
        self.run('generate', '-m', 'generator', '--out', self.raw, '--areas', *map(str, AREAS),
                 '--rooms-per-area', str(self.size.rooms_per_area), '--points',
                 str(self.size.points), '--seed', str(self.seed), '--workers',
                 str(self.size.workers))
        # a labelling rule that gives objects points off them would stretch their true boxes
        self.run('check_annotations', 'tools/check_annotations.py', self.raw, '--areas',
                 *map(str, AREAS))

    def converted(self) -> bool:
        return all((self.data / f's3dis_infos_Area_{area}.pkl').is_file() for area in AREAS)

    def convert(self) -> None:
        self.run('convert', 'tools/create_data.py', 's3dis', '--root-path', self.data, '--out-dir',
                 self.data, '--areas', *map(str, AREAS), '--workers', str(self.size.workers))

    def table1(self) -> None:
        """``table1.json`` and ``table1.txt``, written by the tool."""
        self.run('table1', 'tools/dataset_stats.py', self.data, '--areas', *map(str, AREAS),
                 '--out', self.work / 'table1.json')

    def write_config(self) -> None:
        """The demo's config: ``configs/tr3d/exp2_cpu.py`` with this size's data, points and
        schedule, dumped as one self-contained file next to the checkpoints."""
        from mmengine.config import Config

        cfg = Config.fromfile(BASE_CONFIG)
        size = self.size
        data_root = f'{self.data}/'
        loader = dict(num_workers=size.loader_workers, persistent_workers=size.loader_workers > 0)
        for dataset in cfg.train_dataloader.dataset.dataset.datasets:
            dataset.data_root = data_root
            dataset.pipeline = with_num_points(dataset.pipeline, size.num_points)
        cfg.train_dataloader.dataset.times = size.repeats
        cfg.train_dataloader.batch_size = size.batch_size
        cfg.train_dataloader.update(loader)
        for name in ('val_dataloader', 'test_dataloader'):
            cfg[name].update(loader)
            cfg[name].dataset.data_root = data_root
            cfg[name].dataset.pipeline = with_num_points(cfg[name].dataset.pipeline,
                                                         size.num_points)
        cfg.train_cfg.max_epochs = size.epochs
        cfg.train_cfg.val_interval = 1
        # a short schedule: the learning rate drops 10x for the last epoch only
        cfg.param_scheduler = dict(
            type='MultiStepLR',
            begin=0,
            end=size.epochs,
            by_epoch=True,
            milestones=[size.epochs - 1] if size.epochs > 1 else [],
            gamma=0.1)
        cfg.default_hooks.logger.interval = size.log_interval
        cfg.randomness = dict(seed=self.seed)
        self.work.mkdir(parents=True, exist_ok=True)
        header = (f'# synthdet demo ({self.size_name}): {BASE_CONFIG.relative_to(REPO_ROOT)} '
                  f'with the data in {self.data},\n# {size.num_points} sampled points, '
                  f'{size.epochs} epochs, training areas repeated {size.repeats}x, batch '
                  f'{size.batch_size}. Written by tools/demo.py.\n')
        write_text(self.config, header + cfg.pretty_text)

    def trained(self) -> bool:
        return (self.train_dir / f'epoch_{self.size.epochs}.pth').is_file()

    def train(self) -> None:
        if not self.config.is_file():
            self.write_config()
        resume = ['--resume'] if list(self.train_dir.glob('epoch_*.pth')) else []
        self.run('train', 'tools/train.py', self.config, '--work-dir', self.train_dir, *resume)

    def final_checkpoint(self) -> Path:
        """The last epoch's checkpoint: area 9 validates and tests, so no epoch is picked on it."""
        final = self.train_dir / f'epoch_{self.size.epochs}.pth'
        if not final.is_file():
            raise StepError(f'no {final}: run the train step first')
        return final

    def test(self) -> None:
        """``table3.json`` and ``table3.txt``, written by the tool."""
        self.run('test', 'tools/test.py', self.config, self.final_checkpoint(), '--work-dir',
                 self.work / 'test', '--out', self.work / 'table3.json')

    def predicted(self) -> bool:
        rooms = self.held_out_rooms()
        return bool(rooms) and all(
            (self.predictions / f'{room}.pred.json').is_file() for room in rooms)

    def predict(self) -> None:
        candidates = self.size.predict_candidates
        options = [] if candidates is None else [
            '--cfg-options', f'model.test_cfg.nms_pre={candidates}'
        ]
        self.run('predict', 'tools/predict.py', self.config, self.final_checkpoint(),
                 *[self.scan(room) for room in self.held_out_rooms()], '--out', self.predictions,
                 '--seed', str(self.seed), '--score-thr', str(self.size.score_thr), *options)

    def table4(self) -> None:
        """``table4.json`` and ``table4.txt``, written by the tool."""
        self.run('table4', 'tools/count_table.py', self.predictions, '--out',
                 self.work / 'table4.json', '--score-thr', str(self.size.score_thr))

    def configurator(self, log: str, command: str, *args: str | os.PathLike) -> None:
        """Run ``python -m configurator COMMAND ARGS``."""
        self.run(log, '-m', 'configurator', command, *args)

    def corners(self) -> None:
        self.rooms_dir.mkdir(parents=True, exist_ok=True)
        for room in self.held_out_rooms():
            self.configurator(f'corners_{room}', 'corners', self.scan(room), '--out',
                              self.rooms_dir / f'{room}.corners.json', '--preview',
                              self.rooms_dir / f'{room}.corners.png')

    def freecad(self) -> None:
        for room in self.held_out_rooms():
            self.configurator(f'freecad_{room}', 'freecad', '--scan', self.scan(room),
                              '--predictions', self.predictions / f'{room}.pred.json', '--corners',
                              self.rooms_dir / f'{room}.corners.json', '--out',
                              self.rooms_dir / f'{room}.FCStd', '--min-score',
                              str(self.size.score_thr))

    def pictures(self) -> None:
        for room in self.held_out_rooms():
            self.run(
                f'visualize_{room}', 'tools/visualize.py', self.scan(room), '--gt',
                self.scan(room).parent / 'meta.json', '--pred',
                self.predictions / f'{room}.pred.json', '--corners',
                self.rooms_dir / f'{room}.corners.json', '--out', self.rooms_dir / f'{room}.png',
                '--ply', self.rooms_dir / f'{room}.ply', '--min-score', str(self.size.score_thr),
                '--title',
                f'Area_{TEST_AREA}/{room}: ground truth (solid), predictions with score >= '
                f'{self.size.score_thr} (dashed), room corners (black)')

    def report(self) -> None:
        write_text(self.work / 'REPORT.md', self.report_text())

    # ------------------------------------------------------------------ the report
    def shipped_report(self) -> list[str]:
        """The report's first section: the scan the shipped model turned into a document."""
        document = self.shipped_document()
        detections = read_predictions(document.with_suffix('.pred.json'))['detections']
        counts = Counter(detection['class'] for detection in detections)
        found = ', '.join(f'{count} {name}' for name, count in sorted(counts.items())) or 'none'
        picture = document.with_suffix('.FCStd.png').relative_to(self.work)
        return [
            '## A scan to a FreeCAD document with the shipped model',
            '',
            f'`tools/scan2cad.py {self.shipped_scan().relative_to(self.work)} --out '
            f'{document.relative_to(self.work)}`: a generated factory room '
            f'({self.size.scan_points:,} points, seed {self.seed + SCAN_SEED_OFFSET}) read as '
            f'a PLY, detected by the model that ships with synthdet (no training), its corners '
            f'traced and its document built. Detections: {found}.',
            '',
            f'![The document as FreeCAD shows it]({picture})',
            '',
        ]

    def report_text(self) -> str:
        """REPORT.md: the tables, the pictures, the corners and the FreeCAD documents."""
        size = self.size
        lines = [
            f'# synthdet demo report ({self.size_name})',
            '',
            f'Generated areas 7, 8, 9 with {size.rooms_per_area} rooms each and {size.points:,} '
            f'points per room (seed {self.seed}); TR3D trained on areas 7 and 8 with '
            f'`{self.config.name}` (configs/tr3d/exp2_cpu.py with {size.num_points:,} sampled '
            f'points, {size.epochs} epoch(s), areas repeated {size.repeats}x), tested on area 9. '
            f'Data: `{self.data}`. Logs of every step: `logs/`.',
            '',
            *self.shipped_report(),
            '## Table 1: instances per class and area',
            '',
            '```',
            (self.work / 'table1.txt').read_text().rstrip(),
            '```',
            '',
            '## Table 3: test on area 9',
            '',
            f'Checkpoint `{self.final_checkpoint().relative_to(self.work)}` (the final '
            'epoch). JSON: [table3.json](table3.json).',
            '',
            _table3_markdown(json.loads((self.work / 'table3.json').read_text())),
            '',
            f'## Table 4: objects per held-out room (score >= {size.score_thr})',
            '',
            'True objects, then correct(incorrect) detections. JSON: [table4.json](table4.json).',
            '',
            '```',
            (self.work / 'table4.txt').read_text().rstrip(),
            '```',
            '',
            '## Held-out rooms of area 9',
            '',
        ]
        for room in self.held_out_rooms():
            corners = read_corners(self.rooms_dir / f'{room}.corners.json')
            meta = read_room(self.scan(room).parent / 'meta.json')
            detections = read_predictions(self.predictions / f'{room}.pred.json')
            fcstd = self.rooms_dir / f'{room}.FCStd'
            lines += [
                f'### {room}',
                '',
                f'![{room}: top view with boxes](rooms/{room}.png)',
                '',
                f'- scan: `{self.scan(room)}`',
                f'- detections (score >= {size.score_thr}): {len(detections["detections"])}; '
                f'true objects of these classes: '
                f'{sum(o["class"] in detections["classes"] for o in meta["objects"])} '
                f'([predictions]'
                f'(predictions/{room}.pred.json))',
                f'- corners ({len(corners["corners"])}, clockwise, metres): ' +
                ', '.join(f'({x:.2f}, {y:.2f})' for x, y in corners['corners']),
                f'- true floor polygon ({len(meta["room"]["polygon"])} corners, '
                f'{meta["room"].get("shape", "?")}): ' +
                ', '.join(f'({x:.2f}, {y:.2f})' for x, y in meta['room']['polygon']),
                f'- floor z {corners["floor_z"]:.3f} m, ceiling z {corners["ceiling_z"]:.3f} m '
                f'(true height {meta["room"]["height"]:.2f} m); corner preview: '
                f'[{room}.corners.png](rooms/{room}.corners.png)',
                f'- FreeCAD document: [`{fcstd}`](rooms/{room}.FCStd)',
                f'- point cloud for CloudCompare: [rooms/{room}.ply](rooms/{room}.ply)',
                '',
            ]
        if self.durations:
            lines += ['## Wall time per step', '', '| step | seconds |', '|---|---|']
            lines += [f'| {name} | {seconds:.0f} |' for name, seconds in self.durations.items()]
            lines.append('')
        return '\n'.join(lines)

    # ------------------------------------------------------------------ driver
    def check_work_dir(self) -> None:
        """Record the size and seed in ``demo.json``; refuse a work dir made with others."""
        claim_work_dir(self.work / 'demo.json', {
            'format': 'synthdet.demo/1',
            'size': self.size_name,
            'seed': self.seed
        })

    def run_all(self, force: bool = False) -> None:
        """Run every step whose outputs are missing (all of them with ``force``)."""
        self.check_work_dir()
        steps = self.steps()
        start = time.monotonic()
        for index, (name, done, action) in enumerate(steps, start=1):
            prefix = f'[demo {index}/{len(steps)}] {name}'
            if done() and not force:
                print(f'{prefix}: outputs exist, skipped', flush=True)
                continue
            print(f'{prefix} ...', flush=True)
            began = time.monotonic()
            action()
            self.durations[name] = time.monotonic() - began
            write_text(self.durations_file, json.dumps(self.durations, indent=1) + '\n')
            print(f'{prefix}: done in {self.durations[name]:.0f} s', flush=True)
        print(
            f'[demo] finished in {time.monotonic() - start:.0f} s: {self.work / "REPORT.md"}',
            flush=True)


def _table3_markdown(table3: dict) -> str:
    """Table 3 (rows mAP@0.25 and mAP@0.5, a column per class and the mean) as Markdown."""
    classes = list(table3['classes']) + ['mean']
    lines = ['| | ' + ' | '.join(classes) + ' |', '|---' * (len(classes) + 1) + '|']
    for row, values in table3['rows'].items():
        cells = ['-' if values.get(c) is None else f'{values[c]:.3f}' for c in classes]
        lines.append(f'| {row} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineParser(description=__doc__.split('\n\n')[0].replace('\n', ' '))
    parser.add_argument(
        '--size',
        choices=sorted(SIZES),
        default='demo',
        help='tiny: smoke test (minutes); demo: about 30 min on 2 cores')
    parser.add_argument('--work-dir', type=Path, default=REPO_ROOT / 'work_dirs/demo')
    parser.add_argument(
        '--seed',
        type=int_in(0, 2**32 - 1),
        default=0,
        help='generator and training seed, 0 to 2^32-1 (default 0)')
    parser.add_argument('--force', action='store_true', help='rerun steps whose outputs exist')
    parser.add_argument(
        '--threads',
        type=int_in(1, 256),
        help='OpenMP threads per step (OMP_NUM_THREADS); 1 is much faster on a '
        'machine busy with other work')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run the demo; 0, 2 with one line for a ``--work-dir`` that is no folder, 1 with one
    line for a step that fails or a work dir that cannot be written (checked first)."""
    args = parse_args(argv)
    demo = Demo(args.work_dir, args.size, args.seed, args.threads)
    try:
        check_output_dir(args.work_dir, '--work-dir')
        demo.run_all(force=args.force)
    except OutputRefused as error:
        print(f'[demo] error: {error}', file=sys.stderr)
        return 2
    except (StepError, OSError) as error:  # OutputFailed: a full disk, a read-only folder
        print(f'[demo] error: {error}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
