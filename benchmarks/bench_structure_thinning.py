"""Points on objects after sampling a room to the model's input, per sensor model: mmdet3d's
``PointSample`` alone vs ``ThinRoomStructure`` then ``PointSample`` (the same number of points)
vs ``VoxelGridSample``, ``ThinRoomStructure`` then ``PointSample``.

    .venv/bin/python benchmarks/bench_structure_thinning.py [--rooms 4] [--points 1000000]
                                                            [--sample 40000] [--keep 0.1]
                                                            [--voxel 0.02]

The generator writes ``--rooms`` rooms per sensor profile (``generator/profiles/{paper,tls,
tablet}.json``, seed 0, area 7) into a temporary folder. Each room's instances come from its
``Annotations/`` files; both pipelines (mmdet3d's registered transforms on ``DepthPoints``, numpy
seeded per room) sample ``--sample`` points, and the table gives per sensor the share of the
sampled points on detection-class objects (table, chair, sofa, yumi, 3dprinter), the median
and 10th-percentile sampled points per object, the same for the ``--voxel`` cubes they occupy
(the detector merges the points of one of its voxels, so these are what it sees), the share of
object points that the thinning took for structure, and the time of each pipeline per room.
Then the gain in median points per object on the sparsest sensor, the voxel grid's time per room
against ``np.unique`` (the straightforward way to keep one point per cube), measured side by
side, and last the gain of the voxel grid in 10th-percentile voxels per object per sensor.
``--pictures DIR`` also draws the first room of each sensor from above after each pipeline
(``DIR/<sensor>_<pipeline>.png``, points by class, the true boxes).
"""
import argparse
import tempfile
import time
import warnings
from pathlib import Path

import bpy  # noqa: F401  (before open3d: both ship libtbb)
import numpy as np
import torch

# before the imports below, which load MinkowskiEngine (it warns when imported)
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
from synthdet.voxels import cube_keys, one_point_per_cube  # noqa: E402
from synthdet.cli import OneLineParser  # noqa: E402

REPO = Path(__file__).resolve().parents[1]

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


def occupied_voxels(xyz: np.ndarray, ids: np.ndarray, objects: int, voxel: float) -> list[int]:
    """The number of ``voxel`` cubes that the sampled points ``xyz`` of each object occupy."""
    on_object = ids >= 0
    cubes = np.floor(xyz[on_object] / voxel).astype(np.int64)
    unique = np.unique(np.column_stack([ids[on_object], cubes]), axis=0)
    return np.bincount(unique[:, 0], minlength=objects).tolist()


def time_grid(points: np.ndarray, grid, seed: int) -> dict[str, float]:
    """Seconds to choose one random point per cube of ``points`` (the rows to keep, not the
    copy of the points): ``VoxelGridSample``'s rule (``synthdet.voxels.one_point_per_cube``:
    shuffle, argsort of the cube keys) and the straightforward ``np.unique`` of the shuffled
    cube keys; both keep the same number of cubes."""
    xyz = points[:, :3].astype(np.float32)
    np.random.seed(seed)
    start = time.perf_counter()
    kept = one_point_per_cube(xyz, grid.voxel_size, np.random)
    ours = time.perf_counter() - start
    np.random.seed(seed)
    start = time.perf_counter()
    order = np.random.permutation(len(xyz))
    _, first = np.unique(cube_keys(xyz, grid.voxel_size)[order], return_index=True)
    plain = time.perf_counter() - start
    if len(first) != len(kept):
        raise RuntimeError(f'the two ways kept {len(kept)} and {len(first)} cubes')
    return {'VoxelGridSample': ours, 'np.unique': plain}


def parse_args() -> argparse.Namespace:
    """The benchmark's command line."""
    parser = OneLineParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rooms', type=int, default=4)
    parser.add_argument('--points', type=int, default=1_000_000)
    parser.add_argument('--sample', type=int, default=40_000)
    parser.add_argument('--keep', type=float, default=0.1)
    parser.add_argument('--voxel', type=float, default=0.02)
    parser.add_argument('--pictures', type=Path, help='draw the first room of each sensor here')
    return parser.parse_args()


