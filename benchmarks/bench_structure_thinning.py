"""Points on objects after sampling a room to the model's input, per sensor model: mmdet3d's
``PointSample`` alone vs ``ThinRoomStructure`` then ``PointSample`` (the same number of points).

    .venv/bin/python benchmarks/bench_structure_thinning.py [--rooms 4] [--points 1000000]
                                                            [--sample 40000] [--keep 0.1]

The generator writes ``--rooms`` rooms per sensor profile (``generator/profiles/{paper,tls,
tablet}.json``, seed 0, area 7) into a temporary folder. Each room's instances come from its
``Annotations/`` files; both pipelines (mmdet3d's registered transforms on ``DepthPoints``, numpy
seeded per room) sample ``--sample`` points, and the table gives per sensor the share of the
sampled points on detection-class objects (table, chair, sofa, yumi, 3dprinter), the median
and 10th-percentile sampled points per object, the share of object points that the thinning
took for structure, and the time of each pipeline per room. The last line gives the gain in
median points per object on the sparsest sensor. ``--pictures DIR`` also draws the first room of
each sensor from above after each pipeline (``DIR/<sensor>_<pipeline>.png``, points by class,
the true boxes).
"""
import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import bpy  # noqa: F401  (before open3d: both ship libtbb)
import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's generator and projects
warnings.filterwarnings('ignore', message='The MinkowskiEngine was compiled with CPU_ONLY')

from mmdet3d.registry import TRANSFORMS  # noqa: E402
from mmdet3d.structures import DepthPoints  # noqa: E402

import projects.synthdet.datasets.synthdet_s3dis  # noqa: E402,F401  (registers the transforms)
from generator.config import load_config  # noqa: E402
from generator.pipeline import RoomGenerator, RunOptions, plan_tasks  # noqa: E402
from synthdet.classes import GENERATED_CLASSES  # noqa: E402
from synthdet.room_data import (
    Scan,
    annotation_class,
    annotation_files,  # noqa: E402
    boxes_from_meta)
from synthdet.scan_io import read_scan  # noqa: E402
from synthdet.topview import draw_top_view  # noqa: E402

SENSORS = ('paper', 'tls', 'tablet')


def read_room(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points of a generated room, an instance id per point (-1 off the detection
    classes) and a class name per point, from its ``Annotations/``."""
    parts, ids, names = [], [], []
    instance = 0
    for file in annotation_files(folder / 'Annotations'):
        points = read_scan(file)
        parts.append(points)
        name = annotation_class(file) or file.stem
        names.append(np.full(len(points), name, dtype=object))
        if name in GENERATED_CLASSES:
            ids.append(np.full(len(points), instance))
            instance += 1
        else:
            ids.append(np.full(len(points), -1))
    return np.concatenate(parts), np.concatenate(ids), np.concatenate(names)


def sampled(points: np.ndarray, steps: list, seed: int) -> tuple[np.ndarray, float]:
    """Run ``steps`` on the room; the rows of the points kept and the seconds taken."""
    np.random.seed(seed)
    cloud = DepthPoints(
        torch.from_numpy(points.astype(np.float32)),
        points_dim=6,
        attribute_dims=dict(color=[3, 4, 5]))
    results = {'points': cloud, 'pts_instance_mask': np.arange(len(points))}
    start = time.perf_counter()
    for step in steps:
        results = step(results)
    return results['pts_instance_mask'], time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rooms', type=int, default=4)
    parser.add_argument('--points', type=int, default=1_000_000)
    parser.add_argument('--sample', type=int, default=40_000)
    parser.add_argument('--keep', type=float, default=0.1)
    parser.add_argument('--pictures', type=Path, help='draw the first room of each sensor here')
    args = parser.parse_args()
    sample = TRANSFORMS.build(dict(type='PointSample', num_points=args.sample))
    thin = TRANSFORMS.build(dict(type='ThinRoomStructure', keep=args.keep))
    pipelines = {'PointSample': [sample], 'thinned': [thin, sample]}
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
    rows = {}
    with tempfile.TemporaryDirectory(prefix='synthdet-bench-thinning-') as work:
        for sensor in SENSORS:
            options = RunOptions(
                out=str(Path(work) / sensor),
                points=args.points,
                object_ratio=0.5,
                seed=0,
                config=load_config(REPO / 'generator' / 'profiles' / f'{sensor}.json'),
                asset_cache=str(Path(work) / 'assets'),
                threads=1)
            generator = RoomGenerator(options)
            for task in plan_tasks([7], args.rooms, 0):
                generator.generate(task)
            stats = {name: {'share': [], 'per_object': [], 'seconds': []} for name in pipelines}
            flagged = []
            for index, folder in enumerate(
                    sorted(p for p in Path(options.out).glob('Area_7/*') if p.is_dir())):
                points, ids, names = read_room(folder)
                objects = ids >= 0
                structure = thin.structure(points[:, :3].astype(np.float64))
                flagged.append((structure & objects).sum() / max(objects.sum(), 1))
                for name, steps in pipelines.items():
                    kept_rows, seconds = sampled(points, steps, seed=index)
                    kept = ids[kept_rows]
                    if args.pictures and index == 0:
                        draw_top_view(
                            args.pictures / f'{sensor}_{name}.png',
                            Scan(points[kept_rows], names[kept_rows]),
                            boxes_from_meta(folder / 'meta.json'),
                            title=f'{sensor} room {folder.name}, {len(kept_rows):,} points '
                            f'after {name}')
                    counts = np.bincount(kept[kept >= 0], minlength=ids.max() + 1)
                    stats[name]['share'].append(np.mean(kept >= 0))
                    stats[name]['per_object'].extend(counts.tolist())
                    stats[name]['seconds'].append(seconds)
            rows[sensor] = (stats, float(np.mean(flagged)))
    print(f'{args.rooms} rooms x {args.points:,} points per sensor, {args.sample:,} sampled, '
          f'structure kept {args.keep:.0%}')
    print(f'{"sensor":<8}{"pipeline":<13}{"on objects":>11}{"median/obj":>11}{"p10/obj":>9}'
          f'{"s/room":>8}{"obj. thinned":>14}')
    gains = {}
    for sensor, (stats, flagged) in rows.items():
        for name, values in stats.items():
            per_object = np.array(values['per_object'])
            print(f'{sensor:<8}{name:<13}{np.mean(values["share"]):>10.1%}'
                  f'{np.median(per_object):>11.0f}{np.percentile(per_object, 10):>9.0f}'
                  f'{np.median(values["seconds"]):>8.2f}'
                  f'{(f"{flagged:.1%}" if name == "thinned" else ""):>14}')
        gains[sensor] = (
            np.median(stats['thinned']['per_object']) /
            np.median(stats['PointSample']['per_object']))
    sparsest = min(rows, key=lambda s: np.median(rows[s][0]['PointSample']['per_object']))
    print(f'structure thinning: {gains[sparsest]:.1f}x the median points per object on {sparsest} '
          f'rooms ({", ".join(f"{s} {g:.1f}x" for s, g in gains.items())})')


if __name__ == '__main__':
    main()
