"""Convert one generated S3DIS-format area with synthdet's converter and with mmdet3d's code path.

mmdet3d's path is its collect step (``data/s3dis/collect_indoor3d_data.py`` with
``indoor3d_util.export``: pandas ``read_csv`` per annotation file, ``.npy`` files in
``s3dis_data/``) followed by the installed ``S3DISData.get_infos`` from
``mmdet3d/.mim/tools/dataset_converters/s3dis_data_utils.py`` (``.bin`` files and box
extraction). The wheel does not ship ``data/s3dis/``, so the collect step is re-expressed
below operation for operation; ``S3DISData`` is imported from the installed file and run
unchanged. It accepts only ``Area_1``..``Area_6``, so the generated area is exposed to it as
``Area_1`` through a symlink (the input is adapted, not its code).

The area holds the five S3DIS detection classes, so that both converters can produce every box.
Outputs are checked to be identical: points, semantic masks and boxes bit for bit, instance
masks after matching instances by annotation file (mmdet3d numbers them in ``glob`` order,
synthdet in natural file-name order).

Both converters run at equal parallelism: one process each (mmdet3d's ``S3DISData`` with one
thread), and ``--workers`` each, where mmdet3d's collect step, serial as shipped, runs its rooms
in a pool of ``--workers`` processes (what a user would write to parallelise it) and
``S3DISData`` gets ``--workers`` threads. mmdet3d as shipped (serial collect, ``--workers``
threads) is timed too. The rooms are flushed to disk and read once (the same warm page cache
for both) before any timing. Every configuration runs once untimed (warm-up), then ``--repeats``
times, alternating; the best wall time of each is kept. Each run writes into empty output
folders (the previous run's files removed before its timer starts), as a first conversion
does. The table gives each configuration's best wall time, its CPU seconds and their
system part (page faults, copies into the page cache: on a virtual machine whose free memory
goes back to its host, the part that varies from run to run). The last line gives the wall-time
ratios at equal parallelism (the headline), synthdet's own parallelism against mmdet3d as
shipped and the ratio of CPU seconds (mmdet3d / synthdet, one process each) beside them.

    python benchmarks/bench_convert.py --rooms 20 --points-per-object 18000 --workers 2 --repeats 2
"""
import argparse
import contextlib
import functools
import glob
import importlib.util
import io
import os
import pickle
import resource
import shutil
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from projects.synthdet.datasets.s3dis_converter import (
    OUTPUT_DIRS, S3DIS_DIR, convert_s3dis)
from synthdet.room_data import annotation_files  # the converter's file order
from tests.s3dis_fixtures import write_synthetic_area
from synthdet.cli import OneLineParser

S3DIS_CLASSES_13 = ('ceiling', 'floor', 'wall', 'beam', 'column', 'window', 'door', 'table',
                    'chair', 'sofa', 'bookcase', 'board', 'clutter')
BENCH_CLASSES = ('table', 'chair', 'sofa', 'bookcase', 'board')


def load_mmdet3d_s3dis_data():
    """The installed ``S3DISData`` class, imported from mmdet3d's shipped tools folder."""
    spec = importlib.util.find_spec('mmdet3d')
    path = Path(
        spec.origin).parent / '.mim' / 'tools' / 'dataset_converters' / 's3dis_data_utils.py'
    module_spec = importlib.util.spec_from_file_location('mmdet3d_s3dis_data_utils', path)
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    return module.S3DISData


def mmdet3d_collect_room(anno_path: str, out_filename: str) -> list[str]:
    """mmdet3d's ``indoor3d_util.export``: returns the annotation files in the order used."""
    files = glob.glob(os.path.join(anno_path, '*.txt'))
    points_list = []
    for ins_idx, path in enumerate(files, start=1):
        one_class = os.path.basename(path).split('_')[0]
        if one_class not in S3DIS_CLASSES_13:
            one_class = 'clutter'
        points = pd.read_csv(path, header=None, sep=' ').to_numpy()
        labels = np.ones((points.shape[0], 1)) * S3DIS_CLASSES_13.index(one_class)
        ins_labels = np.ones((points.shape[0], 1)) * ins_idx
        points_list.append(np.concatenate([points, labels, ins_labels], 1))
    data_label = np.concatenate(points_list, 0)
    data_label[:, 0:3] -= np.amin(data_label, axis=0)[0:3]
    np.save(f'{out_filename}_point.npy', data_label[:, :6].astype(np.float32))
    np.save(f'{out_filename}_sem_label.npy', data_label[:, 6].astype(np.int64))
    np.save(f'{out_filename}_ins_label.npy', data_label[:, 7].astype(np.int64))
    return files


class Timer:
    """Wall time, CPU time and its system part, of this process, its threads and its finished
    child processes."""

    def __enter__(self) -> 'Timer':
        self.wall = -time.perf_counter()
        self.cpu, self.sys = (-seconds for seconds in self._cpu_and_sys())
        return self

    def __exit__(self, *exc) -> None:
        self.wall += time.perf_counter()
        cpu, sys_cpu = self._cpu_and_sys()
        self.cpu += cpu
        self.sys += sys_cpu

    @staticmethod
    def _cpu_and_sys() -> tuple[float, float]:
        own = resource.getrusage(resource.RUSAGE_SELF)
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        sys_cpu = own.ru_stime + children.ru_stime
        return own.ru_utime + children.ru_utime + sys_cpu, sys_cpu