def measure_sensor(sensor: str, work: Path, args: argparse.Namespace, pipelines: dict,
                   grid_seconds: dict[str, list[float]]) -> tuple[dict, float]:
    """Generate ``args.rooms`` rooms of the ``sensor`` profile into ``work`` and sample each
    with every pipeline; returns the per-pipeline figures and the mean share of object points
    the structure thinning flags. The voxel grid's timings go into ``grid_seconds``."""
    thin, grid = pipelines['thinned'][0], pipelines['grid+thinned'][0]
    options = RunOptions(
        out=str(work / sensor),
        points=args.points,
        object_ratio=0.5,
        seed=0,
        config=load_config(REPO / 'generator' / 'profiles' / f'{sensor}.json'),
        asset_cache=str(work / 'assets'),
        threads=1)
    generator = RoomGenerator(options)
    for task in plan_tasks([7], args.rooms, 0):
        generator.generate(task)
    stats = {
        name: {'share': [], 'per_object': [], 'voxels': [], 'seconds': []}
        for name in pipelines
    }
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
            stats[name]['voxels'].extend(
                occupied_voxels(points[kept_rows, :3], kept, ids.max() + 1, args.voxel))
            stats[name]['seconds'].append(seconds)
        for name, seconds in time_grid(points, grid, seed=index).items():
            grid_seconds[name].append(seconds)
    return stats, float(np.mean(flagged))


def print_rows(rows: dict[str, tuple[dict, float]]) -> tuple[dict, dict]:
    """The table of every sensor and pipeline; returns per sensor the thinning's gain of median
    points per object and the voxel grid's gain of 10th-percentile voxels per object."""
    print(f'{"sensor":<8}{"pipeline":<14}{"on objects":>11}{"median/obj":>11}{"p10/obj":>9}'
          f'{"voxels/obj":>11}{"p10":>6}{"s/room":>8}{"obj. thinned":>14}')
    gains, grid_gains = {}, {}
    for sensor, (stats, flagged) in rows.items():
        for name, values in stats.items():
            per_object, voxels = np.array(values['per_object']), np.array(values['voxels'])
            print(f'{sensor:<8}{name:<14}{np.mean(values["share"]):>10.1%}'
                  f'{np.median(per_object):>11.0f}{np.percentile(per_object, 10):>9.0f}'
                  f'{np.median(voxels):>11.0f}{np.percentile(voxels, 10):>6.0f}'
                  f'{np.median(values["seconds"]):>8.2f}'
                  f'{(f"{flagged:.1%}" if name == "thinned" else ""):>14}')
        gains[sensor] = (
            np.median(stats['thinned']['per_object']) /
            np.median(stats['PointSample']['per_object']))
        grid_gains[sensor] = (
            np.percentile(stats['grid+thinned']['voxels'], 10) /
            max(np.percentile(stats['thinned']['voxels'], 10), 1))
    return gains, grid_gains


def main() -> None:
    """Sample generated rooms of every sensor with and without the thinning and the grid."""
    args = parse_args()
    sample = TRANSFORMS.build(dict(type='PointSample', num_points=args.sample))
    thin = TRANSFORMS.build(dict(type='ThinRoomStructure', keep=args.keep))
    grid = TRANSFORMS.build(dict(type='VoxelGridSample', voxel_size=args.voxel))
    pipelines = {
        'PointSample': [sample],
        'thinned': [thin, sample],
        'grid+thinned': [grid, thin, sample]
    }
    grid_seconds = {'VoxelGridSample': [], 'np.unique': []}
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix='synthdet-bench-thinning-') as work:
        rows = {
            sensor: measure_sensor(sensor, Path(work), args, pipelines, grid_seconds)
            for sensor in SENSORS
        }
    print(f'{args.rooms} rooms x {args.points:,} points per sensor, {args.sample:,} sampled, '
          f'structure kept {args.keep:.0%}')
    gains, grid_gains = print_rows(rows)
    sparsest = min(rows, key=lambda s: np.median(rows[s][0]['PointSample']['per_object']))
    print(f'structure thinning: {gains[sparsest]:.1f}x the median points per object on {sparsest} '
          f'rooms ({", ".join(f"{s} {g:.1f}x" for s, g in gains.items())})')
    ours, plain = (np.median(grid_seconds[name]) for name in ('VoxelGridSample', 'np.unique'))
    print(f'voxel grid per 1M-point room: VoxelGridSample {ours:.3f} s vs np.unique '
          f'{plain:.3f} s, x{plain / ours:.2f} faster')
    print('voxel grid first: 10th-percentile voxels per object '
          + ', '.join(f'{s} {g:.2f}x' for s, g in grid_gains.items()))

if __name__ == '__main__':
    main()
