"""Ray casting speed on one generated room: the batched Embree scanner (``Scanner.cast``, Open3D
``RaycastingScene``) against the per-ray loops a bpy user would write, on the same scene and rays.

    .venv/bin/python benchmarks/bench_scanner.py [--rays 200000] [--slow-rays 20000]

Every method turns the same numpy rays (origins, unit directions) into numpy hit distances and
triangle (face) indices, the input of labelling:

- ``BVHTree.ray_cast`` loop: one ``mathutils.bvhtree.BVHTree`` of all world triangles, one call
  per ray (the fastest bpy loop);
- ``Object.ray_cast`` loop: the paper's per-object casts, the ray moved into each object's frame
  (vectorised, outside the loop), the nearest hit over the objects kept;
- ``scene.ray_cast`` loop: one call per ray on the scene (the previous baseline).

Equal treatment: one warm-up pass on the first 1000 rays, then the median of ``--repeats`` timed
passes with the garbage collector off, for every method; the slow loops (``Object`` and ``scene``) take the first
``--slow-rays`` rays. Each loop's hits are checked against Embree's. All methods run on one
thread (bpy's ray casts are single-threaded); Embree on all cores is printed beside it. Then a
full 1M-point scan (``Scanner.scan``: ray generation, Embree, labelling) on one thread and on all
cores, with the share of Embree time. The last line is the one-thread ratio against the fastest
bpy loop, with the all-core ratio beside it.
"""
import argparse
import gc
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import bpy  # before open3d: both ship libtbb
import numpy as np
from mathutils import Vector
from mathutils.bvhtree import BVHTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's generator

from generator.config import load_config  # noqa: E402
from generator.layout import catalog_from_library, generate_layout  # noqa: E402
from generator.pipeline import RunOptions, open_library  # noqa: E402
from generator.scanner import Scanner, random_directions, sensor_path  # noqa: E402
from generator.scene import COLLECTION, RoomScene, export_triangles  # noqa: E402

Caster = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def bvhtree_caster(vertices: np.ndarray, triangles: np.ndarray) -> Caster:
    """Per-ray ``BVHTree.ray_cast`` on one tree of the world triangles."""
    tree = BVHTree.FromPolygons(vertices.tolist(), triangles.tolist(), all_triangles=True)

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ray_cast = tree.ray_cast
        distance, face = [], []
        for o, d in zip(origins.tolist(), directions.tolist()):
            _location, _normal, index, t = ray_cast(o, d)
            distance.append(t)
            face.append(index)
        # a miss gives None, which numpy turns into nan
        distance = np.array(distance, dtype=np.float64)
        face = np.array(face, dtype=np.float64)
        return np.nan_to_num(distance, nan=np.inf), np.nan_to_num(face, nan=-1).astype(np.int64)

    return cast


def object_caster(objects: list, face_offsets: np.ndarray) -> Caster:
    """The paper's per-object ``Object.ray_cast``, nearest hit over the objects; the world face
    index is the object's offset plus its face index."""
    inverse = [np.linalg.inv(np.array(obj.matrix_world, dtype=np.float64)) for obj in objects]

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance = np.full(len(origins), np.inf)
        face = np.full(len(origins), -1, dtype=np.int64)
        for obj, matrix, offset in zip(objects, inverse, face_offsets):
            local_o = (origins @ matrix[:3, :3].T + matrix[:3, 3]).tolist()
            local_d = (directions @ matrix[:3, :3].T).tolist()  # rigid: lengths kept
            ray_cast = obj.ray_cast
            for i, (o, d) in enumerate(zip(local_o, local_d)):
                hit, location, _normal, index = ray_cast(o, d)
                if hit:
                    t = (location - Vector(o)).length
                    if t < distance[i]:
                        distance[i], face[i] = t, offset + index
        return distance, face

    return cast