def run_mmdet3d(root: Path, collect_processes: int,
                threads: int) -> tuple[Timer, list, dict[str, list[str]]]:
    """mmdet3d's collect step (rooms spread over ``collect_processes`` processes; 1 = serial as
    shipped) and ``S3DISData.get_infos`` with ``threads`` threads."""
    s3dis_data_cls = load_mmdet3d_s3dis_data()
    data_dir = root / S3DIS_DIR
    output_folder = root / 's3dis_data'
    remove_outputs(output_folder, *(root / sub for sub in OUTPUT_DIRS))
    output_folder.mkdir()
    with Timer() as timer:
        rooms = sorted(os.listdir(data_dir / 'Area_1'))
        collect = functools.partial(_collect_room, data_dir, output_folder)
        if collect_processes > 1:
            with ProcessPoolExecutor(collect_processes) as pool:  # waits for its processes
                orders = list(pool.map(collect, rooms))
        else:
            orders = [collect(room) for room in rooms]
        with contextlib.redirect_stdout(io.StringIO()):
            infos = s3dis_data_cls(
                root_path=str(root), split='Area_1').get_infos(num_workers=threads)
    return timer, infos, dict(zip(rooms, orders))


def remove_outputs(*folders: Path) -> None:
    """Remove an earlier run's outputs (untimed): every run writes new files, as a first
    conversion does (replacing files makes ext4 flush them to disk at once)."""
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)


def _collect_room(data_dir: Path, output_folder: Path, room: str) -> list[str]:
    return mmdet3d_collect_room(
        str(data_dir / 'Area_1' / room / 'Annotations'), str(output_folder / f'Area_1_{room}'))


def run_synthdet(root: Path, out_dir: Path, area: int, workers: int) -> Timer:
    remove_outputs(out_dir)
    with Timer() as timer:
        convert_s3dis(root, out_dir, areas=[area], workers=workers)
    return timer


def check_identical(root: Path, area: int, out_dir: Path, mm_root: Path, mm_infos: list,
                    mm_orders: dict[str, list[str]]) -> int:
    """Compare every room; returns the number of boxes compared."""
    with open(out_dir / f's3dis_infos_Area_{area}.pkl', 'rb') as f:
        ours = {Path(i['lidar_points']['lidar_path']).stem: i for i in pickle.load(f)['data_list']}
    n_boxes = 0
    for mm_info in mm_infos:
        room = mm_info['point_cloud']['lidar_idx'][len('Area_1_'):]
        name = f'Area_{area}_{room}'
        mm_points = np.fromfile(mm_root / mm_info['pts_path'], dtype=np.float32).reshape(-1, 6)
        mm_ins = np.fromfile(mm_root / mm_info['pts_instance_mask_path'], dtype=np.int64)
        mm_sem = np.fromfile(mm_root / mm_info['pts_semantic_mask_path'], dtype=np.int64)
        points = np.fromfile(out_dir / 'points' / f'{name}.bin', dtype=np.float32).reshape(-1, 6)
        ins = np.fromfile(out_dir / 'instance_mask' / f'{name}.bin', dtype=np.int64)
        sem = np.fromfile(out_dir / 'semantic_mask' / f'{name}.bin', dtype=np.int64)
        # instance id of each annotation file in each converter
        mm_id = {Path(p).name: k for k, p in enumerate(mm_orders[room], start=1)}
        our_id = {
            Path(p).name: k
            for k, p in enumerate(
                annotation_files(root / S3DIS_DIR / f'Area_{area}' / room / 'Annotations'),
                start=1)
        }
        assert mm_id.keys() == our_id.keys(), room
        renumber = np.zeros(len(mm_id) + 1, dtype=np.int64)  # mmdet3d id -> synthdet id
        for file_name, k in mm_id.items():
            renumber[k] = our_id[file_name]
        order = np.argsort(renumber[mm_ins], kind='stable')  # rows in synthdet's order
        assert np.array_equal(points, mm_points[order]), f'{room}: points differ'
        assert np.array_equal(sem, mm_sem[order]), f'{room}: semantic masks differ'
        assert np.array_equal(ins, renumber[mm_ins[order]]), f'{room}: instance masks differ'
        # boxes: mmdet3d lists them by its instance id, synthdet by its own
        mm_file = {k: f for f, k in mm_id.items()}
        mm_ids = [k for k in sorted(mm_file) if mm_file[k].split('_')[0] in BENCH_CLASSES]
        mm_by_file = {
            mm_file[k]: (int(label), box.tolist())
            for k, label, box in zip(mm_ids, mm_info['annos']['class'], mm_info['annos']
                                     ['gt_boxes_upright_depth'])
        }
        our_files = [f for f in sorted(our_id, key=our_id.get) if f.split('_')[0] in BENCH_CLASSES]
        assert [mm_by_file[f] for f in our_files] == [
            (inst['bbox_label_3d'], inst['bbox_3d']) for inst in ours[name]['instances']], \
            f'{room}: boxes differ'
        n_boxes += len(our_files)
    return n_boxes


