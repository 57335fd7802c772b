"""Ray casting speed on one generated room: the paper's per-ray bpy ``scene.ray_cast`` loop vs
the batched Embree scanner (Open3D ``RaycastingScene``), on the same scene and the same rays.

    .venv/bin/python benchmarks/bench_scanner.py [--bpy-rays 100000] [--embree-rays 2000000]

Prints rays/s for both, checks that both find the same first hits, and ends with
``scan speedup vs bpy ray_cast loop: <N>x``.
"""
import argparse
import os
import tempfile
import time
from pathlib import Path

import bpy  # before open3d: both ship libtbb
import numpy as np
from mathutils import Vector

from generator.config import load_config
from generator.layout import catalog_from_library, generate_layout
from generator.pipeline import RunOptions, open_library
from generator.scanner import Scanner, random_directions, sensor_path
from generator.scene import RoomScene, export_triangles


def bpy_loop(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, float]:
    """The paper's approach: one ``scene.ray_cast`` call per ray; returns distances and seconds."""
    scene = bpy.context.scene
    depsgraph = bpy.context.evaluated_depsgraph_get()
    distances = np.full(len(origins), np.inf)
    start = time.perf_counter()
    for i, (o, d) in enumerate(zip(origins.tolist(), directions.tolist())):
        hit, location, _normal, _index, _obj, _matrix = scene.ray_cast(
            depsgraph, Vector(o), Vector(d))
        if hit:
            distances[i] = (location - Vector(o)).length
    return distances, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--bpy-rays', type=int, default=100_000)
    parser.add_argument('--embree-rays', type=int, default=2_000_000)
    parser.add_argument('--asset-cache', type=Path, default=None)
    parser.add_argument('--seed', type=int, default=3)
    args = parser.parse_args()

    config = load_config()
    cache = args.asset_cache or Path(tempfile.mkdtemp(prefix='synthdet-bench-assets-'))
    options = RunOptions(
        out='', points=1, object_ratio=0.5, seed=0, config=config, asset_cache=str(cache))
    library = open_library(options)
    by_name = {i.name: i for c in library.classes() for i in library.instances(c)}
    layout = generate_layout(
        np.random.default_rng(args.seed), catalog_from_library(library), config)
    room = RoomScene(lambda cls, name: by_name[name].mesh_arrays())
    room.build(layout, np.random.default_rng(0))
    triangles, names, _ = export_triangles()
    print(f'scene: {layout.shape} room {np.ptp(layout.polygon, axis=0).round(2).tolist()} m, '
          f'{len(layout.objects)} objects, {len(triangles.triangles)} triangles')

    rng = np.random.default_rng(0)
    path, _ = sensor_path(layout.polygon, layout.height, rng)
    n = max(args.bpy_rays, args.embree_rays)
    origins = path[np.arange(n) % len(path)]
    directions = random_directions(rng, n)

    bpy_t, bpy_seconds = bpy_loop(origins[:args.bpy_rays], directions[:args.bpy_rays])
    bpy_rate = args.bpy_rays / bpy_seconds

    import open3d  # noqa: F401
    rates = {}
    for threads in (1, 0):  # one thread (as in a 2-worker run on 2 cores) and all cores
        scanner = Scanner(triangles, threads=threads)
        scanner.cast(scanner.full_scene, origins[:1000], directions[:1000])  # warm-up
        times = []
        for _ in range(3):
            start = time.perf_counter()
            t_hit, _ = scanner.cast(scanner.full_scene, origins[:args.embree_rays],
                                    directions[:args.embree_rays])
            times.append(time.perf_counter() - start)
        rates[threads] = (float(np.median(times)), args.embree_rays / float(np.median(times)))

    both = np.isfinite(bpy_t) & np.isfinite(t_hit[:args.bpy_rays])
    agree = np.mean(np.abs(bpy_t[both] - t_hit[:args.bpy_rays][both]) < 1e-3)
    hits_same = np.mean(np.isfinite(bpy_t) == np.isfinite(t_hit[:args.bpy_rays]))
    start = time.perf_counter()
    scan = scanner.scan(path, 1_000_000, 0.5, np.random.default_rng(1), config['scanner'])
    scan_seconds = time.perf_counter() - start
    print(f'same first hit (|dt| < 1 mm) on {agree:.2%} of {both.sum()} rays, '
          f'hit/miss agreement {hits_same:.2%}')
    print(f'{"method":<34}{"rays":>10}{"seconds":>10}{"rays/s":>14}')
    print(f'{"bpy scene.ray_cast loop (paper)":<34}{args.bpy_rays:>10}{bpy_seconds:>10.2f}'
          f'{bpy_rate:>14,.0f}')
    for threads, label in ((1, '1 thread'), (0, f'{os.cpu_count()} threads')):
        seconds, rate = rates[threads]
        print(
            f'{"Embree batch, " + label:<34}{args.embree_rays:>10}{seconds:>10.2f}{rate:>14,.0f}')
    print(
        f'full scan of 1M labelled points (object ratio 0.5, all threads): {scan_seconds:.2f} s, '
        f'{scan.rays_cast:,} rays')
    print(f'all-thread Embree vs bpy loop: {rates[0][1] / bpy_rate:.1f}x; the line below is '
          f'single-thread vs single-thread')
    print(f'scan speedup vs bpy ray_cast loop: {rates[1][1] / bpy_rate:.1f}x')


if __name__ == '__main__':
    main()