def scene_caster(face_offsets: dict[str, int]) -> Caster:
    """Per-ray ``scene.ray_cast`` on the evaluated scene (world frame)."""
    scene = bpy.context.scene
    depsgraph = bpy.context.evaluated_depsgraph_get()

    def cast(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        distance = np.full(len(origins), np.inf)
        face = np.full(len(origins), -1, dtype=np.int64)
        for i, (o, d) in enumerate(zip(origins.tolist(), directions.tolist())):
            hit, location, _normal, index, obj, _matrix = scene.ray_cast(depsgraph, o, d)
            if hit:
                distance[i] = (location - Vector(o)).length
                face[i] = face_offsets[obj.name] + index
        return distance, face

    return cast


def timed(cast: Caster, origins: np.ndarray, directions: np.ndarray,
          repeats: int) -> tuple[float, tuple[np.ndarray, np.ndarray]]:
    """One warm-up pass on the first 1000 rays, then the median seconds of ``repeats`` passes.

    The garbage collector is off while timing: the per-ray loops allocate a result tuple per
    ray, and collections over this process's large heap would otherwise slow them down 3-4x.
    """
    cast(origins[:1000], directions[:1000])
    gc.collect()
    gc.disable()
    try:
        seconds = []
        for _ in range(repeats):
            start = time.perf_counter()
            result = cast(origins, directions)
            seconds.append(time.perf_counter() - start)
    finally:
        gc.enable()
    return statistics.median(seconds), result


def agreement(found: tuple[np.ndarray, np.ndarray], embree: tuple[np.ndarray,
                                                                   np.ndarray]) -> str:
    """Share of rays where a loop and Embree agree on hit/miss and on the first-hit distance."""
    distance, _ = found
    reference = embree[0][:len(distance)].astype(np.float64)
    both = np.isfinite(distance) & np.isfinite(reference)
    same_hit = np.mean(np.isfinite(distance) == np.isfinite(reference))
    same_t = np.mean(np.abs(distance[both] - reference[both]) < 1e-3)
    return f'hit/miss {same_hit:.2%}, |dt| < 1 mm {same_t:.2%}'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rays', type=int, default=200_000, help='rays for BVHTree and Embree')
    parser.add_argument(
        '--slow-rays', type=int, default=20_000, help='rays for Object and scene ray_cast')
    parser.add_argument('--repeats', type=int, default=5, help='timed passes (median)')
    parser.add_argument('--scan-points', type=int, default=1_000_000)
    parser.add_argument('--asset-cache', type=Path, default=None)
    parser.add_argument('--seed', type=int, default=3)
    args = parser.parse_args()

    for obj in list(bpy.data.objects):  # bpy's start-up cube, camera and light
        bpy.data.objects.remove(obj, do_unlink=True)
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
    # the bpy objects in export order: their faces are the TriangleScene's triangles, in order
    objects = sorted(bpy.data.collections[COLLECTION].objects,
                     key=lambda o: o['synthdet_instance'])
    offsets = np.cumsum([0] + [len(o.data.polygons) for o in objects])[:-1]
    print(f'scene: {layout.shape} room {np.ptp(layout.polygon, axis=0).round(2).tolist()} m, '
          f'{len(objects)} objects, {len(triangles.triangles)} triangles; one warm-up pass, '
          f'median of {args.repeats}')

    rng = np.random.default_rng(0)
    path, _ = sensor_path(layout.polygon, layout.height, rng)
    origins = path[np.arange(args.rays) % len(path)]
    directions = random_directions(rng, args.rays)

    import open3d  # noqa: F401
    embree = {threads: Scanner(triangles, threads=threads) for threads in (1, 0)}
    results = {}  # label -> (rays, seconds, hits)
    for threads, scanner in embree.items():
        label = f'Embree Scanner.cast, {threads or os.cpu_count()} thread(s)'
        results[label] = (args.rays, *timed(lambda o, d, s=scanner: s.cast(s.full_scene, o, d),
                                            origins, directions, args.repeats))
    loops = {
        'bpy BVHTree.ray_cast loop': (bvhtree_caster(triangles.vertices, triangles.triangles),
                                      args.rays),
        'bpy Object.ray_cast loop (per object)': (object_caster(objects, offsets),
                                                  args.slow_rays),
        'bpy scene.ray_cast loop': (scene_caster(dict(zip((o.name for o in objects),
                                                          offsets.tolist()))), args.slow_rays),
    }
    for label, (cast, n) in loops.items():
        results[label] = (n, *timed(cast, origins[:n], directions[:n], args.repeats))

    reference = results['Embree Scanner.cast, 1 thread(s)'][2]
    print(f'{"method":<42}{"rays":>9}{"seconds":>9}{"rays/s":>13}  agreement with Embree')
    rate = {}
    for label, (n, seconds, found) in results.items():
        rate[label] = n / seconds
        check = '' if label.startswith('Embree') else agreement(found, reference)
        print(f'{label:<42}{n:>9}{seconds:>9.3f}{rate[label]:>13,.0f}  {check}')

    scan_seconds = {}
    for threads, scanner in embree.items():
        scanner.scan(path, 10_000, 0.5, np.random.default_rng(1), config['scanner'])  # warm-up
        cast_seconds = []
        original_cast = scanner.cast

        def counted_cast(*cast_args, original=original_cast):
            start = time.perf_counter()
            answer = original(*cast_args)
            cast_seconds.append(time.perf_counter() - start)
            return answer

        scanner.cast = counted_cast
        start = time.perf_counter()
        scan = scanner.scan(path, args.scan_points, 0.5, np.random.default_rng(1),
                            config['scanner'])
        scan_seconds[threads] = time.perf_counter() - start
        print(f'full scan of {args.scan_points:,} labelled points, {threads or os.cpu_count()} '
              f'thread(s): {scan_seconds[threads]:.2f} s, {scan.rays_cast:,} rays, '
              f'{args.scan_points / scan_seconds[threads]:,.0f} points/s; Embree calls '
              f'{sum(cast_seconds) / scan_seconds[threads]:.0%} of it')

    fastest = max((label for label in rate if label.startswith('bpy')), key=rate.get)
    one = rate['Embree Scanner.cast, 1 thread(s)'] / rate[fastest]
    every = rate[f'Embree Scanner.cast, {os.cpu_count()} thread(s)'] / rate[fastest]
    print(f'scan speedup vs fastest bpy loop ({fastest}), 1 thread each: {one:.1f}x '
          f'(Embree on {os.cpu_count()} threads: {every:.1f}x)')


if __name__ == '__main__':
    main()