def parse_args() -> argparse.Namespace:
    """The benchmark's command line."""
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rooms', type=int, default=20)
    parser.add_argument(
        '--points-per-object',
        type=int,
        default=18000,
        help='18000 gives about 300k points per room')
    parser.add_argument(
        '--workers',
        type=int,
        default=2,
        help='synthdet processes; also mmdet3d S3DISData threads')
    parser.add_argument(
        '--repeats',
        type=int,
        default=1,
        help='runs per converter, alternating; the best time of each is kept')
    parser.add_argument('--work-dir', help='keep data here (default: a temporary folder)')
    return parser.parse_args()


def write_inputs(work: Path, area: int, rooms: int, points_per_object: int) -> tuple[Path, Path]:
    """The synthetic area (written unless it exists) and the mmdet3d layout linking it as its
    area 1, both on disk and in the page cache; returns their roots."""
    root, mm_root = work / 'synthetic', work / 'mmdet3d'
    if not (root / S3DIS_DIR / f'Area_{area}').is_dir():
        print(f'writing {rooms} rooms ...', flush=True)
        write_synthetic_area(
            root,
            area,
            rooms,
            seed=0,
            classes=BENCH_CLASSES,
            points_per_object=points_per_object,
            room_size=(7.0, 6.0, 3.0))
    (mm_root / S3DIS_DIR).mkdir(parents=True, exist_ok=True)
    link = mm_root / S3DIS_DIR / 'Area_1'
    if not link.exists():
        link.symlink_to(root / S3DIS_DIR / f'Area_{area}', target_is_directory=True)
    os.sync()  # the rooms on disk: their write-back falls into no timed run
    for path in (root / S3DIS_DIR).rglob('*.txt'):  # same warm page cache for both
        path.read_bytes()
    return root, mm_root


def main() -> None:
    """Time both converters on one area, check that they agree and print the table."""
    args = parse_args()
    area = 7
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.work_dir or tmp)
        root, mm_root = write_inputs(work, area, args.rooms, args.points_per_object)
        n = args.workers
        configurations = {  # label -> run
            'mmdet3d collect + S3DISData, 1 process':
            lambda: run_mmdet3d(mm_root, 1, 1),
            f'mmdet3d as shipped (serial collect, {n} threads)':
            lambda: run_mmdet3d(mm_root, 1, n),
            f'mmdet3d, collect in {n} processes + {n} threads':
            lambda: run_mmdet3d(mm_root, n, n),
            'synthdet convert_s3dis, 1 worker':
            lambda: (run_synthdet(root, work / 'synthdet_w1', area, workers=1), ),
            f'synthdet convert_s3dis, {n} workers':
            lambda: (run_synthdet(root, work / 'synthdet', area, n), ),
        }
        for run in configurations.values():  # warm-up: imports, first-use costs, page cache
            run()
        runs: dict[str, list[Timer]] = {label: [] for label in configurations}
        for _ in range(args.repeats):
            for label, run in configurations.items():
                answer = run()
                runs[label].append(answer[0])
                if label.startswith('mmdet3d'):
                    _, mm_infos, mm_orders = answer
        best = {key: min(timers, key=lambda t: t.wall) for key, timers in runs.items()}
        n_boxes = check_identical(root, area, work / 'synthdet', mm_root, mm_infos, mm_orders)
        n_points = sum(
            len(np.fromfile(p, dtype=np.float32)) // 6
            for p in (work / 'synthdet' / 'points').glob('*.bin'))
    print(f'{args.rooms} rooms, {n_points} points, {n_boxes} boxes: points, masks and boxes '
          'identical')
    print(f'{"converter (best of " + str(args.repeats) + ")":<50} {"wall s":>8} {"CPU s":>8} '
          f'{"sys s":>6} {"Mpoints/s":>10}')
    for label, timer in best.items():
        print(f'{label:<50} {timer.wall:8.2f} {timer.cpu:8.2f} {timer.sys:6.2f} '
              f'{n_points / timer.wall / 1e6:10.2f}')
    labels = list(best)
    mm_1, mm_shipped, mm_n, ours_1, ours_n = (best[label].wall for label in labels)
    cpu_ratio = best[labels[0]].cpu / best[labels[3]].cpu
    print(f'convert speedup vs mmdet3d at equal parallelism: {mm_1 / ours_1:.1f}x (1 process '
          f'each), {mm_n / ours_n:.1f}x ({args.workers} each); synthdet {args.workers} workers vs '
          f'mmdet3d as shipped: {mm_shipped / ours_n:.1f}x; CPU-time ratio (1 process each): '
          f'{cpu_ratio:.1f}x')


if __name__ == '__main__':
    main()
